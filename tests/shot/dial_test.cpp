// The dial in the service ([render] preview_fps, shot/pipeline_renderer.h) on the demo's
// scene at a small size: what it measured, that its choice is on the front of its own
// measurements and is what preview then renders with, and that refinement keeps max_depth and
// every pixel. No timing is asserted (a loaded CI machine decides which point fits); the two
// extremes of the target make the choice deterministic in kind.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "config/service_config.h"
#include "gpu/context.h"
#include "scene/scene_description.h"
#include "shot/pipeline_renderer.h"
#include "tests/shot/pipeline_renderer_access.h"
#include "tests/support/scene_builders.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

struct Demo {
    ServiceConfig config;
    Scene scene;
};

Demo demo(double previewFps) {
    Result<ServiceConfig> config =
        loadServiceConfig(::previs::testing::sourcePath("examples/demo/previsd.toml"));
    EXPECT_TRUE(config) << config.message();
    Demo d{*config, {}};
    d.config.render.width = 64;
    d.config.render.height = 36;
    d.config.render.maxDepth = 6;
    d.config.render.previewFps = previewFps;
    d.config.render.denoise = "off";  // no strength axis: the counts below are of the other three
    Result<Scene> scene = loadScene(d.config.scenePath);
    EXPECT_TRUE(scene) << scene.message();
    d.scene = std::move(*scene);
    return d;
}

// A camera frame of one mid grey (code 118: about 18 % linear through the sRGB curve).
std::shared_ptr<Frame> greyFrame(uint32_t width, uint32_t height) {
    auto f = std::make_shared<Frame>();
    f->width = width;
    f->height = height;
    f->rgb.assign(size_t(width) * height * 3, 118);
    return f;
}

// Each case starts the service's renderer on the demo (its create runs the dial) on one device.
class Dial : public ::testing::Test {
protected:
    void SetUp() override {
        Result<std::unique_ptr<GpuContext>> ctx = GpuContext::create({});
        ASSERT_TRUE(ctx) << ctx.message();
        ctx_ = std::move(*ctx);
    }

    // The live corrections' start: `d` at a rate every point reaches, so the dial chose its most
    // accurate point (best_); quickest_ is the fastest point it measured.
    void startAtRest(const Demo& d) {
        auto p = PipelineRenderer::create(*ctx_, d.scene, d.config);
        ASSERT_TRUE(p) << p.message();
        renderer_ = std::move(*p);
        ASSERT_TRUE(renderer_->dialChoice());
        best_ = *renderer_->dialChoice();
        quickest_ = *fastest(renderer_->dialMeasurements());
    }

    std::unique_ptr<GpuContext> ctx_;
    std::unique_ptr<PipelineRenderer> renderer_;  // after ctx_: destroyed before it
    size_t best_ = 0;
    size_t quickest_ = 0;
};

// Every frame rate is reachable at 1 fps here: the most accurate of all 30 settings.
TEST_F(Dial, ASlowTargetTakesTheMostAccurateSetting) {
    Demo d = demo(0.01);
    auto p = PipelineRenderer::create(*ctx_, d.scene, d.config);
    ASSERT_TRUE(p) << p.message();
    const auto& m = (*p)->dialMeasurements();
    ASSERT_EQ(m.size(), 5u * 3u * 2u);  // depths 2 and 4 only: max_depth is 6
    ASSERT_TRUE((*p)->dialChoice());
    const size_t chosen = *(*p)->dialChoice();
    for (const DialMeasurement& x : m) {
        EXPECT_GT(x.frameSeconds, 0.0);
        EXPECT_GE(x.error, m[chosen].error);
        EXPECT_LE(x.point.maxDepth, 6u);
    }
    const std::vector<size_t> front = paretoFront(m);
    EXPECT_NE(std::find(front.begin(), front.end(), chosen), front.end());
    // Preview renders with the choice; refinement with max_depth at full resolution.
    EXPECT_EQ((*p)->previewSamples(), m[chosen].point.samplesPerFrame);
    EXPECT_EQ((*p)->previewResolutionScale(), m[chosen].point.resolutionScale);
    EXPECT_EQ((*p)->previewMaxDepth(), m[chosen].point.maxDepth);
    EXPECT_EQ(testing::innerRenderer(**p).maxDepth(), 6u);
    EXPECT_EQ(testing::innerRenderer(**p).resolutionScale(), 1.0f);
}

// An unreachable rate: no choice, and preview falls back to the fastest setting measured. The
// start's hooks hear the dial's stage with its 30 settings, then each one done, those pruned
// included: 0/30 up to 30/30 (previsd's status while starting).
TEST_F(Dial, AnUnreachableTargetTakesTheFastest) {
    // Large enough that even the cheapest point (107×60 traced) cannot reach 240 fps here; the
    // dial times only that one (the rest cost more on every axis and are pruned).
    Demo d = demo(240.0);
    d.config.render.width = 640;
    d.config.render.height = 360;
    std::vector<std::pair<std::string, size_t>> stages;
    std::vector<std::pair<size_t, size_t>> progress;
    PipelineStartHooks hooks;
    hooks.stage = [&](const std::string& what, size_t steps) { stages.emplace_back(what, steps); };
    // The dial's steps only: the pipelines' compile counts come through the same hook first.
    hooks.progress = [&](size_t done, size_t total) {
        if (!stages.empty() && stages.back().first.starts_with("timing the preview's settings"))
            progress.emplace_back(done, total);
    };
    auto p = PipelineRenderer::create(*ctx_, d.scene, d.config, hooks);
    ASSERT_TRUE(p) << p.message();
    const auto& m = (*p)->dialMeasurements();
    ASSERT_FALSE(m.empty());
    const size_t grid = 5u * 3u * 2u;
    ASSERT_FALSE(stages.empty());
    EXPECT_EQ(stages.back(),
              std::make_pair(std::string("timing the preview's settings for 240 fps"), grid));
    ASSERT_EQ(progress.size(), grid + 1);
    for (size_t i = 0; i <= grid; ++i) EXPECT_EQ(progress[i], std::make_pair(i, grid));
    if ((*p)->dialChoice()) GTEST_SKIP() << "this device renders 640x360 at 240 fps";
    double fastest = m[0].frameSeconds;
    for (const DialMeasurement& x : m) fastest = std::min(fastest, x.frameSeconds);
    bool previewIsFastest = false;
    for (const DialMeasurement& x : m)
        previewIsFastest |= x.frameSeconds == fastest &&
                            x.point.samplesPerFrame == (*p)->previewSamples() &&
                            x.point.resolutionScale == (*p)->previewResolutionScale() &&
                            x.point.maxDepth == (*p)->previewMaxDepth();
    EXPECT_TRUE(previewIsFastest);
}

// The live correction: frames far slower than measured move preview to the fastest point;
// frames as fast as measured move it back to the most accurate one that fits, save the point
// whose own frames were seen too slow, until kDialLiveMemoryWindows windows have passed; the
// same observation again changes nothing.
TEST_F(Dial, LiveFramesSlowerThanMeasuredMovePreviewToACheaperPoint) {
    ASSERT_NO_FATAL_FAILURE(startAtRest(demo(0.01)));
    PipelineRenderer& r = *renderer_;
    const auto& m = r.dialMeasurements();
    ASSERT_NE(best_, quickest_);
    // 10^4 times slower than measured: at 0.01 fps nothing fits any more.
    std::optional<std::string> moved = r.adaptDial(m[best_].frameSeconds * 1e4 * 1e2, 1.0);
    ASSERT_TRUE(moved);
    EXPECT_FALSE(r.dialChoice());
    EXPECT_EQ(r.previewSamples(), m[quickest_].point.samplesPerFrame);
    EXPECT_EQ(r.previewResolutionScale(), m[quickest_].point.resolutionScale);
    EXPECT_EQ(r.previewMaxDepth(), m[quickest_].point.maxDepth);
    // As fast as measured: a dearer point, not the one seen too slow in window 1.
    moved = r.adaptDial(m[quickest_].frameSeconds, 1.0);
    ASSERT_TRUE(moved);
    ASSERT_TRUE(r.dialChoice());
    EXPECT_NE(*r.dialChoice(), best_);
    for (uint64_t window = 3; window <= kDialLiveMemoryWindows; ++window) {
        r.adaptDial(m[*r.dialChoice()].frameSeconds, 1.0);
        ASSERT_TRUE(r.dialChoice());
        EXPECT_NE(*r.dialChoice(), best_) << "window " << window;
    }
    // Its own time forgotten: the most accurate.
    ASSERT_TRUE(r.adaptDial(m[*r.dialChoice()].frameSeconds, 1.0));
    EXPECT_EQ(r.dialChoice(), best_);
    EXPECT_EQ(r.previewSamples(), m[best_].point.samplesPerFrame);
    EXPECT_FALSE(r.adaptDial(m[best_].frameSeconds, 1.0));
}

// A held camera's frames trace refinement's depth while that keeps the rate. Where even the
// fastest point's held frames would not, they trace its own depth if the depth is what costs
// (3x the point's frames), not if it costs under a tenth (the rate would barely move); the point
// stays. A box as fast as measured brings both back: a point that fits, refinement's depth.
TEST_F(Dial, HeldFramesThatWouldNotKeepTheRateTraceThePointsDepth) {
    Demo d = demo(0.01);
    ASSERT_TRUE(d.config.render.previewAccumulate && d.config.render.previewHoldDepth);
    const uint32_t refineDepth = d.config.render.maxDepth;
    ASSERT_NO_FATAL_FAILURE(startAtRest(d));
    PipelineRenderer& r = *renderer_;
    const auto& m = r.dialMeasurements();
    ASSERT_LT(m[quickest_].point.maxDepth, refineDepth) << "a hold traces deeper";
    TrackedFrame held;
    held.frame = greyFrame(r.width(), r.height());
    held.worldFromCamera = cv::Matx44d(1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, -2, 0, 0, 0, 1);
    held.lost = false;
    // The view's second frame holds.
    auto heldFrameDepth = [&] {
        EXPECT_TRUE(r.renderPreview(held, nullptr));
        EXPECT_TRUE(r.renderPreview(held, nullptr));
        return testing::innerRenderer(r).maxDepth();
    };
    EXPECT_EQ(heldFrameDepth(), refineDepth);
    EXPECT_TRUE(r.lastPreviewOffDial());
    // 10^6 times slower than measured: nothing fits at 0.01 fps; the fastest point.
    std::optional<std::string> changed = r.adaptDial(m[best_].frameSeconds * 1e6, 1.05);
    ASSERT_TRUE(changed);
    EXPECT_EQ(changed->find("held camera"), std::string::npos) << *changed;
    EXPECT_EQ(heldFrameDepth(), refineDepth) << "a depth that costs 5 % stays";
    changed = r.adaptDial(m[quickest_].frameSeconds * 1e6, 3.0);
    ASSERT_TRUE(changed);
    EXPECT_NE(changed->find("a held camera at depth"), std::string::npos) << *changed;
    EXPECT_FALSE(r.dialChoice()) << "the fastest still";
    EXPECT_EQ(heldFrameDepth(), m[quickest_].point.maxDepth);
    EXPECT_FALSE(r.lastPreviewOffDial()) << "the point's own frames";
    EXPECT_FALSE(r.adaptDial(m[quickest_].frameSeconds * 1e6, 3.0)) << "no change the second time";
    changed = r.adaptDial(m[quickest_].frameSeconds, 3.0);
    ASSERT_TRUE(changed);
    EXPECT_NE(changed->find("refinement's depth"), std::string::npos) << *changed;
    ASSERT_TRUE(r.dialChoice()) << "a point that fits";
    EXPECT_NE(*r.dialChoice(), best_) << "not the one seen 10^6x too slow 3 windows ago";
    EXPECT_EQ(heldFrameDepth(), refineDepth);
    EXPECT_TRUE(r.lastPreviewOffDial());
}

// [render] denoise = "auto": the dial sweeps the denoiser's strength too, preview frames are
// denoised at the strength it chose, and refinement denoises while the meter's estimate is above
// target_noise and stops once it is below.
TEST_F(Dial, DenoiserStrengthIsOnTheDialAndRefinementStopsDenoisingAtTheTarget) {
    Demo d = demo(0.01);
    d.config.render.denoise = "auto";
    d.config.refine.targetNoise = 0.02;
    d.config.tracking.sceneCameraUntilTracked = true;  // render without a board in view
    auto p = PipelineRenderer::create(*ctx_, d.scene, d.config);
    ASSERT_TRUE(p) << p.message();
    const auto& m = (*p)->dialMeasurements();
    ASSERT_EQ(m.size(), 5u * 3u * 2u * 3u);  // × strength 0, 2, 4
    size_t denoised = 0;
    for (const DialMeasurement& x : m) denoised += x.point.denoiseIterations > 0;
    EXPECT_EQ(denoised, 5u * 3u * 2u * 2u);
    ASSERT_TRUE((*p)->dialChoice());
    const DialPoint& chosen = m[*(*p)->dialChoice()].point;
    EXPECT_EQ((*p)->previewDenoiseLevels(), chosen.denoiseIterations);

    TrackedFrame tracked;
    tracked.frame = greyFrame((*p)->width(), (*p)->height());
    ASSERT_TRUE((*p)->renderPreview(tracked, nullptr));
    Result<ImageF> preview = (*p)->composite();
    ASSERT_TRUE(preview) << preview.message();
    EXPECT_EQ((*p)->lastDenoiseLevels(), chosen.denoiseIterations);

    ASSERT_TRUE((*p)->beginRefine(tracked, nullptr));
    ASSERT_TRUE((*p)->refineStep(8));
    ASSERT_TRUE((*p)->composite(0.1));  // above the target: denoised at denoise_levels
    EXPECT_EQ((*p)->lastDenoiseLevels(), d.config.render.denoiseLevels);
    Result<ImageF> converged = (*p)->composite(0.01);  // below: the accumulation as it is
    ASSERT_TRUE(converged) << converged.message();
    EXPECT_EQ((*p)->lastDenoiseLevels(), 0u);
    for (float v : converged->pixels) ASSERT_TRUE(std::isfinite(v));

    // "on" without the dial: every preview frame at denoise_levels, and it changes the picture.
    Demo on = demo(0.0);
    on.config.render.denoise = "on";
    on.config.render.denoiseLevels = 3;
    on.config.render.width = 160;  // the virtual object a few pixels across at 64x36
    on.config.render.height = 90;
    on.config.tracking.sceneCameraUntilTracked = true;
    // The demo scene is lit by the fisheye's estimate: without one, a sky of its own.
    on.scene.environment = ::previs::testing::uniformEnvironment(glm::vec3(0.5f));
    auto q = PipelineRenderer::create(*ctx_, on.scene, on.config);
    ASSERT_TRUE(q) << q.message();
    EXPECT_EQ((*q)->previewDenoiseLevels(), 3u);
    tracked.frame = greyFrame(160, 90);
    ASSERT_TRUE((*q)->renderPreview(tracked, nullptr));
    Result<ImageF> filtered = (*q)->composite();
    ASSERT_TRUE(filtered) << filtered.message();
    EXPECT_EQ((*q)->lastDenoiseLevels(), 3u);
    Result<ImageF> raw = (*q)->image(Aov::Composite);
    ASSERT_TRUE(raw) << raw.message();
    EXPECT_NE(filtered->pixels, raw->pixels);
    // Preview frames build the temporal history; refinement starts without one.
    ASSERT_TRUE((*q)->renderPreview(tracked, nullptr));
    ASSERT_TRUE((*q)->composite());
    ASSERT_NE(testing::innerRenderer(**q).film().denoiser(), nullptr);
    EXPECT_EQ(testing::innerRenderer(**q).film().denoiser()->historyFrames(), 2u);
    ASSERT_TRUE((*q)->beginRefine(tracked, nullptr));
    EXPECT_EQ(testing::innerRenderer(**q).film().denoiser()->historyFrames(), 0u);
}

// The dial measures each point on a pan through preview's temporal stage (DialMotion): the pan
// ends at the view it started from, and the reprojected history of a slow pan lowers the last
// frame's error well below a still camera's single frame (8 frames of history at 1 pixel a
// frame; the 32-spp reference's own noise is common to both).
TEST_F(Dial, APanCountsWhatReprojectionKeepsAndEndsAtTheReferenceView) {
    Demo d = demo(0.0);
    d.config.render.denoise = "on";
    d.config.render.previewAccumulate = true;
    auto p = PipelineRenderer::create(*ctx_, d.scene, d.config);
    ASSERT_TRUE(p) << p.message();
    Renderer& r = testing::innerRenderer(**p);
    // The demo's set is lit by the fisheye alone: a sky stands in, and a grey plate.
    ASSERT_TRUE(r.setEnvironment(
        std::make_shared<EnvironmentMap>(::previs::testing::uniformEnvironment(glm::vec3(1.0f)))));
    ImageF grey;
    grey.width = (*p)->width();
    grey.height = (*p)->height();
    grey.channels = 3;
    grey.pixels.assign(size_t(grey.width) * grey.height * 3, 0.18f);
    ASSERT_TRUE(r.film().setPlate(std::move(grey)));
    const glm::dmat4 view = r.denoiseCamera().worldFromCamera;
    ASSERT_TRUE(r.reset());
    r.setSeed(99);
    ASSERT_TRUE(r.render(32));
    Result<ImageF> reference = r.image(Aov::Composite);
    ASSERT_TRUE(reference) << reference.message();
    const DialPoint point{1.0f, 1, 4, 0, 0};
    auto still = measureDial(r, std::span(&point, 1), *reference, 1);
    DialMotion pan;
    pan.panStepRad = r.camera().fovYRad / 36.0;  // one pixel
    pan.frames = 9;
    pan.accumulate = true;
    auto panned = measureDial(r, std::span(&point, 1), *reference, 1, std::nullopt, pan);
    ASSERT_TRUE(still && panned);
    EXPECT_GT((*panned)[0].frameSeconds, 0.0);
    EXPECT_LT((*panned)[0].error, 0.8 * (*still)[0].error);
    EXPECT_EQ(r.denoiseCamera().worldFromCamera, view);
    EXPECT_EQ(r.film().denoiser()->historyFrames(), 0u);  // preview starts its own history
}

}  // namespace
}  // namespace previs
