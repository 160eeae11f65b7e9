// Preview as the service renders it (shot/pipeline_renderer.h) on the demo take's still view
// (frames 20–44: one render, new sensor noise per frame), small: before any lighting snapshot the
// virtual objects are lit by the studio stand-in and the renderer says lighting is pending; a
// held camera's accumulated preview converges toward refinement while the paper's fixed sequence
// does not. Bounds come from Monte Carlo's 1/√N (stated at each assertion), not from a run.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "config/service_config.h"
#include "gpu/context.h"
#include "render/renderer.h"
#include "scene/scene_description.h"
#include "shot/pipeline_renderer.h"
#include "shot/pipeline_stages.h"
#include "tests/shot/pipeline_renderer_access.h"
#include "tests/support/demo_frames.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

using testing::demoFrames;

constexpr size_t kStill = 20;  // the first frame of the demo take's still view

struct Demo {
    ServiceConfig config;
    Scene scene;
    std::unique_ptr<GpuContext> gpu;
    TrackedFrame still;                            // frame kStill, tracked
    std::shared_ptr<const LiveLighting> lighting;  // the take's lighting at the still view
    // One clipped exposure's lighting of the same instant: no 2000-radiance lamps, whose rare
    // bright paths dominate an RMSE of a few frames (the accumulation tests' noise model).
    std::shared_ptr<const LiveLighting> clippedLighting;
};

// The shipped demo config at 96×54, no dial (it times this machine), no spatial filter (the
// accumulation is what is measured) and no photons: the chrome ball's caustic is
// tests/integrator/photons_test.cpp's, and at 96×54 a pass of 65536 photons for every sample of
// 5184 pixels made these tests 5–8× slower.
Demo demo() {
    Demo d;
    Result<ServiceConfig> config =
        loadServiceConfig(testing::sourcePath("examples/demo/previsd.toml"));
    EXPECT_TRUE(config) << config.message();
    d.config = *config;
    d.config.render.width = 96;
    d.config.render.height = 54;
    d.config.render.previewFps = 0.0;
    d.config.render.denoise = "off";
    d.config.render.photons.mode = PhotonMode::Off;
    Result<Scene> scene = loadScene(d.config.scenePath);
    EXPECT_TRUE(scene) << scene.message();
    d.scene = std::move(*scene);
    auto gpu = GpuContext::create({});
    EXPECT_TRUE(gpu) << gpu.message();
    d.gpu = std::move(*gpu);
    Result<TrackingStage> tracking = TrackingStage::create(d.config);
    EXPECT_TRUE(tracking) << tracking.message();
    const auto frames = demoFrames("scene", kStill + 1);
    EXPECT_EQ(frames.size(), kStill + 1);
    d.still = tracking->process(frames.back());
    EXPECT_TRUE(d.still.worldFromCamera && !d.still.lost) << d.still.reason;
    Result<LightingStage> lighting = LightingStage::create(d.config);
    EXPECT_TRUE(lighting) << lighting.message();
    // The sixth lighting instant's bracket (the demo brackets 3 frames an instant): its merge.
    const auto fisheye = demoFrames("fisheye", 18);
    EXPECT_EQ(fisheye.size(), 18u);
    for (const auto& f : fisheye) {
        Result<std::shared_ptr<const LiveLighting>> lit = lighting->process(*f);
        EXPECT_TRUE(lit) << lit.message();
        if (lit && *lit) d.lighting = *lit;
    }
    EXPECT_TRUE(d.lighting) << "no bracket merged";
    // The same instant's 0-stop frame lit on its own: the lamps clipped at 16, a soft light.
    ServiceConfig single = d.config;
    single.fisheyeCamera->bracket.reset();
    Result<LightingStage> soft = LightingStage::create(single);
    EXPECT_TRUE(soft) << soft.message();
    Result<std::shared_ptr<const LiveLighting>> clipped = soft->process(*fisheye[15]);
    EXPECT_TRUE(clipped && *clipped);
    d.clippedLighting = *clipped;
    return d;
}

// Mean over the pixels the virtual objects cover (mask above one half) of the composite, and
// their count.
std::pair<double, size_t> virtualMean(const PipelineRenderer& r, const ImageF& composite) {
    Result<ImageF> mask = r.image(Aov::Mask);
    EXPECT_TRUE(mask) << mask.message();
    double sum = 0.0;
    size_t n = 0;
    for (size_t i = 0; i < size_t(mask->width) * mask->height; ++i) {
        if (mask->pixels[i] < 0.5f) continue;
        for (int c = 0; c < 3; ++c) sum += composite.pixels[i * 3 + c] / 3.0;
        ++n;
    }
    return {n ? sum / double(n) : 0.0, n};
}

// sqrt(mean (a − b)²) over every value.
double rmse(const ImageF& a, const ImageF& b) {
    double s = 0.0;
    for (size_t i = 0; i < a.pixels.size(); ++i)
        s += double(a.pixels[i] - b.pixels[i]) * double(a.pixels[i] - b.pixels[i]);
    return std::sqrt(s / double(a.pixels.size()));
}

TEST(Preview, BeforeTheFirstLightingTheVirtualObjectsAreLitAndLightingIsPending) {
    Demo d = demo();
    auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
    ASSERT_TRUE(p) << p.message();
    EXPECT_TRUE((*p)->lightingPending());
    ASSERT_TRUE((*p)->renderPreview(d.still, nullptr));
    Result<ImageF> pending = (*p)->composite();
    ASSERT_TRUE(pending) << pending.message();
    const auto [pendingLevel, pixels] = virtualMean(**p, *pending);
    ASSERT_GT(pixels, 20u) << "the balls are in view";
    EXPECT_TRUE((*p)->lightingPending());

    // The take's own lighting: pending ends; the stand-in was at the set's level, within the
    // factor a studio key light makes against a real room (4x either way), and never black.
    Result<ImageF> lit = makeError("no frame");
    for (int i = 0; i < 4; ++i) {
        ASSERT_TRUE((*p)->renderPreview(d.still, d.lighting));
        lit = (*p)->composite();
    }
    EXPECT_FALSE((*p)->lightingPending());
    ASSERT_TRUE(lit) << lit.message();
    const double litLevel = virtualMean(**p, *lit).first;
    ASSERT_GT(litLevel, 0.0);
    EXPECT_GT(pendingLevel, litLevel / 4.0);
    EXPECT_LT(pendingLevel, litLevel * 4.0);
}

// The box's saved lighting (the service keeps the last snapshot's map, daemon/service.cpp)
// stands in until the first snapshot, exactly: a restored map renders what the live one did,
// bit for bit (float32 OpenEXR), while the renderer still says lighting is pending.
TEST(Preview, TheSavedLightingStandsInUntilTheFirstSnapshot) {
    Demo d = demo();
    const std::string saved = ::testing::TempDir() + "/previs_saved_lighting.exr";
    ASSERT_TRUE(saveLighting(*d.lighting, saved));
    Result<LightingStage> stage = LightingStage::create(d.config);
    ASSERT_TRUE(stage) << stage.message();
    Result<std::shared_ptr<const LiveLighting>> restored = stage->restore(saved);
    ASSERT_TRUE(restored) << restored.message();
    EXPECT_TRUE((*restored)->restored);
    EXPECT_EQ((*restored)->environment->radiance, d.lighting->environment->radiance);

    auto composite = [&](const std::shared_ptr<const LiveLighting>& lighting, bool& pending) {
        auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
        EXPECT_TRUE(p) << p.message();
        EXPECT_TRUE((*p)->renderPreview(d.still, lighting));
        Result<ImageF> image = (*p)->composite();
        EXPECT_TRUE(image) << image.message();
        pending = (*p)->lightingPending();
        return *image;
    };
    bool pendingRestored = false, pendingLive = true;
    const ImageF standIn = composite(*restored, pendingRestored);
    const ImageF live = composite(d.lighting, pendingLive);
    EXPECT_TRUE(pendingRestored);
    EXPECT_FALSE(pendingLive);
    EXPECT_EQ(standIn.pixels, live.pixels);

    // A file that is not a map: the service logs it and keeps the studio stand-in.
    std::FILE* f = std::fopen(saved.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs("not an EXR", f);
    std::fclose(f);
    EXPECT_FALSE(stage->restore(saved));
    std::remove(saved.c_str());
}

// The preview after `frames` frames of the held still view, and a refinement of it.
ImageF previewAfter(Demo& d, bool accumulate, int frames) {
    d.config.render.previewAccumulate = accumulate;
    auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
    EXPECT_TRUE(p) << p.message();
    // As the service does: one composite per frame (it advances the accumulation).
    Result<ImageF> image = makeError("no frame");
    for (int i = 0; i < frames; ++i) {
        EXPECT_TRUE((*p)->renderPreview(d.still, d.lighting));
        image = (*p)->composite();
        EXPECT_TRUE(image) << image.message();
    }
    return *image;
}

// The still view refined to `samples` per pixel at full resolution, as the service refines.
Result<ImageF> refined(Demo& d, uint32_t samples) {
    auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
    if (!p) return p.error();
    if (Status s = (*p)->beginRefine(d.still, d.lighting); !s) return s.error();
    if (Status s = (*p)->refineStep(samples); !s) return s.error();
    return (*p)->composite();
}

TEST(Preview, AHeldCameraConvergesTowardRefinementTheFixedSequenceDoesNot) {
    Demo d = demo();
    d.lighting = d.clippedLighting;
    // The accumulation's own convergence, of unbiased samples: the preview's clamp (on by
    // default) converges to the clamped image (as AtHalfResolutionAHeldCameraGoesBelowThe-
    // UpsamplingFloor says).
    d.config.render.previewSampleClamp = 0.0;
    Result<ImageF> reference = refined(d, 1024);
    ASSERT_TRUE(reference) << reference.message();

    // Independent frames averaged: the error falls as 1/√N (1/4 after 16 frames; the reference's
    // own noise, 1/32 of a frame's, adds under 1 %). Asserted at 1/2: room for the
    // reprojection's resampling and for the history's first frame.
    const double one = rmse(previewAfter(d, true, 1), *reference);
    const double sixteen = rmse(previewAfter(d, true, 16), *reference);
    std::printf("accumulated preview RMSE: 1 frame %.4f, 16 frames %.4f (%.2fx)\n", one, sixteen,
                one / sixteen);
    EXPECT_LT(sixteen, one / 2.0);
    // The paper's fixed sequence renders the same samples every frame: no better after 16.
    const double fixedOne = rmse(previewAfter(d, false, 1), *reference);
    const double fixedSixteen = rmse(previewAfter(d, false, 16), *reference);
    EXPECT_NEAR(fixedSixteen, fixedOne, 0.01 * fixedOne);
}

// A held camera's accumulation is the plain mean of its frames, each rendered on its own with its
// frame's seed, at every pixel, the virtual objects' outlines included: there the frames' few
// samples hit the object or the set behind it, and the history (its mask's and its signal's
// means) must not restart on that change nor pair this frame's mask with the history's signal.
// Before, the outlines' history restarted every 3.8 frames of 16 on average and the two differed
// by about the frames' own error. Equal up to float rounding of a running mean (16 frames stay
// within the history's length, where the weight is 1/(n+1)): asserted at 1 % of the frames' own
// error, far above rounding and far below a restarted history.
TEST(Preview, AHeldCamerasAccumulationIsThePlainMeanOfItsFramesOutlinesIncluded) {
    Demo d = demo();
    d.lighting = d.clippedLighting;
    constexpr int kFrames = 16;
    const ImageF accumulated = previewAfter(d, true, kFrames);
    std::vector<ImageF> frames;
    for (int k = 1; k <= kFrames; ++k) {
        d.config.render.seed = Renderer::previewFrameSeed(0, k);
        frames.push_back(previewAfter(d, false, 1));
    }
    ImageF mean = frames[0];
    for (size_t i = 0; i < mean.pixels.size(); ++i) {
        double sum = 0.0;
        for (const ImageF& f : frames) sum += f.pixels[i];
        mean.pixels[i] = float(sum / kFrames);
    }
    const double frameError = rmse(frames[0], mean);
    const double difference = rmse(accumulated, mean);
    std::printf("accumulated vs the plain mean of %d frames: RMSE %.5f (a frame's own %.4f)\n",
                kFrames, difference, frameError);
    EXPECT_LT(difference, 0.01 * frameError);
}

// At half resolution the held view (render/held_view.h) keeps each frame's samples per output
// pixel: a held camera's preview goes below what any number of half-resolution samples
// upsampled can reach (the floor: a converged half-resolution trace, upsampled), toward the
// full-resolution refinement.
TEST(Preview, AtHalfResolutionAHeldCameraGoesBelowTheUpsamplingFloor) {
    Demo d = demo();
    d.lighting = d.clippedLighting;
    Result<ImageF> reference = refined(d, 1024);
    ASSERT_TRUE(reference) << reference.message();

    d.config.render.resolutionScale = 0.5f;
    d.config.render.previewAccumulate = true;
    // The held view's own convergence, of unbiased samples: the preview's clamp (on by default)
    // trades it for a clean first frame, and the held view then converges to the clamped image
    // (BENCHMARKS.md, "The preview as shipped", measures both).
    d.config.render.previewSampleClamp = 0.0;
    auto half = PipelineRenderer::create(*d.gpu, d.scene, d.config);
    ASSERT_TRUE(half) << half.message();
    ASSERT_TRUE((*half)->renderPreview(d.still, d.lighting));
    Renderer& r = testing::innerRenderer(**half);
    ASSERT_EQ(r.traceWidth() * 2, (*half)->width());
    ASSERT_TRUE(r.holdView(false));
    ASSERT_TRUE(r.reset());
    ASSERT_TRUE(r.render(256));
    Result<ImageF> converged = r.image(Aov::Composite);
    ASSERT_TRUE(converged) << converged.message();
    const double floor = rmse(*converged, *reference);

    std::vector<double> errors;
    for (int frames : {1, 4, 16, 32}) {
        errors.push_back(rmse(previewAfter(d, true, frames), *reference));
        std::printf("held half-resolution preview after %d frames: RMSE %.4f (floor %.4f)\n",
                    frames, errors.back(), floor);
    }
    // 32 frames keep 8 samples of each output pixel (1 a frame, one pixel of each 2 x 2 block).
    EXPECT_LT(errors.back(), floor);
    EXPECT_LT(errors.back(), errors.front() / 2.0);
}

// While the camera moves ([render] preview_follow), the held view's samples follow it at the
// output's resolution, fading to 3/4 a frame (render/held_reprojection.h): after four moving
// frames about 1 + 3/4 + (3/4)² + (3/4)³ = 2.7 frames' samples are kept (less those the move took
// out of the image, and at a third of the resolution those of an output pixel another traced
// pixel owns), and none count as held. Off, a moving camera keeps none.
TEST(Preview, AMovingCamerasSamplesFollowItAtTheOutputsResolution) {
    Demo d = demo();
    d.config.render.resolutionScale = 1.0f / 3.0f;
    d.config.render.previewObjectSamples = 0.0;  // a frame's samples: one per traced pixel
    for (bool follow : {true, false}) {
        d.config.render.previewFollow = follow;
        auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
        ASSERT_TRUE(p) << p.message();
        TrackedFrame frame = d.still;
        ASSERT_TRUE(frame.worldFromCamera);
        for (int i = 0; i < 4; ++i) {
            (*frame.worldFromCamera)(0, 3) += 0.02;  // 2 cm a frame: a pan
            ASSERT_TRUE((*p)->renderPreview(frame, d.lighting));
        }
        EXPECT_EQ((*p)->heldViewFrames(), 0u);
        const Renderer& r = testing::innerRenderer(**p);
        Result<std::vector<glm::vec4>> held = r.heldSamples();
        ASSERT_TRUE(held) << held.message();
        if (!follow) {
            EXPECT_TRUE(held->empty());
            continue;
        }
        double kept = 0.0;
        for (size_t i = 0; i < held->size() / 2; ++i) kept += (*held)[2 * i + 1].x;
        const double frameSamples =
            double(r.traceWidth()) * r.traceHeight() * d.config.liveRender.samplesPerFrame;
        EXPECT_GT(kept, 2.0 * frameSamples);
        EXPECT_LT(kept, 2.74 * frameSamples);
    }
}

// While the camera holds, preview frames trace refinement's depth ([render] preview_hold_depth),
// so a held preview converges toward refinement's picture, not preview's shallower one; the
// first frame of a view traces preview's depth, and with the setting off every frame does.
TEST(Preview, AHeldCameraTracesRefinementsDepth) {
    Demo d = demo();
    ASSERT_EQ(d.config.render.maxDepth, 4u);
    d.config.render.resolutionScale = 1.0f / 3.0f;
    d.config.render.previewMaxDepth = 2;
    for (bool holdDepth : {true, false}) {
        d.config.render.previewHoldDepth = holdDepth;
        auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
        ASSERT_TRUE(p) << p.message();
        const Renderer& r = testing::innerRenderer(**p);
        ASSERT_TRUE((*p)->renderPreview(d.still, d.lighting));
        EXPECT_EQ(r.maxDepth(), 2u) << "a view's first frame";
        ASSERT_TRUE((*p)->renderPreview(d.still, d.lighting));
        EXPECT_EQ((*p)->heldViewFrames(), 1u) << "the camera holds";
        EXPECT_EQ(r.maxDepth(), holdDepth ? 4u : 2u);
    }
}

// Below full resolution the traced pixels under the virtual objects get samples added every
// frame ([render] preview_object_samples): each pixel the objects cover has more than the
// frame's own, pixels away from them have exactly those, and the extra samples stay within
// half of the frame's (Renderer::kObjectSampleBudget). Off (0), every pixel has the frame's.
// (The counts as image() gives them: upsampled to the output, which keeps a constant and the
// mean.)
TEST(Preview, TheVirtualObjectsGetSamplesAddedWherePreviewTracesAFraction) {
    Demo d = demo();
    d.config.render.resolutionScale = 1.0f / 3.0f;
    auto counts = [&](double objectSamples, ImageF& mask) {
        d.config.render.previewObjectSamples = objectSamples;
        auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
        EXPECT_TRUE(p) << p.message();
        EXPECT_TRUE((*p)->renderPreview(d.still, d.lighting));
        EXPECT_EQ(testing::innerRenderer(**p).traceWidth(), 32u);  // 96 × 54 at a third
        Result<ImageF> m = (*p)->image(Aov::Mask);
        EXPECT_TRUE(m) << m.message();
        mask = *m;
        Result<ImageF> n = (*p)->image(Aov::SampleCount);
        EXPECT_TRUE(n) << n.message();
        return *n;
    };
    const double spp = d.config.liveRender.samplesPerFrame;
    ImageF mask;
    const ImageF added = counts(1.0, mask);
    size_t objectPixels = 0, plain = 0;
    double extra = 0.0;
    for (size_t i = 0; i < added.pixels.size(); ++i) {
        extra += added.pixels[i] - spp;
        if (std::abs(added.pixels[i] - spp) < 1e-3) ++plain;
        if (mask.pixels[i] < 0.5f) continue;
        ++objectPixels;
        EXPECT_GT(added.pixels[i], spp + 0.5) << "pixel " << i << " shows a virtual object";
    }
    EXPECT_GT(objectPixels, 40u) << "the balls are in view";
    EXPECT_GT(plain, added.pixels.size() / 2) << "the region is the objects', not the frame";
    EXPECT_LE(extra, 0.5 * spp * double(added.pixels.size()) * 1.01);
    const ImageF off = counts(0.0, mask);
    for (float n : off.pixels) EXPECT_NEAR(n, spp, 1e-3);
}

// Back from refinement to preview on the same view and lighting, the held view starts from the
// refined samples: the first preview frame shows what refinement reached. Its estimate (counted
// as 16 samples) beside refinement's 256 leaves about 16/272 of a fresh frame's error; asserted
// at a quarter of it.
TEST(Preview, BackFromRefinementTheFirstPreviewFrameShowsWhatRefinementReached) {
    Demo d = demo();
    d.lighting = d.clippedLighting;
    d.config.render.resolutionScale = 1.0f / 3.0f;
    d.config.render.previewAccumulate = true;
    auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
    ASSERT_TRUE(p) << p.message();
    ASSERT_TRUE((*p)->renderPreview(d.still, d.lighting));
    Result<ImageF> fresh = (*p)->composite();
    ASSERT_TRUE(fresh) << fresh.message();
    ASSERT_TRUE((*p)->beginRefine(d.still, d.lighting));
    ASSERT_TRUE((*p)->refineStep(256));
    Result<ImageF> reached = (*p)->composite();
    ASSERT_TRUE(reached) << reached.message();
    ASSERT_TRUE((*p)->renderPreview(d.still, d.lighting));
    Result<ImageF> resumed = (*p)->composite();
    ASSERT_TRUE(resumed) << resumed.message();
    const double freshError = rmse(*fresh, *reached), resumedError = rmse(*resumed, *reached);
    std::printf("preview against refinement's 256 spp: fresh %.4f, resumed %.4f\n", freshError,
                resumedError);
    EXPECT_LT(resumedError, freshError / 4.0);
}

// Preview's estimate scales a sample brighter than [render] preview_sample_clamp down to it: under
// the take's bracketed lighting (lamps of radiance ~1900 seen in the chrome ball and through
// the room) no traced pixel of the mixed solution is brighter than the clamp, while refinement
// of the same view, never clamped, is. (Rec. 709 luminance, as the shader's; the upsampling is a
// convex combination, so it cannot exceed its inputs' largest.)
TEST(Preview, TheEstimateClampsTheRareBrightSampleRefinementDoesNot) {
    Demo d = demo();
    d.config.render.previewSampleClamp = 4.0;
    auto brightest = [](const ImageF& mixed) {
        double most = 0.0;
        for (size_t i = 0; i < size_t(mixed.width) * mixed.height; ++i)
            most = std::max(most, 0.2126 * mixed.pixels[i * 3] + 0.7152 * mixed.pixels[i * 3 + 1] +
                                      0.0722 * mixed.pixels[i * 3 + 2]);
        return most;
    };
    auto p = PipelineRenderer::create(*d.gpu, d.scene, d.config);
    ASSERT_TRUE(p) << p.message();
    double preview = 0.0;
    for (int frame = 0; frame < 4; ++frame) {
        ASSERT_TRUE((*p)->renderPreview(d.still, d.lighting));
        Result<ImageF> mixed = (*p)->image(Aov::Mixed);
        ASSERT_TRUE(mixed) << mixed.message();
        preview = std::max(preview, brightest(*mixed));
    }
    ASSERT_TRUE((*p)->beginRefine(d.still, d.lighting));
    ASSERT_TRUE((*p)->refineStep(16));
    Result<ImageF> refined = (*p)->image(Aov::Mixed);
    ASSERT_TRUE(refined) << refined.message();
    std::printf("brightest mixed pixel: preview %.2f, refinement %.2f\n", preview,
                brightest(*refined));
    EXPECT_LE(preview, 4.0 * (1.0 + 1e-5));
    EXPECT_GT(brightest(*refined), 4.0);
}

}  // namespace
}  // namespace previs
