// The convergence meter's arithmetic (render/convergence.h) on synthetic accumulations whose
// true error is known: Gaussian samples of a stated variance, and the extremes — no samples,
// zero variance, a 1e5-radiance sun, a million samples per pixel.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "render/convergence.h"

namespace previs {
namespace {

// A pixel of `n` samples drawn N(mean, sigma²) per channel, interleaved into two replicates as
// the path tracer does (odd samples in replicate 1).
MeterPixel gaussianPixel(std::mt19937& rng, glm::dvec3 mean, double sigma, int n) {
    std::normal_distribution<double> noise(0.0, sigma);
    MeterPixel p;
    for (int i = 0; i < n; ++i) {
        glm::dvec3 x = mean + glm::dvec3(noise(rng), noise(rng), noise(rng));
        p.sum += x;
        p.count += 1.0;
        if (i % 2 == 1) {
            p.halfSum += x;
            p.halfCount += 1.0;
        }
    }
    return p;
}

// The expected relMSE of such an image: Σ σ²/n / (μ² + 0.01) over pixels and channels.
// The estimate is a mean of 3P one-degree-of-freedom terms, so its relative standard deviation
// is about √(2/(3P)) (1.3 % at P = 4096); 5 of those bound it (and the μ² ≈ mean² stand-in's bias,
// σ²/(nμ²) ≤ 1 % here).
TEST(ConvergenceMeter, EstimatesTheErrorOfIndependentSamples) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> level(0.05, 2.0);
    for (int n : {2, 3, 16, 255, 1024}) {
        std::vector<MeterPixel> pixels;
        double expected = 0.0;
        const int count = 4096;
        for (int i = 0; i < count; ++i) {
            const glm::dvec3 mean(level(rng), level(rng), level(rng));
            const double sigma = 0.05 * std::sqrt(double(n));  // the mean's error stays 0.05
            pixels.push_back(gaussianPixel(rng, mean, sigma, n));
            for (int c = 0; c < 3; ++c)
                expected += sigma * sigma / n / (mean[c] * mean[c] + kRelMseOffset);
        }
        expected = std::sqrt(expected / (3.0 * count));
        const NoiseEstimate e = estimateNoise(pixels);
        ASSERT_TRUE(e.relativeRmse) << n << " spp";
        EXPECT_EQ(e.pixelsMeasured, uint64_t(count));
        const double tolerance = 5.0 * std::sqrt(2.0 / (3.0 * count)) + 0.01;
        EXPECT_NEAR(*e.relativeRmse / expected, 1.0, tolerance) << n << " spp";
    }
}

// Below two samples a pixel has no second replicate and says nothing; an image of such pixels
// has no estimate (never 0, which would read as converged).
TEST(ConvergenceMeter, NoEstimateWithoutBothReplicates) {
    std::mt19937 rng(1);
    std::vector<MeterPixel> pixels(64, gaussianPixel(rng, glm::dvec3(0.5), 0.1, 1));
    EXPECT_FALSE(estimateNoise(pixels).relativeRmse);
    EXPECT_FALSE(estimateNoise({}).relativeRmse);
    pixels.push_back(gaussianPixel(rng, glm::dvec3(0.5), 0.1, 2));
    EXPECT_EQ(estimateNoise(pixels).pixelsMeasured, 1u);
}

// A black scene and a noiseless one are exactly converged: 0, not NaN (0/0 nowhere).
TEST(ConvergenceMeter, ZeroVarianceIsExactlyZero) {
    for (double value : {0.0, 0.25, 1e5}) {
        MeterPixel p;
        p.count = 1e6;
        p.halfCount = 5e5;
        p.sum = glm::dvec3(value * p.count);
        p.halfSum = glm::dvec3(value * p.halfCount);
        std::vector<MeterPixel> pixels(16, p);
        const NoiseEstimate e = estimateNoise(pixels);
        ASSERT_TRUE(e.relativeRmse);
        EXPECT_EQ(*e.relativeRmse, 0.0) << value;
    }
}

// A pixel seeing a 1e5-radiance sun among dim ones: relMSE divides its error by its own
// square, so the sun neither overflows nor dominates; and a million samples of it keep the
// replicate difference (a difference of sums near 1e11) finite and right.
TEST(ConvergenceMeter, SunPixelAndMillionsOfSamplesStayFinite) {
    std::mt19937 rng(3);
    std::vector<MeterPixel> pixels;
    for (int i = 0; i < 255; ++i) pixels.push_back(gaussianPixel(rng, glm::dvec3(0.2), 0.2, 64));
    pixels.push_back(gaussianPixel(rng, glm::dvec3(1e5), 1e5, 64));
    const NoiseEstimate e = estimateNoise(pixels);
    ASSERT_TRUE(e.relativeRmse);
    EXPECT_TRUE(std::isfinite(*e.relativeRmse));
    EXPECT_LT(*e.relativeRmse, 1.0);

    // 10^6 samples: replicate means 1e5 ± 1 apart exactly.
    MeterPixel big;
    big.count = 1e6;
    big.halfCount = 5e5;
    big.halfSum = glm::dvec3((1e5 + 1.0) * big.halfCount);
    big.sum = big.halfSum + glm::dvec3((1e5 - 1.0) * (big.count - big.halfCount));
    const NoiseEstimate one = estimateNoise(std::vector<MeterPixel>{big});
    ASSERT_TRUE(one.relativeRmse);
    // (A − B)² nA nB / n² = 4 · 1/4 = 1 per channel, over (1e5)² + 0.01.
    EXPECT_NEAR(*one.relativeRmse, 1.0 / 1e5, 1e-12);
}

// A hand-made accumulation with a non-finite sum is skipped, not propagated.
TEST(ConvergenceMeter, NonFinitePixelsAreSkipped) {
    std::mt19937 rng(5);
    std::vector<MeterPixel> pixels(8, gaussianPixel(rng, glm::dvec3(0.5), 0.1, 8));
    MeterPixel bad = pixels[0];
    bad.sum.x = std::numeric_limits<double>::infinity();
    pixels.push_back(bad);
    bad.halfSum.y = std::numeric_limits<double>::quiet_NaN();
    pixels.push_back(bad);
    const NoiseEstimate e = estimateNoise(pixels);
    ASSERT_TRUE(e.relativeRmse);
    EXPECT_TRUE(std::isfinite(*e.relativeRmse));
    EXPECT_EQ(e.pixelsMeasured, 8u);
}

// The 1/√spp extrapolation: the samples it asks for, and the ETA, at ordinary values and at the
// edges (target 0, NaN or infinite noise, 0 samples, no measured rate).
TEST(ConvergenceMeter, PredictionAndEtaAreFiniteAndMonotone) {
    EXPECT_EQ(samplesForNoise(0.02, 100, 0.01), 400u);
    EXPECT_EQ(samplesForNoise(0.01, 100, 0.01), 100u);
    EXPECT_EQ(samplesForNoise(0.005, 100, 0.01), 100u);
    EXPECT_EQ(samplesForNoise(0.02, 0, 0.01), 4u);
    EXPECT_EQ(samplesForNoise(0.02, 100, 0.0), kMaxPredictedSamples);
    EXPECT_EQ(samplesForNoise(1e300, 100, 1e-300), kMaxPredictedSamples);
    EXPECT_EQ(samplesForNoise(std::numeric_limits<double>::quiet_NaN(), 100, 0.01),
              kMaxPredictedSamples);
    EXPECT_EQ(samplesForNoise(std::numeric_limits<double>::infinity(), 100, 0.01),
              kMaxPredictedSamples);

    EXPECT_EQ(etaSeconds(0.005, 100, 0.01, 0.1), 0.0);
    EXPECT_NEAR(*etaSeconds(0.02, 100, 0.01, 0.1), 30.0, 1e-9);
    EXPECT_FALSE(etaSeconds(std::nullopt, 100, 0.01, 0.1));
    EXPECT_FALSE(etaSeconds(0.02, 100, 0.01, 0.0));
    EXPECT_FALSE(etaSeconds(0.02, 100, 0.01, std::numeric_limits<double>::infinity()));
    // Larger noise, later arrival; every value finite.
    double last = 0.0;
    for (double noise = 0.011; noise < 10.0; noise *= 1.7) {
        const std::optional<double> eta = etaSeconds(noise, 64, 0.01, 0.05);
        ASSERT_TRUE(eta);
        EXPECT_TRUE(std::isfinite(*eta));
        EXPECT_GT(*eta, last);
        last = *eta;
    }
}

// The schedule looks at growing counts (never twice at one), stops exactly when the target is
// reached, and never looks later than the prediction.
TEST(ConvergenceMeter, ScheduleLooksGeometricallyAndAtThePrediction) {
    NoiseSchedule plain;
    std::vector<uint64_t> looks;
    for (uint64_t n = 1; n <= 1000000; ++n) {
        if (!plain.due(n)) continue;
        looks.push_back(n);
        plain.looked(n, 1.0 / std::sqrt(double(n)));
    }
    EXPECT_FALSE(plain.reached());  // no target: never "reached"
    EXPECT_LT(looks.size(), 40u);
    for (size_t i = 1; i < looks.size(); ++i) {
        EXPECT_GT(looks[i], looks[i - 1]);
        EXPECT_EQ(looks[i] % 2, 0u);
        EXPECT_LE(looks[i], looks[i - 1] * 3 / 2 + 2);
    }

    // Noise exactly 1/√n aimed at 1 %: the prediction is exact, so the look after the first one
    // past 1.5× steps lands on 10 000.
    NoiseSchedule aimed(0.01);
    uint64_t stop = 0;
    for (uint64_t n = 1; n <= 1000000 && !aimed.reached(); ++n) {
        if (!aimed.due(n)) continue;
        aimed.looked(n, 1.0 / std::sqrt(double(n)));
        stop = n;
    }
    EXPECT_TRUE(aimed.reached());
    EXPECT_NEAR(double(stop), 10000.0, 2.0);
}

}  // namespace
}  // namespace previs
