// The stage watch that decides whether previsd feeds systemd's watchdog (base/stage_watch.h),
// on explicit times.
#include "base/stage_watch.h"

#include <gtest/gtest.h>

#include <chrono>

namespace previs {
namespace {

constexpr int64_t kS = 1'000'000'000;

TEST(StageWatch, AnIdleStageIsNeverStuck) {
    StageWatch watch;
    watch.add("display");
    EXPECT_TRUE(watch.stuck(1000 * kS, 15 * kS).empty());
}

TEST(StageWatch, AStepLongerThanTheLimitIsStuckAndNamed) {
    StageWatch watch;
    Stage& capture = watch.add("capture scene");
    Stage& display = watch.add("display");
    capture.begin(100 * kS);
    display.begin(100 * kS);
    display.end();
    EXPECT_TRUE(watch.stuck(114 * kS, 15 * kS).empty());
    const std::vector<StageWatch::Stuck> stuck = watch.stuck(116 * kS, 15 * kS);
    ASSERT_EQ(stuck.size(), 1u);
    EXPECT_EQ(stuck[0].name, "capture scene");
    EXPECT_DOUBLE_EQ(stuck[0].seconds, 16.0);
    // A step that ends, however late, leaves the stage idle again.
    capture.end();
    EXPECT_TRUE(watch.stuck(200 * kS, 15 * kS).empty());
}

TEST(StageWatch, ACompileMayTakeItsAllowanceAndNoMore) {
    StageWatch watch;
    Stage& render = watch.add("render");
    render.begin(10 * kS);
    render.allowLonger(std::chrono::minutes(10));
    EXPECT_TRUE(watch.stuck((10 + 600 + 14) * kS, 15 * kS).empty());
    EXPECT_EQ(watch.stuck((10 + 600 + 16) * kS, 15 * kS).size(), 1u);
    // The allowance was the step's: the next step has the plain limit.
    render.end();
    render.begin(1000 * kS);
    EXPECT_EQ(watch.stuck(1016 * kS, 15 * kS).size(), 1u);
}

TEST(StageWatch, AScopedStepBeginsAndEnds) {
    StageWatch watch;
    Stage& tracking = watch.add("tracking");
    {
        StageStep step(&tracking);
        EXPECT_GT(tracking.runningNs(stageClockNs() + kS), 0);
    }
    EXPECT_EQ(tracking.runningNs(stageClockNs()), 0);
    StageStep none(nullptr);  // a thread run without a watch (tests, tools)
}

}  // namespace
}  // namespace previs
