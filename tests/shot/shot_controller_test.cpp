// The shot's rules (issue 35, shot/shot_controller.h) with a hand-advanced clock and a renderer
// whose samples cost a set time: refinement steps sized to the target, restarts, the stopping
// point, the preview's cap, the dial's live correction, mode changes, tracking's pace. previsd,
// `previs replay` and the service bench drive this same object; previsd_test.cpp checks replay.
#include "shot/shot_controller.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "tests/support/refine_config.h"

namespace previs {
namespace {

using namespace std::chrono_literals;

// Every sample costs `msPerSample` of the shot's clock, as a GPU would.
class FakeRenderer final : public ShotRenderer {
public:
    FakeRenderer(ManualShotClock& clock, double msPerSample) : ms_(msPerSample), clock_(clock) {}

    Status renderPreview(const TrackedFrame& frame,
                         const std::shared_ptr<const LiveLighting>&) override {
        const uint32_t spp = preview_.inUse.samplesPerFrame;
        spend(spp);
        samples_ = spp;
        rendered_ = frame.worldFromCamera.has_value();
        previews.push_back(spp);
        return {};
    }
    Status beginRefine(const TrackedFrame& frame,
                       const std::shared_ptr<const LiveLighting>&) override {
        samples_ = 0;
        rendered_ = frame.worldFromCamera.has_value();
        frozenOn.push_back(frame.frame ? frame.frame->sequence : 0);
        return {};
    }
    Status refineStep(uint32_t samples) override {
        spend(samples);
        samples_ += samples;
        steps.push_back(samples);
        return {};
    }
    uint64_t samples() const override { return samples_; }
    bool rendered() const override { return rendered_; }
    // Monte Carlo: 10 % at 1 spp.
    Result<std::optional<double>> measureNoise() override {
        ++looks;
        return std::optional<double>(0.1 / std::sqrt(double(samples_)));
    }
    PreviewState preview() const override { return preview_; }
    Status setPreview(const PreviewSettings& configured, uint32_t samplesInUse) override {
        preview_ = {configured, configured};
        preview_.inUse.samplesPerFrame = std::min(samplesInUse, configured.samplesPerFrame);
        return {};
    }
    bool hasDial() const override { return dial; }
    bool lastPreviewOffDial() const override { return offDial; }
    // Call `pointChangeAt` (counting from 1) moves to another point; `depthChangeAt` changes
    // only the held camera's depth.
    std::optional<std::string> adaptDial(double liveFrameSeconds, double heldCost) override {
        dialCorrections.push_back(liveFrameSeconds);
        heldCosts.push_back(heldCost);
        if (dialCorrections.size() == depthChangeAt) return "the held camera's depth";
        if (dialCorrections.size() != pointChangeAt) return std::nullopt;
        PreviewSettings cheaper = preview_.configured;
        cheaper.resolutionScale /= 2;
        preview_ = {cheaper, cheaper};
        return "a cheaper point";
    }
    bool lightingPending() const override { return pending; }
    // A reading whose ratio is the number of readings so far (so a test can tell them apart).
    Result<std::optional<PlateConsistency>> measurePlateConsistency() override {
        ++plateReadings;
        PlateConsistency c;
        c.ratio = {double(plateReadings), 1.0, 1.0};
        c.pixels = 100;
        c.ok = true;
        return std::optional<PlateConsistency>(c);
    }
    // The lighting fit after each reading: `nextFit`, once (then not needed).
    LightingFitReport fitLighting(const TrackedFrame&, const PlateConsistency&) override {
        ++fits;
        LightingFitReport r = nextFit;
        nextFit = {};
        return r;
    }

    bool dial = false;
    bool offDial = false;
    size_t pointChangeAt = 0, depthChangeAt = 0;
    std::vector<uint32_t> previews, steps;
    std::vector<uint64_t> frozenOn;
    std::vector<double> dialCorrections, heldCosts;
    int looks = 0;
    int plateReadings = 0;
    int fits = 0;
    LightingFitReport nextFit;
    bool pending = false;
    double ms_;

private:
    void spend(uint32_t samples) {
        clock_.advance(std::chrono::nanoseconds(int64_t(ms_ * 1e6 * samples)));
    }
    ManualShotClock& clock_;
    PreviewState preview_;
    uint64_t samples_ = 0;
    bool rendered_ = false;
};

cv::Matx44d panned(double deg) {
    const double a = deg * M_PI / 180.0, c = std::cos(a), s = std::sin(a);
    return {c, 0, s, 0, 0, 1, 0, 0, -s, 0, c, 0, 0, 0, 0, 1};
}

std::shared_ptr<const TrackedFrame> frame(uint64_t sequence, double panDeg = 0.0) {
    auto f = std::make_shared<TrackedFrame>();
    auto camera = std::make_shared<Frame>();
    camera->sequence = sequence;
    f->frame = camera;
    f->worldFromCamera = panned(panDeg);
    f->lost = false;
    return f;
}

RefineConfig refineConfig() {
    RefineConfig c = testing::restartRuleConfig();
    c.samplesPerStep = 16;
    c.maxSamples = 0;
    c.targetNoise = 0.0;
    return c;
}

struct Fixture {
    ManualShotClock clock;
    FakeRenderer renderer;
    ModeMachine modes;
    ShotController shot;
    explicit Fixture(double msPerSample, RefineConfig refine = refineConfig(),
                     Mode mode = Mode::Preview)
        : renderer(clock, msPerSample), modes(mode), shot(renderer, modes, clock, refine) {}
};

TEST(ShotController, PreviewRendersEveryFrameAndNothingWithout) {
    Fixture f(10.0);
    Result<ShotStep> none = f.shot.step(nullptr, nullptr);
    ASSERT_TRUE(none) << none.message();
    EXPECT_EQ(none->kind, ShotStep::Kind::NoFrame);
    EXPECT_TRUE(f.shot.wantsFrame());
    for (uint64_t i = 0; i < 5; ++i) {
        Result<ShotStep> s = f.shot.step(frame(i), nullptr);
        ASSERT_TRUE(s) << s.message();
        EXPECT_EQ(s->kind, ShotStep::Kind::Previewed);
        EXPECT_EQ(s->shown->frame->sequence, i);
        f.clock.advance(50ms);  // the camera's next frame
    }
    EXPECT_EQ(f.renderer.previews.size(), 5u);
    EXPECT_NEAR(f.shot.step(frame(5), nullptr)->fps, 1.0 / 0.06, 0.5);
}

TEST(ShotController, RefinementStepsAreSizedToTheTargetAndStopAtMaxSamples) {
    // 100 ms a sample: the first step is samples_per_step (nothing measured yet), then 250 ms'
    // worth (2); max_samples cuts the last one short and then the shot holds.
    RefineConfig c = refineConfig();
    c.maxSamples = 25;
    Fixture f(100.0, c, Mode::Refine);
    ASSERT_EQ(f.shot.step(frame(7), nullptr)->kind, ShotStep::Kind::Refined);
    EXPECT_FALSE(f.shot.wantsFrame()) << "refining: take a frame only if there is one";
    for (int i = 0; i < 8; ++i) ASSERT_TRUE(f.shot.step(nullptr, nullptr));
    EXPECT_EQ(f.renderer.frozenOn, std::vector<uint64_t>{7});
    const std::vector<uint32_t> expected{16, 2, 2, 2, 2, 1};
    EXPECT_EQ(f.renderer.steps, expected);
    Result<ShotStep> held = f.shot.step(nullptr, nullptr);
    EXPECT_EQ(held->kind, ShotStep::Kind::Held);
    EXPECT_EQ(held->shown->frame->sequence, 7u);
    EXPECT_EQ(f.renderer.samples(), 25u);
}

TEST(ShotController, RefinementStopsAtTheTargetNoiseWithAnEta) {
    // 10 % at 1 spp: 1 % at 100 spp. The meter looks at growing counts; the ETA falls to 0.
    RefineConfig c = refineConfig();
    c.samplesPerStep = 4;
    c.targetNoise = 0.01;
    Fixture f(1.0, c, Mode::Refine);
    std::optional<double> firstEta;
    for (int i = 0; i < 200; ++i) {
        Result<ShotStep> s = f.shot.step(i == 0 ? frame(0) : nullptr, nullptr);
        ASSERT_TRUE(s);
        if (s->kind == ShotStep::Kind::Held) break;
        if (!firstEta) firstEta = s->etaSeconds;
        if (s->converged) {
            EXPECT_EQ(s->etaSeconds.value_or(-1.0), 0.0);
        }
    }
    ASSERT_TRUE(firstEta);
    EXPECT_GT(*firstEta, 0.0);
    EXPECT_GE(f.renderer.samples(), 100u);
    EXPECT_LT(f.renderer.samples(), 160u) << "a look soon after the target is reached";
    EXPECT_LT(f.renderer.looks, 20) << "looks grow geometrically, not one a step";
}

TEST(ShotController, AMoveRestartsAfterRestartAfterPosesAndAnOutlierDoesNot) {
    Fixture f(1.0, refineConfig(), Mode::Refine);
    ASSERT_TRUE(f.shot.step(frame(0), nullptr));
    ASSERT_TRUE(f.shot.step(frame(1, 2.0), nullptr));  // one outlier
    ASSERT_TRUE(f.shot.step(frame(2), nullptr));
    EXPECT_EQ(f.shot.restarts(), 0u);
    for (uint64_t i = 3; i < 6; ++i) {
        Result<ShotStep> s = f.shot.step(frame(i, 2.0), nullptr);
        ASSERT_TRUE(s);
        EXPECT_EQ(s->restarted, i == 5) << "frame " << i;
    }
    EXPECT_EQ(f.shot.restarts(), 1u);
    EXPECT_EQ(f.renderer.frozenOn, (std::vector<uint64_t>{0, 5}));
    EXPECT_EQ(f.shot.frozen()->frame->sequence, 5u) << "re-frozen on the moved view";
}

TEST(ShotController, OutOfRefinementAndBackWithinOneStepRefreezes) {
    Fixture f(1.0, refineConfig(), Mode::Refine);
    ASSERT_TRUE(f.shot.step(frame(0), nullptr));
    f.modes.toggle("test");
    f.modes.toggle("test");
    EXPECT_TRUE(f.shot.wantsFrame());
    ASSERT_TRUE(f.shot.step(frame(1), nullptr));
    EXPECT_EQ(f.renderer.frozenOn, (std::vector<uint64_t>{0, 1}));
    f.modes.set(Mode::Preview, "test");
    EXPECT_EQ(f.shot.step(frame(2), nullptr)->kind, ShotStep::Kind::Previewed);
    EXPECT_EQ(f.shot.renderedMode(), Mode::Preview);
}

// A reload's live settings: [refine], and [render] samples_per_frame.
LiveConfig liveConfig(uint32_t samplesPerFrame) {
    LiveConfig c;
    c.refine = refineConfig();
    c.liveRender.samplesPerFrame = samplesPerFrame;
    return c;
}

TEST(ShotController, APreviewFrameIsCappedToItsLongestTime) {
    // 4 samples a frame at 1 s each would take 4 s: after the first frame, 3 s' worth.
    Fixture f(1000.0);
    f.shot.setConfig(liveConfig(4));
    for (uint64_t i = 0; i < 3; ++i) ASSERT_TRUE(f.shot.step(frame(i), nullptr));
    EXPECT_EQ(f.renderer.previews, (std::vector<uint32_t>{4, 3, 3}));
    // A new configured count (SIGHUP) is taken, then capped again by what it costs.
    f.renderer.ms_ = 10.0;
    f.shot.setConfig(liveConfig(8));
    for (uint64_t i = 3; i < 5; ++i) ASSERT_TRUE(f.shot.step(frame(i), nullptr));
    EXPECT_EQ(f.renderer.previews.back(), 8u);
}

// Where the dial runs it chooses preview's samples: a reload's samples_per_frame leaves its
// choice, and the reload's [refine] still applies.
TEST(ShotController, AReloadLeavesTheDialsSamples) {
    Fixture f(1.0);
    f.renderer.dial = true;
    PreviewSettings dialsChoice;
    dialsChoice.samplesPerFrame = 2;
    ASSERT_TRUE(f.renderer.setPreview(dialsChoice, 2));
    LiveConfig reloaded = liveConfig(8);
    reloaded.refine.samplesPerStep = 4;
    f.shot.setConfig(reloaded);
    ASSERT_TRUE(f.shot.step(frame(0), nullptr));
    EXPECT_EQ(f.renderer.previews, (std::vector<uint32_t>{2}));
    f.modes.set(Mode::Refine, "test");
    ASSERT_EQ(f.shot.step(frame(1), nullptr)->kind, ShotStep::Kind::Refined);
    EXPECT_EQ(f.renderer.steps, (std::vector<uint32_t>{4})) << "the reload's samples_per_step";
}

TEST(ShotController, TheDialIsCorrectedOnTheMedianOfAWindowOfLiveFrames) {
    Fixture f(20.0);
    f.renderer.dial = true;
    for (uint64_t i = 0; i < 2 * ShotController::kDialWindowFrames; ++i) {
        f.renderer.ms_ = i % 3 == 0 ? 200.0 : 20.0;  // an occasional slow frame
        ASSERT_TRUE(f.shot.step(frame(i), nullptr));
    }
    ASSERT_EQ(f.renderer.dialCorrections.size(), 2u);
    EXPECT_NEAR(f.renderer.dialCorrections[0], 0.020, 1e-9) << "the median, not the mean";
}

// A caller that shows its frames (the service) corrects the dial on each frame's whole time,
// render to readback (previewShown), not on the render's alone: the display pass shares the
// frame's budget.
TEST(ShotController, TheDialIsCorrectedOnTheWholeTimeOfTheFramesShown) {
    Fixture f(20.0);
    f.renderer.dial = true;
    for (uint64_t i = 0; i < ShotController::kDialWindowFrames; ++i) {
        EXPECT_TRUE(f.renderer.dialCorrections.empty()) << "each frame counts once";
        ASSERT_TRUE(f.shot.step(frame(i), nullptr));
        f.shot.previewShown(0.050);  // 20 ms of render, 30 more to the monitor
    }
    ASSERT_EQ(f.renderer.dialCorrections.size(), 1u);
    EXPECT_NEAR(f.renderer.dialCorrections[0], 0.050, 1e-9);
}

// Preview frames of one kind in a row: `held` (off the dial's point) or not, each taking
// `ms` of the shot's clock.
void previewFrames(Fixture& f, size_t count, bool held, double ms) {
    f.renderer.offDial = held;
    f.renderer.ms_ = ms;
    for (size_t i = 0; i < count; ++i) ASSERT_TRUE(f.shot.step(frame(i), nullptr));
}

// The dial's corrections in order: the point's seconds each window handed it, and the held cost
// it was handed with.
void expectCorrections(const Fixture& f, const std::vector<double>& seconds,
                       const std::vector<double>& heldCosts) {
    ASSERT_EQ(f.renderer.dialCorrections.size(), seconds.size())
        << "every window corrects the dial";
    for (size_t i = 0; i < seconds.size(); ++i) {
        EXPECT_NEAR(f.renderer.dialCorrections[i], seconds[i], 1e-9) << "window " << i;
        EXPECT_NEAR(f.renderer.heldCosts[i], heldCosts[i], 1e-9) << "window " << i;
    }
}

// A held camera's frames trace refinement's depth, off the dial's point ([render]
// preview_hold_depth): they re-time the dial too, as the point's own time, by the held cost that
// the hold's first window measured against the moving frames before it. A hold at a steady load
// leaves the correction where the moving frames put it; a load that doubles during the hold
// doubles it; the first moving window after the hold pairs with the hold's last.
TEST(ShotController, HeldFramesReTimeTheDialOnTheLoadNotOnTheirDepth) {
    Fixture f(20.0);
    f.renderer.dial = true;
    const size_t window = ShotController::kDialWindowFrames;
    previewFrames(f, window, false, 20.0);
    previewFrames(f, window, true, 50.0);  // deeper paths: 2.5x the point's frames
    previewFrames(f, window, true, 50.0);
    previewFrames(f, window, true, 100.0);  // another process takes half the box
    previewFrames(f, window, false, 40.0);  // the camera moves again
    expectCorrections(f, {0.020, 0.020, 0.020, 0.040, 0.040}, {1.0, 2.5, 2.5, 2.5, 2.5});
}

// The moving frames' unfinished window (5 of them after a whole window) pairs with the hold's
// first window only: the hold's second, at twice the load, is that load's, not a dearer depth's.
// Likewise the moving frames after the hold pair with the hold's unfinished window once.
TEST(ShotController, TheFramesBeforeAHoldPairWithItsFirstWindowOnly) {
    Fixture f(20.0);
    f.renderer.dial = true;
    const size_t window = ShotController::kDialWindowFrames;
    previewFrames(f, window + 5, false, 20.0);
    previewFrames(f, window, true, 50.0);
    previewFrames(f, window, true, 100.0);  // another process takes half the box
    previewFrames(f, 5, true, 100.0);
    previewFrames(f, window, false, 40.0);
    previewFrames(f, window, false, 20.0);  // the other process has gone
    expectCorrections(f, {0.020, 0.020, 0.040, 0.040, 0.020}, {1.0, 2.5, 2.5, 2.5, 2.5});
}

// A held view's frames can be quicker than the point's (BENCHMARKS.md measures 0.88-0.98): the
// held cost is what was measured, so a hold at a steady load re-times the dial as the moving
// frames did, not as a quieter box.
TEST(ShotController, AHeldCostUnderOneIsKeptAsMeasured) {
    Fixture f(20.0);
    f.renderer.dial = true;
    const size_t window = ShotController::kDialWindowFrames;
    previewFrames(f, window, false, 20.0);
    previewFrames(f, window, true, 18.0);
    previewFrames(f, window, true, 18.0);
    ASSERT_EQ(f.renderer.dialCorrections.size(), 3u);
    EXPECT_NEAR(f.renderer.heldCosts[1], 0.9, 1e-9);
    EXPECT_NEAR(f.renderer.dialCorrections[2], 0.020, 1e-9) << "the same load";
}

// A change of the dial's point starts both windows over and forgets the held cost (a ratio at
// the old point's depth): the hold's frames at the new point count as they are until the camera
// moves, whose first window measures the cost at the new point.
TEST(ShotController, ANewDialPointStartsTheHeldCostOver) {
    Fixture f(20.0);
    f.renderer.dial = true;
    f.renderer.pointChangeAt = 2;
    const size_t window = ShotController::kDialWindowFrames;
    previewFrames(f, window, false, 20.0);
    previewFrames(f, window, true, 50.0);  // 2.5x; the dial moves to a cheaper point
    previewFrames(f, window, true, 30.0);
    previewFrames(f, window, false, 10.0);
    ASSERT_EQ(f.renderer.dialCorrections.size(), 4u);
    EXPECT_NEAR(f.renderer.heldCosts[1], 2.5, 1e-9);
    EXPECT_NEAR(f.renderer.dialCorrections[2], 0.030, 1e-9) << "as they are";
    EXPECT_NEAR(f.renderer.heldCosts[2], 1.0, 1e-9) << "unknown at the new point";
    EXPECT_NEAR(f.renderer.dialCorrections[3], 0.010, 1e-9);
    EXPECT_NEAR(f.renderer.heldCosts[3], 3.0, 1e-9) << "measured at the new point";
}

// A hold that closes its window within a few moving frames leaves the moving kind's unfinished
// window behind: a change of point there starts it over, so the new point's first moving window
// is its own frames only.
TEST(ShotController, ANewDialPointStartsTheOtherKindsWindowOver) {
    Fixture f(20.0);
    f.renderer.dial = true;
    f.renderer.pointChangeAt = 1;
    previewFrames(f, 10, true, 50.0);
    previewFrames(f, 10, false, 20.0);
    previewFrames(f, 5, true, 50.0);  // the held window closes: 2.5x; the dial moves
    previewFrames(f, ShotController::kDialWindowFrames, false, 10.0);
    ASSERT_EQ(f.renderer.dialCorrections.size(), 2u);
    EXPECT_NEAR(f.renderer.heldCosts[0], 2.5, 1e-9);
    EXPECT_NEAR(f.renderer.dialCorrections[1], 0.010, 1e-9) << "the new point's frames only";
}

// A change of the held camera's depth alone is no new point: the moving window before it pairs
// with the hold's first.
TEST(ShotController, AChangeOfTheHeldDepthAloneKeepsThePair) {
    Fixture f(20.0);
    f.renderer.dial = true;
    f.renderer.depthChangeAt = 1;
    const size_t window = ShotController::kDialWindowFrames;
    previewFrames(f, window, false, 20.0);
    previewFrames(f, window, true, 50.0);
    ASSERT_EQ(f.renderer.dialCorrections.size(), 2u);
    EXPECT_NEAR(f.renderer.heldCosts[1], 2.5, 1e-9);
    EXPECT_NEAR(f.renderer.dialCorrections[1], 0.020, 1e-9);
}

// A camera held since the start has no moving frames to measure the held cost against: its
// frames count as they are (the dial then keeps them at the rate), with the cost unknown (1).
// Once it moves, the first moving window pairs with the hold's last and the cost is known.
TEST(ShotController, ACameraHeldSinceTheStartTimesItsFramesAsTheyAre) {
    Fixture f(20.0);
    f.renderer.dial = true;
    const size_t window = ShotController::kDialWindowFrames;
    previewFrames(f, window, true, 60.0);
    previewFrames(f, window, false, 20.0);
    previewFrames(f, window, true, 60.0);
    ASSERT_EQ(f.renderer.dialCorrections.size(), 3u);
    EXPECT_NEAR(f.renderer.dialCorrections[0], 0.060, 1e-9);
    EXPECT_NEAR(f.renderer.heldCosts[0], 1.0, 1e-9);
    EXPECT_NEAR(f.renderer.dialCorrections[1], 0.020, 1e-9);
    EXPECT_NEAR(f.renderer.heldCosts[1], 3.0, 1e-9);
    EXPECT_NEAR(f.renderer.dialCorrections[2], 0.020, 1e-9) << "the same load";
}

// A pose that jitters about the held threshold interleaves the two kinds (two frames of three
// held, 25x dearer): each kind's window is corrected on the point's own time at the one load.
TEST(ShotController, AJitteringHoldTimesBothKindsAtOneLoad) {
    Fixture f(20.0);
    f.renderer.dial = true;
    for (uint64_t i = 0; i < 3 * ShotController::kDialWindowFrames; ++i) {
        f.renderer.offDial = i % 3 != 0;
        f.renderer.ms_ = f.renderer.offDial ? 500.0 : 20.0;
        ASSERT_TRUE(f.shot.step(frame(i), nullptr));
    }
    ASSERT_EQ(f.renderer.dialCorrections.size(), 3u);
    for (double s : f.renderer.dialCorrections) EXPECT_NEAR(s, 0.020, 1e-9);
    EXPECT_NEAR(f.renderer.heldCosts.back(), 25.0, 1e-9);
}

// The plate-consistency meter reads with a trusted pose only, once per view and lighting (a new
// one beyond [refine]'s restart thresholds), at most every kPlateMeterPeriod.
TEST(ShotController, ThePlateMeterReadsOnATrustedPoseWhenTheViewOrLightingChanges) {
    Fixture f(20.0);
    auto untracked = std::make_shared<TrackedFrame>(*frame(0));
    untracked->worldFromCamera.reset();
    untracked->lost = true;
    Result<ShotStep> s = f.shot.step(untracked, nullptr);
    ASSERT_TRUE(s);
    EXPECT_FALSE(s->plateConsistency) << "nothing rendered";
    auto held = std::make_shared<TrackedFrame>(*frame(1));
    held->lost = true;  // tracking lost, the last pose held
    ASSERT_TRUE(s = f.shot.step(held, nullptr));
    EXPECT_FALSE(s->plateConsistency) << "a held pose is not trusted";
    EXPECT_EQ(f.renderer.plateReadings, 0);
    f.renderer.pending = true;
    ASSERT_TRUE(s = f.shot.step(frame(2), nullptr));
    EXPECT_FALSE(s->plateConsistency) << "lit by a stand-in";
    EXPECT_EQ(f.renderer.plateReadings, 0);
    f.renderer.pending = false;  // the first snapshot: read at once, not a period later

    ASSERT_TRUE(s = f.shot.step(frame(2), nullptr));
    ASSERT_TRUE(s->plateConsistency);
    EXPECT_EQ(s->plateConsistency->frame, 2u);
    EXPECT_EQ(s->plateConsistency->value.ratio[0], 1.0);
    // The same view a while later: nothing new to read.
    f.clock.advance(2s);
    ASSERT_TRUE(s = f.shot.step(frame(3), nullptr));
    EXPECT_FALSE(s->plateConsistency);
    // Within the threshold (0.5 deg): still the same view.
    f.clock.advance(2s);
    ASSERT_TRUE(s = f.shot.step(frame(4, 0.3), nullptr));
    EXPECT_FALSE(s->plateConsistency);
    // A new view, but within a period of the last reading: not yet; after it, read.
    ASSERT_TRUE(s = f.shot.step(frame(5, 5.0), nullptr));
    ASSERT_TRUE(s->plateConsistency) << "2 s since the last";
    ASSERT_TRUE(s = f.shot.step(frame(6, 10.0), nullptr));
    EXPECT_FALSE(s->plateConsistency) << "40 ms since the last";
    f.clock.advance(ShotController::kPlateMeterPeriod);
    ASSERT_TRUE(s = f.shot.step(frame(7, 10.0), nullptr));
    ASSERT_TRUE(s->plateConsistency);
    EXPECT_EQ(f.renderer.plateReadings, 3);
    ASSERT_TRUE(f.shot.plateConsistency());
    EXPECT_EQ(f.shot.plateConsistency()->frame, 7u);

    // Lighting: a first snapshot is a change; a small one is not; a large one is.
    auto lit = [](double level) {
        auto l = std::make_shared<LiveLighting>();
        l->luminanceSh[0] = level;
        return std::shared_ptr<const LiveLighting>(l);
    };
    f.clock.advance(2s);
    ASSERT_TRUE(s = f.shot.step(frame(8, 10.0), lit(1.0)));
    EXPECT_TRUE(s->plateConsistency);
    f.clock.advance(2s);
    ASSERT_TRUE(s = f.shot.step(frame(9, 10.0), lit(1.01)));
    EXPECT_FALSE(s->plateConsistency) << "1 % is within lighting_threshold";
    f.clock.advance(2s);
    ASSERT_TRUE(s = f.shot.step(frame(10, 10.0), lit(1.5)));
    EXPECT_TRUE(s->plateConsistency);
    EXPECT_EQ(f.renderer.plateReadings, 5);
}

// Refinement: the first step of a new view reads (its accumulation so far), and the step that
// converges reads again, on the same view, whatever the period: its L_or has the most samples.
TEST(ShotController, ThePlateMeterReadsAgainAsRefinementConverges) {
    RefineConfig c = refineConfig();
    c.maxSamples = 25;
    Fixture f(1.0, c, Mode::Refine);
    std::vector<int> readOn;  // step indices with a reading
    for (int i = 0; i < 10; ++i) {
        Result<ShotStep> s = f.shot.step(i == 0 ? frame(7) : nullptr, nullptr);
        ASSERT_TRUE(s);
        if (s->plateConsistency) {
            readOn.push_back(i);
            EXPECT_EQ(s->plateConsistency->frame, 7u);
            EXPECT_EQ(s->converged, i > 0) << "step " << i;
        }
    }
    EXPECT_EQ(readOn.size(), 2u);
    EXPECT_EQ(f.renderer.plateReadings, 2);
}

// A fit that changes the lighting while refining starts the accumulation over (its samples were
// lit by the lighting before); one that failed does not, and is kept for the status.
TEST(ShotController, ALightingFitRestartsRefinementAndAFailedOneDoesNot) {
    Fixture f(1.0, refineConfig(), Mode::Refine);
    f.renderer.nextFit.state = LightingFitReport::State::Fitted;
    f.renderer.nextFit.changed = true;
    Result<ShotStep> s = f.shot.step(frame(7), nullptr);
    ASSERT_TRUE(s);
    ASSERT_TRUE(s->lightingFit.has_value());
    EXPECT_EQ(s->lightingFit->state, LightingFitReport::State::Fitted);
    s = f.shot.step(nullptr, nullptr);
    ASSERT_TRUE(s);
    EXPECT_TRUE(s->restarted);
    EXPECT_EQ(f.renderer.frozenOn.size(), 2u);

    Fixture g(1.0, refineConfig(), Mode::Refine);
    g.renderer.nextFit.state = LightingFitReport::State::Failed;
    g.renderer.nextFit.why = "too few samples";
    ASSERT_TRUE(g.shot.step(frame(7), nullptr));
    s = g.shot.step(nullptr, nullptr);
    ASSERT_TRUE(s);
    EXPECT_FALSE(s->restarted);
    ASSERT_TRUE(g.shot.lightingFit().has_value());
    EXPECT_EQ(g.shot.lightingFit()->why, "too few samples");
}

TEST(TrackingPace, EveryFrameInPreviewAFewASecondRefining) {
    TrackingPace pace;
    const uint64_t period = 66'666'667;  // 15 fps
    int tracked = 0;
    for (uint64_t i = 0; i < 15; ++i) tracked += pace.due(Mode::Preview, i * period);
    EXPECT_EQ(tracked, 15);
    std::vector<uint64_t> refining;
    for (uint64_t i = 15; i < 45; ++i)
        if (pace.due(Mode::Refine, i * period)) refining.push_back(i);
    // 250 ms at 66.7 ms a frame: every 4th frame.
    EXPECT_EQ(refining, (std::vector<uint64_t>{18, 22, 26, 30, 34, 38, 42}));
    EXPECT_TRUE(pace.due(Mode::Refine, 0)) << "a looping recording's clock starts over";
}

}  // namespace
}  // namespace previs
