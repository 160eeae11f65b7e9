// The dial's choosing (render/quality_dial.h): the Pareto front against a brute-force check on
// random measurements, the choice for a frame rate, and the grid neighbours the bench reports.
#include "render/quality_dial.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace previs {
namespace {

const DialAxes kAxes = {{1.0f, 0.5f, 0.25f}, {1, 2, 4}, {2, 4}, {}, {}};
// With the denoiser's strength and a photon budget swept too.
const DialAxes kAllAxes = {{1.0f, 0.5f}, {1, 2}, {2, 4}, {0, 2, 4}, {4096, 16384}};

std::vector<DialMeasurement> randomMeasurements(std::mt19937& rng, const DialAxes& axes = kAxes) {
    std::uniform_real_distribution<double> time(0.01, 1.0), error(0.01, 1.0);
    std::vector<DialMeasurement> m;
    for (const DialPoint& p : dialGrid(axes)) m.push_back({p, time(rng), error(rng)});
    return m;
}

TEST(QualityDial, ParetoFrontIsExactlyTheUndominatedPoints) {
    std::mt19937 rng(11);
    for (int trial = 0; trial < 50; ++trial) {
        const auto m = randomMeasurements(rng);
        const auto front = paretoFront(m);
        ASSERT_FALSE(front.empty());
        for (size_t i = 0; i < m.size(); ++i) {
            bool dominated = false;
            for (size_t j = 0; j < m.size(); ++j)
                dominated |= m[j].frameSeconds <= m[i].frameSeconds && m[j].error <= m[i].error &&
                             (m[j].frameSeconds < m[i].frameSeconds || m[j].error < m[i].error);
            const bool onFront = std::find(front.begin(), front.end(), i) != front.end();
            EXPECT_EQ(onFront, !dominated) << "point " << i;
        }
        // Ordered by time, so errors fall along it.
        for (size_t k = 1; k < front.size(); ++k) {
            EXPECT_LT(m[front[k - 1]].frameSeconds, m[front[k]].frameSeconds);
            EXPECT_GT(m[front[k - 1]].error, m[front[k]].error);
        }
    }
}

TEST(QualityDial, ChoiceFitsTheBudgetAndIsOnTheFront) {
    std::mt19937 rng(12);
    for (int trial = 0; trial < 50; ++trial) {
        const auto m = randomMeasurements(rng);
        const auto front = paretoFront(m);
        for (double fps : {1.5, 3.0, 10.0, 50.0}) {
            const auto chosen = chooseForFrameRate(m, fps);
            bool anyFits = false;
            for (const auto& x : m) anyFits |= x.frameSeconds <= 1.0 / fps;
            ASSERT_EQ(chosen.has_value(), anyFits);
            if (!chosen) continue;
            EXPECT_LE(m[*chosen].frameSeconds, 1.0 / fps);
            EXPECT_NE(std::find(front.begin(), front.end(), *chosen), front.end());
            for (const auto& x : m) {
                if (x.frameSeconds <= 1.0 / fps) {
                    EXPECT_GE(x.error, m[*chosen].error);
                }
            }
        }
    }
}

// A live slowdown of 2 chooses at 10 fps what twice the frame rate would choose unslowed; no
// slowdown changes nothing; a meaningless one chooses nothing.
TEST(QualityDial, SlowdownScalesTheBudget) {
    std::mt19937 rng(15);
    for (int trial = 0; trial < 20; ++trial) {
        const auto m = randomMeasurements(rng);
        EXPECT_EQ(chooseForFrameRate(m, 2.0, 2.0), chooseForFrameRate(m, 4.0));
        EXPECT_EQ(chooseForFrameRate(m, 4.0, 1.0), chooseForFrameRate(m, 4.0));
    }
    const auto m = randomMeasurements(rng);
    EXPECT_FALSE(chooseForFrameRate(m, 10.0, 0.0));
    EXPECT_FALSE(chooseForFrameRate(m, 10.0, std::nan("")));
}

// A held camera's depth (100 s budget): frames that take 99.5 s keep refinement's depth while
// they do and do not bring it back once dropped; 84 s, within kDialUpgradeMargin, does. A depth
// that costs under a tenth, or an unknown cost, keeps however slow the frames.
TEST(QualityDial, TheHeldDepthComesBackOnlyWithinTheMargin) {
    EXPECT_TRUE(holdKeepsRefineDepth(99.5, 1.105, 0.01, true));
    EXPECT_FALSE(holdKeepsRefineDepth(300.0, 3.0, 0.01, true));
    EXPECT_FALSE(holdKeepsRefineDepth(99.5, 1.105, 0.01, false));
    EXPECT_TRUE(holdKeepsRefineDepth(84.0, 1.2, 0.01, false));
    EXPECT_FALSE(holdKeepsRefineDepth(86.0, 1.2, 0.01, false));
    EXPECT_TRUE(holdKeepsRefineDepth(1e6, 1.05, 0.01, false));
    EXPECT_TRUE(holdKeepsRefineDepth(1e6, 1.0, 0.01, false));
}

// The live dial's costs: every measured time scaled by the slowdown; a point's own live time
// where it is longer and seen within kDialLiveMemoryWindows windows; a shorter one, or an older
// one, leaves the estimate.
TEST(QualityDial, APointSeenTooSlowLiveCostsWhatItTookForAWhile) {
    const std::vector<DialMeasurement> m = {{{}, 0.010, 0.3}, {{}, 0.020, 0.2}, {{}, 0.050, 0.1}};
    std::vector<std::optional<DialLiveTime>> live(3);
    live[1] = DialLiveTime{0.100, 5};
    live[2] = DialLiveTime{0.030, 5};
    std::vector<DialMeasurement> c = liveCosts(m, 1.5, live, 5);
    EXPECT_DOUBLE_EQ(c[0].frameSeconds, 0.015);
    EXPECT_DOUBLE_EQ(c[1].frameSeconds, 0.100) << "its own, longer";
    EXPECT_DOUBLE_EQ(c[2].frameSeconds, 0.075) << "its own is shorter: the estimate";
    EXPECT_DOUBLE_EQ(c[1].error, 0.2);
    c = liveCosts(m, 1.5, live, 5 + kDialLiveMemoryWindows - 1);
    EXPECT_DOUBLE_EQ(c[1].frameSeconds, 0.100) << "still remembered";
    c = liveCosts(m, 1.5, live, 5 + kDialLiveMemoryWindows);
    EXPECT_DOUBLE_EQ(c[1].frameSeconds, 0.030) << "forgotten";
    EXPECT_EQ(liveCosts(m, 1.0, {}, 0).size(), 3u);
    // At 15 fps (66.7 ms) the scaled estimate would take point 1; its own time keeps it out.
    EXPECT_EQ(chooseForFrameRate(liveCosts(m, 1.5, live, 5), 15.0), std::optional<size_t>(0));
    EXPECT_EQ(chooseForFrameRate(liveCosts(m, 1.5, {}, 5), 15.0), std::optional<size_t>(1));
}

// A point tried again after its memory lapsed and still too slow (over 66.7 ms at 15 fps) is
// remembered twice as long, up to the cap; while it stays in use its memory holds; frames within
// the budget start it afresh.
TEST(QualityDial, APointFoundTooSlowAgainIsRememberedLonger) {
    const double fps = 15.0;
    DialLiveTime t = nextLiveTime(std::nullopt, 0.080, 3, fps);
    EXPECT_EQ(t.memory, kDialLiveMemoryWindows) << "the first time";
    t = nextLiveTime(t, 0.080, 4, fps);
    EXPECT_EQ(t.memory, kDialLiveMemoryWindows) << "still in use: the next window";
    t = nextLiveTime(t, 0.075, 4 + kDialLiveMemoryWindows, fps);
    EXPECT_EQ(t.memory, 2 * kDialLiveMemoryWindows) << "tried again, too slow again";
    EXPECT_EQ(t.window, 4 + kDialLiveMemoryWindows);
    EXPECT_DOUBLE_EQ(t.seconds, 0.075);
    for (uint64_t w = 100; w < 1000; w += 100) t = nextLiveTime(t, 0.070, w, fps);
    EXPECT_EQ(t.memory, kDialLiveMemoryMaxWindows);
    // The longer memory keeps it out of liveCosts for its windows, then lets it be tried.
    const std::vector<DialMeasurement> m = {{{}, 0.030, 0.2}};
    std::vector<std::optional<DialLiveTime>> live{t};
    EXPECT_DOUBLE_EQ(
        liveCosts(m, 1.0, live, t.window + kDialLiveMemoryMaxWindows - 1)[0].frameSeconds, 0.070);
    EXPECT_DOUBLE_EQ(liveCosts(m, 1.0, live, t.window + kDialLiveMemoryMaxWindows)[0].frameSeconds,
                     0.030);
    t = nextLiveTime(t, 0.060, 2000, fps);
    EXPECT_EQ(t.memory, kDialLiveMemoryWindows) << "within the budget";
    // Within the budget before: a slow window now is a first time.
    EXPECT_EQ(nextLiveTime(DialLiveTime{0.050, 1}, 0.090, 20, fps).memory, kDialLiveMemoryWindows);
}

// Unmeasurable points (a failed run: NaN or infinite) are never chosen nor on the front; no
// frame rate or a zero one chooses nothing.
TEST(QualityDial, InvalidMeasurementsAndTargetsAreRefused) {
    std::vector<DialMeasurement> m = {
        {{1.0f, 1, 2, 0, 0}, 0.05, 0.1},
        {{0.5f, 1, 2, 0, 0}, std::nan(""), 0.01},
        {{0.25f, 1, 2, 0, 0}, 0.01, std::numeric_limits<double>::infinity()}};
    EXPECT_EQ(paretoFront(m), std::vector<size_t>{0});
    EXPECT_EQ(chooseForFrameRate(m, 10.0), 0u);
    EXPECT_FALSE(chooseForFrameRate(m, 0.0));
    EXPECT_FALSE(chooseForFrameRate(m, std::nan("")));
    EXPECT_FALSE(chooseForFrameRate(m, 1000.0));
}

// In the full grid a middle point has one neighbour per step along each axis.
TEST(QualityDial, GridNeighboursAreOneStepAway) {
    std::mt19937 rng(13);
    const auto m = randomMeasurements(rng);
    size_t middle = 0;
    for (size_t i = 0; i < m.size(); ++i)
        if (m[i].point.resolutionScale == 0.5f && m[i].point.samplesPerFrame == 2 &&
            m[i].point.maxDepth == 2)
            middle = i;
    const auto n = gridNeighbours(m, middle, kAxes);
    EXPECT_EQ(n.size(), 2u + 2u + 1u);  // scale ±1, samples ±1, depth +1 (2 is the smallest)
    for (size_t i : n) EXPECT_NE(i, middle);
}

// Every combination once; the axes not swept are 0 (off); the denoiser's and the photons'
// axes have neighbours like the others.
TEST(QualityDial, GridCoversEveryAxis) {
    const std::vector<DialPoint> plain = dialGrid(kAxes);
    EXPECT_EQ(plain.size(), 3u * 3u * 2u);
    for (const DialPoint& p : plain) {
        EXPECT_EQ(p.denoiseIterations, 0u);
        EXPECT_EQ(p.photons, 0u);
    }
    const std::vector<DialPoint> all = dialGrid(kAllAxes);
    EXPECT_EQ(all.size(), 2u * 2u * 2u * 3u * 2u);
    for (size_t i = 0; i < all.size(); ++i)
        for (size_t j = i + 1; j < all.size(); ++j)
            EXPECT_FALSE(all[i].resolutionScale == all[j].resolutionScale &&
                         all[i].samplesPerFrame == all[j].samplesPerFrame &&
                         all[i].maxDepth == all[j].maxDepth &&
                         all[i].denoiseIterations == all[j].denoiseIterations &&
                         all[i].photons == all[j].photons);
    std::mt19937 rng(14);
    const auto m = randomMeasurements(rng, kAllAxes);
    size_t corner = 0;  // scale 1, 1 spp, depth 2, denoised at strength 2, 4096 photons
    for (size_t i = 0; i < m.size(); ++i)
        if (m[i].point.resolutionScale == 1.0f && m[i].point.samplesPerFrame == 1 &&
            m[i].point.maxDepth == 2 && m[i].point.denoiseIterations == 2 &&
            m[i].point.photons == 4096)
            corner = i;
    // scale +1, samples +1, depth +1, strength ±1 (0 and 4), photons +1
    EXPECT_EQ(gridNeighbours(m, corner, kAllAxes).size(), 1u + 1u + 1u + 2u + 1u);
    EXPECT_EQ(m[corner].point.describe(),
              "scale 1/1, 1 spp, depth 2, denoised (2 levels), 4096 photons");
}

// A point is left out only when a point that costs no more on any axis already took longer
// than the budget (with the margin): never one a cheaper measurement says may fit.
TEST(QualityDial, OnlyPointsThatCannotFitArePruned) {
    const double budget = 0.1;
    const std::vector<DialMeasurement> measured = {
        {{0.5f, 2, 4, 0, 0}, budget * kDialPruneMargin * 1.01, 0.1},  // over the budget
        {{0.25f, 4, 4, 0, 0}, budget * 1.1, 0.1},                     // over, but within the margin
    };
    EXPECT_TRUE(cannotFit(measured, {0.5f, 2, 4, 2, 0}, budget));    // the same, denoised
    EXPECT_TRUE(cannotFit(measured, {1.0f, 2, 8, 0, 0}, budget));    // more on two axes
    EXPECT_FALSE(cannotFit(measured, {0.5f, 1, 8, 0, 0}, budget));   // fewer samples
    EXPECT_FALSE(cannotFit(measured, {0.25f, 4, 8, 0, 0}, budget));  // only the margin's point
    EXPECT_FALSE(cannotFit(measured, {0.5f, 2, 4, 0, 0}, 1.0));      // a larger budget
}

}  // namespace
}  // namespace previs
