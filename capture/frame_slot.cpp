#include "capture/frame_slot.h"

#include <utility>

namespace previs {

void FrameSlot::publish(std::shared_ptr<const Frame> frame) {
    std::shared_ptr<const Frame> replaced;
    {
        std::lock_guard lock(mutex_);
        latest_ = frame;
        replaced = std::exchange(pending_, std::move(frame));
        ++published_;
        if (replaced) ++dropped_;
    }
    ready_.notify_all();
}

std::shared_ptr<const Frame> FrameSlot::take() {
    std::lock_guard lock(mutex_);
    return std::exchange(pending_, nullptr);
}

std::shared_ptr<const Frame> FrameSlot::waitTake(std::chrono::milliseconds timeout) {
    std::unique_lock lock(mutex_);
    ready_.wait_for(lock, timeout, [this] { return pending_ != nullptr; });
    return std::exchange(pending_, nullptr);
}

std::shared_ptr<const Frame> FrameSlot::latest() const {
    std::lock_guard lock(mutex_);
    return latest_;
}

uint64_t FrameSlot::published() const {
    std::lock_guard lock(mutex_);
    return published_;
}

uint64_t FrameSlot::dropped() const {
    std::lock_guard lock(mutex_);
    return dropped_;
}

}  // namespace previs
