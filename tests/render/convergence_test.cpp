// The convergence meter's arithmetic (render/convergence.h) on synthetic accumulations whose
// true error is known: Gaussian samples of a stated variance, and the extremes — no samples,
// zero variance, a 1e5-radiance sun, a million samples per pixel.
#include "render/convergence.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

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

    EXPECT_EQ(secondsToStop(100, 0.005, 0.01, 0, 0.1), 0.0);
    EXPECT_NEAR(*secondsToStop(100, 0.02, 0.01, 0, 0.1), 30.0, 1e-9);
    EXPECT_FALSE(secondsToStop(100, std::nullopt, 0.01, 0, 0.1));
    EXPECT_FALSE(secondsToStop(100, 0.02, 0.01, 0, 0.0));
    EXPECT_FALSE(secondsToStop(100, 0.02, 0.01, 0, std::numeric_limits<double>::infinity()));
    // Larger noise, later arrival; every value finite.
    double last = 0.0;
    for (double noise = 0.011; noise < 10.0; noise *= 1.7) {
        const std::optional<double> eta = secondsToStop(64, noise, 0.01, 0, 0.05);
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

// The stopping rule alone (issue 55): it stops at the target, on a look, or at the maximum,
// whichever comes first, and nowhere else.
TEST(StoppingRule, DoneAtTheTargetOrAtTheMaximum) {
    // Noise exactly 0.5/√n aimed at 1 %: reached at n = 2500, seen at the first look past it.
    const double c = 0.5;
    StoppingRule aimed(0.01);
    EXPECT_FALSE(aimed.done(0));
    uint64_t n = 0;
    while (!aimed.done(n)) {
        ASSERT_LT(n, 100000u) << "never stopped";
        n = std::min(aimed.nextStop(n), n + 16);
        if (aimed.lookDue(n)) aimed.looked(n, c / std::sqrt(double(n)));
    }
    EXPECT_TRUE(aimed.reachedTarget());
    EXPECT_GE(n, 2500u);
    EXPECT_LE(double(n), 2500.0 * 1.5 + 2.0);

    // The same curve capped at 1000 samples: the maximum first, exactly there, never past it.
    StoppingRule capped(0.01, 1000);
    n = 0;
    while (!capped.done(n)) {
        const uint64_t stop = capped.nextStop(n);
        ASSERT_LE(stop, 1000u);
        n = std::min(stop, n + 16);
        if (capped.lookDue(n)) capped.looked(n, c / std::sqrt(double(n)));
    }
    EXPECT_EQ(n, 1000u);
    EXPECT_FALSE(capped.reachedTarget());

    // No target: only the maximum stops it, whatever the meter says.
    StoppingRule fixed(0.0, 64);
    fixed.looked(16, 0.0);
    EXPECT_FALSE(fixed.reachedTarget());
    EXPECT_FALSE(fixed.done(63));
    EXPECT_TRUE(fixed.done(64));
    EXPECT_EQ(fixed.nextStop(16), 64u);

    // restart() forgets the looks: a new accumulation is not done because the last one was.
    aimed.restart();
    EXPECT_FALSE(aimed.done(0));
    EXPECT_FALSE(aimed.measured());
}

// The ETA falls monotonically to 0 along a 1/√n noise curve seen at the rule's looks (carried
// forward between them), and is exactly the remaining samples at the measured cost.
TEST(StoppingRule, EtaFallsMonotonicallyAlongTheNoiseCurve) {
    const double c = 0.5, target = 0.01, secondsPerSample = 0.04;
    const double reachAt = (c / target) * (c / target);  // 2500 samples
    StoppingRule rule(target);
    double last = std::numeric_limits<double>::infinity();
    size_t etas = 0;
    for (uint64_t n = 1; n < 10000; ++n) {
        if (rule.lookDue(n)) rule.looked(n, c / std::sqrt(double(n)));
        const std::optional<double> eta = rule.eta(n, secondsPerSample);
        if (eta) {  // from the first look on
            ++etas;
            ASSERT_TRUE(std::isfinite(*eta)) << n;
            EXPECT_LE(*eta, last) << n;
            EXPECT_NEAR(*eta, std::max(0.0, reachAt - double(n)) * secondsPerSample, 1e-6) << n;
            last = *eta;
        }
        if (rule.done(n)) break;
    }
    EXPECT_TRUE(rule.reachedTarget());
    EXPECT_GT(etas, 2000u);
    EXPECT_EQ(last, 0.0);
    // The maximum first: the ETA is to it.
    StoppingRule capped(target, 1000);
    capped.looked(100, c / 10.0);
    EXPECT_NEAR(*capped.eta(100, secondsPerSample), 900 * secondsPerSample, 1e-9);
    EXPECT_EQ(*capped.eta(1000, secondsPerSample), 0.0);
}

// The edges: no samples, zero noise, no measured rate, broken estimates; nothing divides by zero
// and nothing is NaN or infinite.
TEST(StoppingRule, NoDivisionByZeroAtZeroSamplesOrZeroNoise) {
    const double nan = std::nan(""), inf = HUGE_VAL;
    StoppingRule rule(0.01);
    // Nothing looked, no samples: nothing to say, not done.
    EXPECT_FALSE(rule.eta(0, 0.04));
    EXPECT_FALSE(rule.noiseAt(0));
    EXPECT_FALSE(rule.done(0));
    // A look at 0 samples (zero noise there says nothing): still not done, still no ETA.
    rule.looked(0, 0.0);
    EXPECT_FALSE(rule.done(0));
    EXPECT_FALSE(rule.eta(0, 0.04));
    EXPECT_EQ(rule.noiseAt(16).value_or(-1.0), 0.0);
    // Zero noise at 16 samples (a black scene): done, ETA 0.
    rule.looked(16, 0.0);
    EXPECT_TRUE(rule.done(16));
    EXPECT_EQ(rule.eta(16, 0.04).value_or(-1.0), 0.0);
    // No cost measured, or a broken one: nothing, unless already stopped.
    StoppingRule far(0.01, 4096);
    far.looked(16, 0.05);
    for (double cost : {0.0, -1.0, nan, inf}) {
        EXPECT_FALSE(far.eta(16, cost)) << cost;
        EXPECT_EQ(far.eta(4096, cost).value_or(-1.0), 0.0) << cost;
    }
    // Without a target or a maximum the accumulation never stops: no ETA.
    StoppingRule open;
    open.looked(16, 0.05);
    EXPECT_FALSE(open.eta(16, 0.04));
    EXPECT_FALSE(open.done(UINT64_MAX));
    EXPECT_EQ(open.nextStop(16), UINT64_MAX);
    // A target that is not a number is none.
    EXPECT_EQ(StoppingRule(nan).targetNoise(), 0.0);
    // The formula itself at its edges.
    EXPECT_FALSE(secondsToStop(0, 0.0, 0.01, 0, 0.04)) << "zero noise at zero samples";
    EXPECT_NEAR(*secondsToStop(0, std::nullopt, 0.01, 64, 0.04), 64 * 0.04, 1e-12);
    for (double noise : {nan, inf, -1.0})
        EXPECT_NEAR(*secondsToStop(16, noise, 0.01, 4096, 0.04), 4080 * 0.04, 1e-9) << noise;
    // A sun pixel's 1e5 relative error against a tiny target: astronomically far, still finite.
    const std::optional<double> sun = secondsToStop(1, 1e5, 1e-6, 0, 1.0);
    ASSERT_TRUE(sun);
    EXPECT_TRUE(std::isfinite(*sun));
    EXPECT_GT(*sun, 1e20);
}

}  // namespace
}  // namespace previs
