#pragma once

// A latest-value slot (DESIGN.md §6): the producer replaces the value, consumers read the newest
// one; nobody waits for anybody's work (the lock only guards a pointer swap). Values are
// immutable snapshots shared by shared_ptr<const T>.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>

namespace previs {

template <typename T>
class LatestValueSlot {
public:
    // Replaces the value; returns true when the previous one had not been taken (dropped).
    bool publish(std::shared_ptr<const T> value) {
        bool dropped = false;
        {
            std::lock_guard lock(mutex_);
            dropped = fresh_;
            value_ = std::move(value);
            fresh_ = true;
            ++version_;
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

    uint64_t version() const {
        std::lock_guard lock(mutex_);
        return version_;
    }

private:
    mutable std::mutex mutex_;
    std::condition_variable changed_;
    std::shared_ptr<const T> value_;
    bool fresh_ = false;
    uint64_t version_ = 0;
};

}  // namespace previs
