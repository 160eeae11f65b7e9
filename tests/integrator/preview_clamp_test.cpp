// Preview's clamp ([render] preview_sample_clamp). The held view's samples, kept in the output
// pixel each landed in, have their indirect light scaled alone (trace_paths.comp,
// gIndirectMixed): the light the camera sees directly and a first surface's direct light come
// through whole, so a floor under a bright sky keeps its level; a floor that only a bounce lights
// stays within the clamp in every pixel. The frame's estimate, which the upsampling spreads, is
// clamped whole. Refinement is never clamped.
#include <gtest/gtest.h>

#include <algorithm>
#include <span>

#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

constexpr uint32_t kSize = 24;
constexpr float kClamp = 4.0f;

class PreviewClampTest : public GpuTest {
protected:
    struct Frames {
        ImageF estimate;          // a preview frame's (traced at half the output's size)
        std::vector<float> held;  // the held view's samples' means per output pixel (red)
        ImageF refined;           // refinement's
    };
    // The mixed solution as a preview frame shows it (clamped) and as refinement does (not).
    Frames previewAndRefinement(const Scene& scene, uint32_t spp) {
        RenderSettings rs = renderSettings(kSize, kSize, 3);
        rs.previewSampleClamp = kClamp;
        rs.resolutionScale = 0.5f;
        auto r = Renderer::create(ctx(), scene, rs);
        EXPECT_TRUE(r.ok()) << r.message();
        if (!r) return {};
        Renderer& renderer = **r;
        Frames f;
        EXPECT_TRUE(renderer.holdView(true).ok());
        EXPECT_TRUE(renderer.renderPreviewFrame(spp, 1).ok());
        Result<ImageF> estimate = renderer.image(Aov::Mixed);
        Result<std::vector<glm::vec4>> held = renderer.heldSamples();
        EXPECT_TRUE(renderer.holdView(false).ok());
        EXPECT_TRUE(renderer.setResolutionScale(1.0f).ok());
        EXPECT_TRUE(renderer.render(spp).ok());
        Result<ImageF> refined = renderer.image(Aov::Mixed);
        EXPECT_TRUE(estimate.ok() && held.ok() && refined.ok());
        if (!estimate || !held || !refined) return {};
        f.estimate = *estimate;
        f.refined = *refined;
        for (size_t i = 0; i < held->size() / 2; ++i)
            if ((*held)[2 * i + 1].x > 0.0f)
                f.held.push_back((*held)[2 * i].x / (*held)[2 * i + 1].x);
        EXPECT_GT(f.held.size(), size_t(kSize) * kSize / 2);
        return f;
    }
};

double meanOf(std::span<const float> values) {
    double sum = 0.0;
    for (float v : values) sum += v;
    return sum / double(std::max<size_t>(values.size(), 1));
}

float brightest(std::span<const float> values) {
    return values.empty() ? 0.0f : *std::max_element(values.begin(), values.end());
}

// Under a uniform sky of 20 the floor's radiance is 0.5 × 20 = 10, over the clamp: its light
// sampled at the first hit is direct, and the held view keeps it whole.
TEST_F(PreviewClampTest, DirectLightBrighterThanTheClampComesThroughWhole) {
    Scene scene = realFloorSeenFromAbove();
    scene.environment = uniformEnvironment(glm::vec3(20.0f));
    const Frames f = previewAndRefinement(scene, 16);
    // A uniform sky through a cosine lobe, sampled by the environment and the BSDF: each
    // sample is within a few per cent of 10.
    EXPECT_NEAR(meanOf(f.held), 10.0, 0.2);
    EXPECT_NEAR(meanOf(f.refined.pixels), 10.0, 0.2);
    EXPECT_LE(brightest(f.estimate.pixels), kClamp * (1.0f + 1e-5f));
}

// A horizontal sun of 1000 W/m² lights a white wall beside the floor head on (radiance
// 0.8/π × 1000 ≈ 255) and the floor not at all (it grazes it): the floor's light is the wall's
// bounce, indirect, and every preview pixel stays within the clamp, while refinement's floor is
// several times brighter.
TEST_F(PreviewClampTest, IndirectLightIsBoundedByTheClamp) {
    Scene scene = realFloorSeenFromAbove();
    addQuad(scene, glm::vec3(1.0f, 1.0f, 0.0f), glm::vec3(0.0f, 0.0f, 2.0f),
            glm::vec3(0.0f, 1.0f, 0.0f), addMaterial(scene, lambert(glm::vec3(0.8f))),
            /*real=*/true);
    scene.lights.push_back(realSun(glm::vec3(1.0f, 0.0f, 0.0f), 1000.0f));
    const Frames f = previewAndRefinement(scene, 16);
    EXPECT_LE(brightest(f.held), kClamp * (1.0f + 1e-5f));
    EXPECT_LE(brightest(f.estimate.pixels), kClamp * (1.0f + 1e-5f));
    EXPECT_GT(meanOf(f.refined.pixels), 2.0 * kClamp);
}

}  // namespace
}  // namespace previs::testing
