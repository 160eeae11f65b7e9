// Time-of-day timecode (base/timecode.h): the rate a camera's fps counts at, and the frame
// number within a second, in UTC so the test does not depend on the machine's zone.
#include "base/timecode.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <ctime>

namespace previs {
namespace {

TEST(Timecode, RatesOfCommonCameras) {
    EXPECT_EQ(timecodeRate(23.976), 24);
    EXPECT_EQ(timecodeRate(25.0), 25);
    EXPECT_EQ(timecodeRate(29.97), 30);
    EXPECT_EQ(timecodeRate(59.94), 60);
    EXPECT_EQ(timecodeRate(0.0), 1) << "never a division by zero";
}

TEST(Timecode, TimeOfDayAndFrameWithinTheSecond) {
    setenv("TZ", "UTC", 1);
    tzset();
    // 2026-12-04 13:45:07 UTC, 0.5 s and 1 ns.
    const uint64_t second = 1796391907ull;
    const uint64_t ns = second * 1'000'000'000ull + 500'000'001ull;
    EXPECT_EQ(timeOfDayTimecode(ns, 30), "13:45:07:15");
    EXPECT_EQ(timeOfDayTimecode(ns, 25), "13:45:07:12");
    // The last frame of a second, and the first of the next.
    EXPECT_EQ(timeOfDayTimecode(second * 1'000'000'000ull + 999'999'999ull, 24), "13:45:07:23");
    EXPECT_EQ(timeOfDayTimecode((second + 1) * 1'000'000'000ull, 24), "13:45:08:00");
}

}  // namespace
}  // namespace previs
