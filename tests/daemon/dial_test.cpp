// The dial in the service ([render] preview_fps, daemon/pipeline_renderer.h) on the demo's
// scene at a small size: what it measured, that its choice is on the front of its own
// measurements and is what preview then renders with, and that refinement keeps max_depth and
// every pixel. No timing is asserted (a loaded CI machine decides which point fits); the two
// extremes of the target make the choice deterministic in kind.
#include <gtest/gtest.h>

#include "daemon/pipeline_renderer.h"
#include "daemon/service_config.h"
#include "gpu/context.h"
#include "scene/scene_description.h"
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
    Result<Scene> scene = loadScene(d.config.scenePath);
    EXPECT_TRUE(scene) << scene.message();
    d.scene = std::move(*scene);
    return d;
}

// Every frame rate is reachable at 1 fps here: the most accurate of all 36 settings.
TEST(Dial, ASlowTargetTakesTheMostAccurateSetting) {
    auto ctx = GpuContext::create({});
    ASSERT_TRUE(ctx) << ctx.message();
    Demo d = demo(0.01);
    auto p = PipelineRenderer::create(**ctx, d.scene, d.config);
    ASSERT_TRUE(p) << p.message();
    const auto& m = (*p)->dialMeasurements();
    ASSERT_EQ(m.size(), 4u * 3u * 2u);  // depths 2 and 4 only: max_depth is 6
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
    EXPECT_EQ((*p)->renderer().maxDepth(), 6u);
    EXPECT_EQ((*p)->renderer().resolutionScale(), 1.0f);
}

// An unreachable rate: no choice, and preview falls back to the fastest setting measured.
TEST(Dial, AnUnreachableTargetTakesTheFastest) {
    auto ctx = GpuContext::create({});
    ASSERT_TRUE(ctx) << ctx.message();
    Demo d = demo(240.0);
    d.config.render.width = 320;
    d.config.render.height = 180;
    auto p = PipelineRenderer::create(**ctx, d.scene, d.config);
    ASSERT_TRUE(p) << p.message();
    const auto& m = (*p)->dialMeasurements();
    ASSERT_FALSE(m.empty());
    if ((*p)->dialChoice()) GTEST_SKIP() << "this device renders 320x180 at 240 fps";
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

}  // namespace
}  // namespace previs
