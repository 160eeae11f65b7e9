// The Sobol' sampler in the path tracer against the independent (PCG) one, on a scene lit by two
// small area lights: the same expected image (unbiased), and a lower error at equal samples.
// Tolerances come from the spread across seeds that each test measures; seeds are fixed.
#include <gtest/gtest.h>

#include <cmath>

#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

class SamplerRenderTest : public GpuTest {};

// Two small emissive quads over a floor, a diffuse sphere and a dim sky: direct light from small
// emitters, soft shadows and a few bounces, where stratifying the light samples pays.
Scene smallAreaLights() {
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 3}, {3, 0, 0}, addMaterial(s, lambert(glm::vec3(0.7f))));
    addSphere(s, {0, 0.4f, 0}, 0.4f, addMaterial(s, lambert(glm::vec3(0.8f, 0.3f, 0.2f))), false,
              16, 32);
    addQuad(s, {-0.6f, 1.4f, 0}, {0.15f, 0, 0}, {0, 0, 0.15f},
            addMaterial(s, emitter(glm::vec3(20.0f))));
    addQuad(s, {0.7f, 1.2f, 0.3f}, {0.1f, 0, 0}, {0, 0, 0.1f},
            addMaterial(s, emitter(glm::vec3(10.0f, 14.0f, 30.0f))));
    s.environment = uniformEnvironment(glm::vec3(0.05f));
    s.cameras.push_back(lookAt({0, 1, 2.5f}, {0, 0.3f, 0}, {0, 1, 0}, glm::radians(45.0f)));
    return s;
}

RenderSettings settingsFor(Sampler sampler) {
    RenderSettings rs = renderSettings(16, 16, 4);
    rs.samplesPerDispatch = 64;
    rs.sampler = sampler;
    // One sequence: the generators' own stratification is what is compared (the convergence
    // meter's two interleaved replicates give some of it up: BENCHMARKS.md, issue 10).
    rs.convergenceMeter = false;
    return rs;
}

// Unbiased: over 16 seeds each, the Sobol' mean image equals the independent one within the noise.
// Per pixel and channel (16×16×3 = 768 tests) |Δ|/σ with σ² the sum of both variances of the
// mean: each variance has 15 degrees of freedom, so the statistic is at least as concentrated as
// Student's t with 15, whose Šidák-corrected 1% two-sided bound over 1024 tests is 6.6 (as in
// integrator_test.cpp; conservative for 768). And per channel over the whole image, where a
// small bias would add up: pixels are independent, so the image mean's variance is the sum of
// the pixels' over n²; with 2×16×256 runs-pixels behind it the normal bound applies, 2.94 =
// Φ⁻¹(1 − 0.01/(2·3)) after Šidák over the 3 channels.
TEST_F(SamplerRenderTest, SobolIsUnbiased) {
    const Scene s = smallAreaLights();
    const uint32_t spp = 16;
    const int runs = 16;
    MeanAndVariance sobol = perPixel(renders(s, settingsFor(Sampler::Sobol), spp, runs, 2000));
    MeanAndVariance pcg = perPixel(renders(s, settingsFor(Sampler::Independent), spp, runs, 2000));
    const MeanDifference diff = compareMeans(sobol, pcg);
    EXPECT_LT(diff.worstPixelT, 6.6);
    RecordProperty("worstPixelT", std::to_string(diff.worstPixelT));
    for (int c = 0; c < 3; ++c) {
        EXPECT_LT(diff.channelZ[c], 2.94) << "channel " << c;
        RecordProperty("imageMeanZ" + std::to_string(c), std::to_string(diff.channelZ[c]));
    }
}

// Lower error per sample: at 16 and 64 spp, the mean squared error against a long reference
// over 16 seeds is lower with Sobol' than with PCG by more than the noise of that comparison —
// the difference of the two means must exceed 2.6 standard errors (Welch, each MSE's variance
// measured over its 16 seeds; 2.602 is Student's t one-sided 1% at 15 degrees of freedom, the
// fewest Welch's approximation can give). The reference's own error adds the same expected
// amount to both MSEs, so it cannot favour either sampler (at 4096 spp it is below 2% of PCG's
// error at 64 spp).
TEST_F(SamplerRenderTest, SobolHasLowerErrorPerSampleWithSmallAreaLights) {
    const Scene s = smallAreaLights();
    const ImageF reference = renders(s, settingsFor(Sampler::Sobol), 4096, 1, 99)[0];
    const int runs = 16;
    auto mses = [&](Sampler sampler, uint32_t spp) {
        return meanSquaredErrors(renders(s, settingsFor(sampler), spp, runs, 2000), reference);
    };
    for (uint32_t spp : {16u, 64u}) {
        auto [sobol, sobolVar] = meanAndVarianceOfMean(mses(Sampler::Sobol, spp));
        auto [pcg, pcgVar] = meanAndVarianceOfMean(mses(Sampler::Independent, spp));
        const double t = (pcg - sobol) / std::sqrt(sobolVar + pcgVar);
        EXPECT_GT(t, 2.602) << spp << " spp: MSE Sobol' " << sobol << ", PCG " << pcg;
        RecordProperty("rmseRatio" + std::to_string(spp), std::to_string(std::sqrt(sobol / pcg)));
        RecordProperty("t" + std::to_string(spp), std::to_string(t));
    }
}

}  // namespace
}  // namespace previs::testing
