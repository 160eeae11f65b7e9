#include "base/timecode.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <ctime>

namespace previs {

int timecodeRate(double fps) { return std::clamp(int(std::lround(fps)), 1, 1000); }

std::string timeOfDayTimecode(uint64_t wallClockNs, int rate) {
    const std::time_t seconds = std::time_t(wallClockNs / 1'000'000'000ull);
    const uint64_t fractionNs = wallClockNs % 1'000'000'000ull;
    std::tm local{};
    localtime_r(&seconds, &local);
    const uint64_t frame = fractionNs * uint64_t(rate) / 1'000'000'000ull;
    return fmt::format("{:02}:{:02}:{:02}:{:02}", local.tm_hour, local.tm_min,
                       std::min(local.tm_sec, 59), frame);
}

}  // namespace previs
