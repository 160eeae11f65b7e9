// The Sobol' sampler in the path tracer against the independent (PCG) one, on a scene lit by two
// small area lights: the same expected image (unbiased), and a lower error at equal samples.
// Tolerances come from the spread across seeds that each test measures; seeds are fixed.
#include <gtest/gtest.h>

#include <cmath>
#include <numeric>

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
    RenderSettings rs;
    rs.width = rs.height = 16;
    rs.maxDepth = 4;
    rs.samplesPerDispatch = 64;
    rs.sampler = sampler;
    return rs;
}


// Unbiased: over 16 seeds each, the Sobol' mean image equals the independent one within the noise.
// Per pixel and channel (16×16×3 = 768 tests) |Δ|/σ with σ² the sum of both variances of the
// mean: each variance has 15 degrees of freedom, so the statistic is at least as concentrated as
// Student's t with 15, whose Šidák-corrected 1% two-sided bound over 1024 tests is 6.6 (as in
// test_integrator.cpp; conservative for 768). And per channel over the whole image, where a
// small bias would add up: pixels are independent, so the image mean's variance is the sum of
// the pixels' over n²; with 2×16×256 runs-pixels behind it the normal bound applies, 2.94 =
// Φ⁻¹(1 − 0.01/(2·3)) after Šidák over the 3 channels.
TEST_F(SamplerRenderTest, SobolIsUnbiased) {
    const Scene s = smallAreaLights();
    const uint32_t spp = 16;
    const int runs = 16;
    MeanAndVariance sobol = perPixel(renders(s, settingsFor(Sampler::Sobol), spp, runs, 2000));
    MeanAndVariance pcg = perPixel(renders(s, settingsFor(Sampler::Independent), spp, runs, 2000));
    ASSERT_EQ(sobol.mean.size(), pcg.mean.size());
    double worstPixel = 0.0;
    double channelDiff[3] = {}, channelVar[3] = {};
    const size_t n = sobol.mean.size();
    for (size_t i = 0; i < n; ++i) {
        const double d = sobol.mean[i] - pcg.mean[i];
        const double v = sobol.varianceOfMean[i] + pcg.varianceOfMean[i];
        if (v > 0.0) worstPixel = std::max(worstPixel, std::abs(d) / std::sqrt(v));
        else EXPECT_NEAR(d, 0.0, 1e-6) << "noise-free value " << i;
        channelDiff[i % 3] += d;
        channelVar[i % 3] += v;
    }
    EXPECT_LT(worstPixel, 6.6);
    RecordProperty("worstPixelT", std::to_string(worstPixel));
    for (int c = 0; c < 3; ++c) {
        const double z = std::abs(channelDiff[c]) / std::sqrt(channelVar[c]);
        EXPECT_LT(z, 2.94) << "channel " << c;
        RecordProperty("imageMeanZ" + std::to_string(c), std::to_string(z));
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
        std::vector<double> out;
        for (const ImageF& img : renders(s, settingsFor(sampler), spp, runs, 2000)) {
            double mse = 0.0;
            for (size_t i = 0; i < img.pixels.size(); ++i) {
                const double d = img.pixels[i] - reference.pixels[i];
                mse += d * d;
            }
            out.push_back(mse / double(img.pixels.size()));
        }
        return out;
    };
    auto meanVar = [](const std::vector<double>& v) {
        const double m = std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
        double ss = 0.0;
        for (double x : v) ss += (x - m) * (x - m);
        return std::pair(m, ss / double(v.size() - 1) / double(v.size()));  // mean, var of mean
    };
    for (uint32_t spp : {16u, 64u}) {
        auto [sobol, sobolVar] = meanVar(mses(Sampler::Sobol, spp));
        auto [pcg, pcgVar] = meanVar(mses(Sampler::Independent, spp));
        const double t = (pcg - sobol) / std::sqrt(sobolVar + pcgVar);
        EXPECT_GT(t, 2.602) << spp << " spp: MSE Sobol' " << sobol << ", PCG " << pcg;
        RecordProperty("rmseRatio" + std::to_string(spp), std::to_string(std::sqrt(sobol / pcg)));
        RecordProperty("t" + std::to_string(spp), std::to_string(t));
    }
}

}  // namespace
}  // namespace previs::testing
