#pragma once

// A Vulkan context shared by a test suite, with validation on; any validation error fails the
// test that caused it.

#include <gtest/gtest.h>

#include <memory>

#include "gpu/context.h"
#include "image/image.h"
#include "render/renderer.h"

namespace previs::testing {

// Per pixel and channel: the mean of `images` and the variance of that mean (unbiased sample
// variance / count).
struct MeanAndVariance {
    std::vector<double> mean;
    std::vector<double> varianceOfMean;
};
MeanAndVariance perPixel(const std::vector<ImageF>& images);

// How far two estimates' means are apart in units of their noise: the largest |Δ|/σ over pixels
// and channels (σ² the sum of both variances of the mean), and per RGB channel the image mean's
// |Δ|/σ. A value with no noise in both must agree to 1e-6 (checked here).
struct MeanDifference {
    double worstPixelT = 0.0;
    double channelZ[3] = {};
};
MeanDifference compareMeans(const MeanAndVariance& a, const MeanAndVariance& b);

// The mean squared error of each image against `reference`, over pixels and channels.
std::vector<double> meanSquaredErrors(const std::vector<ImageF>& images, const ImageF& reference);

// The mean of `values` and the variance of that mean.
std::pair<double, double> meanAndVarianceOfMean(const std::vector<double>& values);

class GpuTest : public ::testing::Test {
protected:
    static void SetUpTestSuite();
    static void TearDownTestSuite() { context_.reset(); }
    void SetUp() override;
    void TearDown() override;

    static GpuContext& ctx() { return *context_; }

    // Renders `spp` samples per pixel and returns the mean image; fails the test on any error,
    // on a NaN/Inf sample, or a non-finite pixel.
    ImageF render(const Scene& scene, const RenderSettings& settings, uint32_t spp,
                  const RendererTestOptions& testOptions = {});

    // The images of `runs` renders of `spp` samples, seeds firstSeed, firstSeed + 1, ... (one
    // renderer, one pipeline compile, re-seeded); fails the test on any error or NaN/Inf sample.
    std::vector<ImageF> renders(const Scene& scene, const RenderSettings& settings, uint32_t spp,
                                uint32_t runs, uint32_t firstSeed);

    // Per-pixel mean and variance of the mean over `runs` independent renders (seeds 1000..):
    // the noise that tolerances are derived from.
    struct Estimate {
        ImageF mean;
        std::vector<double> varianceOfMean;  // per pixel and channel
    };
    Estimate estimate(const Scene& scene, RenderSettings settings, uint32_t spp, uint32_t runs);

private:
    static std::unique_ptr<GpuContext> context_;
    uint32_t errorsAtStart_ = 0;
};

}  // namespace previs::testing
