#pragma once

// The hand-over between a capture thread and its consumer (DESIGN.md §6): a latest-value slot.
// publish() never waits for the consumer; a frame replaced before anyone took it is a drop,
// and drops are counted so a slow consumer shows up in the logs instead of stalling capture.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>

#include "capture/frame.h"

namespace previs {

class FrameSlot {
public:
    // Replaces the held frame. Holds the lock only for a pointer swap; the replaced frame (if
    // nobody took it) is released after unlocking, so a large free never runs under the lock.
    void publish(std::shared_ptr<const Frame> frame);

    // The newest frame not yet taken, or nullptr; a later take() returns nullptr until the next
    // publish().
    std::shared_ptr<const Frame> take();
    // As take(), waiting up to `timeout` for a frame to arrive.
    std::shared_ptr<const Frame> waitTake(std::chrono::milliseconds timeout);
    // The newest frame ever published (taken or not), for consumers that only sample the state.
    std::shared_ptr<const Frame> latest() const;

    uint64_t published() const;
    // Frames published and replaced before any take(): the consumer never saw them.
    uint64_t dropped() const;

private:
    mutable std::mutex mutex_;
    std::condition_variable ready_;
    std::shared_ptr<const Frame> pending_;
    std::shared_ptr<const Frame> latest_;
    uint64_t published_ = 0;
    uint64_t dropped_ = 0;
};

}  // namespace previs
