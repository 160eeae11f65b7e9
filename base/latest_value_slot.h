#pragma once

// A latest-value slot (DESIGN.md §6): the producer replaces the value, consumers read the newest
// one; nobody waits for anybody's work (the lock only guards a pointer swap). Values are
// immutable snapshots shared by shared_ptr<const T>. A value replaced before anyone took it is
// a drop; drops are counted, so a slow consumer shows up in the logs instead of stalling its
// producer. Capture frames, tracked frames, lighting snapshots and display frames all use it.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <utility>

namespace previs {

template <typename T>
class LatestValueSlot {
public:
    // Replaces the value; returns true when the previous one had not been taken (dropped). The
    // replaced value is released after unlocking, so a large free never runs under the lock.
    bool publish(std::shared_ptr<const T> value) {
        std::shared_ptr<const T> replaced;
        bool dropped = false;
        {
            std::lock_guard lock(mutex_);
            dropped = fresh_;
            replaced = std::exchange(value_, std::move(value));
            fresh_ = true;
            ++version_;
            if (dropped) ++dropped_;
        }
        changed_.notify_all();
        return dropped;
    }

    // The newest value (null before the first publish); does not mark it taken.
    std::shared_ptr<const T> latest() const {
        std::lock_guard lock(mutex_);
        return value_;
    }

    // Takes the newest value if one arrived since the last take, else null.
    std::shared_ptr<const T> take() {
        std::lock_guard lock(mutex_);
        if (!fresh_) return nullptr;
        fresh_ = false;
        return value_;
    }

    // Waits until a value arrives since the last take, or stop is set (then null).
    std::shared_ptr<const T> waitTake(const bool& stop) {
        std::unique_lock lock(mutex_);
        changed_.wait(lock, [&] { return fresh_ || stop; });
        if (!fresh_) return nullptr;
        fresh_ = false;
        return value_;
    }

    // As take(), waiting up to `timeout` for a value to arrive (null on timeout).
    template <typename Rep, typename Period>
    std::shared_ptr<const T> waitTakeFor(std::chrono::duration<Rep, Period> timeout) {
        std::unique_lock lock(mutex_);
        if (!changed_.wait_for(lock, timeout, [&] { return fresh_; })) return nullptr;
        fresh_ = false;
        return value_;
    }

    // Wakes waiters (after the caller set its stop flag under lock()).
    void wakeAll() { changed_.notify_all(); }
    std::mutex& mutex() { return mutex_; }

    // Values published so far.
    uint64_t published() const {
        std::lock_guard lock(mutex_);
        return version_;
    }
    uint64_t version() const { return published(); }
    // Values replaced before any take(): the consumer never saw them.
    uint64_t dropped() const {
        std::lock_guard lock(mutex_);
        return dropped_;
    }

private:
    mutable std::mutex mutex_;
    std::condition_variable changed_;
    std::shared_ptr<const T> value_;
    bool fresh_ = false;
    uint64_t version_ = 0;
    uint64_t dropped_ = 0;
};

}  // namespace previs
