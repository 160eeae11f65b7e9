#pragma once

// Now on CLOCK_MONOTONIC in nanoseconds: the clock of V4L2 buffer timestamps, so a frame's
// capture, a packet's arrival and an audio chunk are compared on one time line
// (std::chrono::steady_clock is CLOCK_MONOTONIC on Linux).

#include <chrono>
#include <cstdint>

namespace previs {

inline int64_t monotonicNowNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

}  // namespace previs
