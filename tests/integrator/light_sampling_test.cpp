// Emissive triangles sampled by solid angle (LightSampling::SolidAngle, shared/triangle_light.h)
// against area sampling, on a floor lit by two small emitters close to it: the same expected image
// (unbiased, MIS with BSDF sampling included), and a lower error of direct light at equal
// samples. Tolerances come from the spread across seeds that each test measures; seeds are fixed.
#include <gtest/gtest.h>

#include <cmath>

#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

class LightSamplingTest : public GpuTest {};

// A floor under two 0.2 m emitters 8 and 12 cm above it — one facing down, one tilted toward
// the floor at 60° — and a diffuse sphere between them, seen from above: the floor around the
// emitters sees them under large solid angles where the area pdf is far from the solid-angle
// one (1/r² and the emitter's cosine vary across it).
Scene smallCloseEmitters() {
    Scene s;
    addQuad(s, {0, 0, 0}, {1, 0, 0}, {0, 0, -1}, addMaterial(s, lambert(glm::vec3(0.7f))));
    addSphere(s, {0.05f, 0.1f, 0.1f}, 0.1f, addMaterial(s, lambert(glm::vec3(0.8f, 0.4f, 0.2f))),
              false, 12, 24);
    addQuad(s, {-0.25f, 0.08f, -0.1f}, {0.1f, 0, 0}, {0, 0, 0.1f},
            addMaterial(s, emitter(glm::vec3(8.0f))));
    const float c = std::cos(glm::radians(60.0f)), sn = std::sin(glm::radians(60.0f));
    addQuad(s, {0.3f, 0.12f, 0.15f}, {0.1f * c, -0.1f * sn, 0}, {0, 0, 0.1f},
            addMaterial(s, emitter(glm::vec3(4.0f, 6.0f, 12.0f))));
    s.environment = uniformEnvironment(glm::vec3(0.02f));
    s.cameras.push_back(lookAt({0, 1.2f, 0.6f}, {0, 0, 0}, {0, 1, 0}, glm::radians(45.0f)));
    return s;
}

RenderSettings settingsFor(LightSampling lightSampling, uint32_t maxDepth) {
    RenderSettings rs = renderSettings(16, 16, maxDepth);
    rs.samplesPerDispatch = 64;
    rs.lightSampling = lightSampling;
    return rs;
}

// Unbiased: over 16 seeds each, the solid-angle mean image equals the area-sampling one within
// the noise, with three bounces (so BSDF-sampled hits of the emitters are weighed by MIS with
// the solid-angle pdf). Bounds as in sampler_render_test.cpp: per pixel and channel (768 tests)
// |Δ|/σ, σ² the sum of both variances of the mean with 15 degrees of freedom each, below 6.6
// (Student's t with 15, Šidák-corrected 1% two-sided over 1024 tests, conservative for 768);
// per channel over the image, |Δ|/σ below 2.94 = Φ⁻¹(1 − 0.01/(2·3)).
TEST_F(LightSamplingTest, SolidAngleSamplingIsUnbiased) {
    const Scene s = smallCloseEmitters();
    const uint32_t spp = 16;
    const int runs = 16;
    MeanAndVariance solid =
        perPixel(renders(s, settingsFor(LightSampling::SolidAngle, 3), spp, runs, 3000));
    MeanAndVariance area =
        perPixel(renders(s, settingsFor(LightSampling::Area, 3), spp, runs, 4000));
    const MeanDifference diff = compareMeans(solid, area);
    EXPECT_LT(diff.worstPixelT, 6.6);
    RecordProperty("worstPixelT", std::to_string(diff.worstPixelT));
    for (int c = 0; c < 3; ++c) {
        EXPECT_LT(diff.channelZ[c], 2.94) << "channel " << c;
        RecordProperty("imageMeanZ" + std::to_string(c), std::to_string(diff.channelZ[c]));
    }
}

// Lower error per sample for direct light (max depth 1) near the small close emitters: at 16 and
// 64 spp the mean squared error against a long reference over 16 seeds is lower with solid-angle
// sampling by more than the noise of that comparison — the difference of the two mean MSEs must
// exceed 2.6 standard errors (Welch; 2.602 is Student's t one-sided 1% at 15 degrees of freedom,
// the fewest Welch's approximation can give). The reference's own error adds the same expected
// amount to both MSEs, so it cannot favour either strategy.
TEST_F(LightSamplingTest, SolidAngleSamplingHasLowerDirectLightError) {
    const Scene s = smallCloseEmitters();
    const ImageF reference = renders(s, settingsFor(LightSampling::SolidAngle, 1), 4096, 1, 99)[0];
    const int runs = 16;
    auto mses = [&](LightSampling ls, uint32_t spp, uint32_t firstSeed) {
        return meanSquaredErrors(renders(s, settingsFor(ls, 1), spp, runs, firstSeed), reference);
    };
    for (uint32_t spp : {16u, 64u}) {
        auto [solid, solidVar] = meanAndVarianceOfMean(mses(LightSampling::SolidAngle, spp, 5000));
        auto [area, areaVar] = meanAndVarianceOfMean(mses(LightSampling::Area, spp, 6000));
        const double t = (area - solid) / std::sqrt(solidVar + areaVar);
        EXPECT_GT(t, 2.602) << spp << " spp: MSE solid angle " << solid << ", area " << area;
        RecordProperty("rmseRatio" + std::to_string(spp), std::to_string(std::sqrt(solid / area)));
        RecordProperty("t" + std::to_string(spp), std::to_string(t));
    }
}

}  // namespace
}  // namespace previs::testing
