#include "tests/integrator/gpu_fixture.h"

#include <cmath>

namespace previs::testing {

std::unique_ptr<GpuContext> GpuTest::context_;

void GpuTest::SetUpTestSuite() {
    if (context_) return;
    GpuOptions options;
    options.validation = true;
    auto ctx = GpuContext::create(options);
    ASSERT_TRUE(ctx.ok()) << ctx.message();
    context_ = std::move(ctx.value());
}

void GpuTest::SetUp() {
    ASSERT_NE(context_, nullptr);
    errorsAtStart_ = context_->validationErrorCount();
}

void GpuTest::TearDown() {
    if (context_) {
        EXPECT_EQ(context_->validationErrorCount(), errorsAtStart_)
            << "Vulkan validation errors (see the log above)";
    }
}

ImageF GpuTest::render(const Scene& scene, const RenderSettings& settings, uint32_t spp,
                       const RendererTestOptions& testOptions) {
    auto renderer = Renderer::create(*context_, scene, settings, {}, testOptions);
    EXPECT_TRUE(renderer.ok()) << renderer.message();
    if (!renderer) return {};
    Status s = (*renderer)->render(spp);
    EXPECT_TRUE(s.ok()) << s.message();
    auto nonFinite = (*renderer)->nonFiniteSamples();
    EXPECT_TRUE(nonFinite.ok());
    if (nonFinite) {
        EXPECT_EQ(*nonFinite, 0u) << "NaN/Inf samples";
    }
    auto image = (*renderer)->image();
    EXPECT_TRUE(image.ok()) << image.message();
    if (!image) return {};
    for (float v : image->pixels) {
        EXPECT_TRUE(std::isfinite(v));
        if (!std::isfinite(v)) break;
    }
    return std::move(image.value());
}

MeanAndVariance perPixel(const std::vector<ImageF>& images) {
    MeanAndVariance r;
    if (images.empty()) return r;
    const size_t n = images[0].pixels.size();
    const double runs = double(images.size());
    r.mean.assign(n, 0.0);
    r.varianceOfMean.assign(n, 0.0);
    for (size_t i = 0; i < n; ++i) {
        double sum = 0.0, sum2 = 0.0;
        for (const ImageF& img : images) {
            sum += img.pixels[i];
            sum2 += double(img.pixels[i]) * img.pixels[i];
        }
        r.mean[i] = sum / runs;
        r.varianceOfMean[i] =
            std::max(0.0, (sum2 - runs * r.mean[i] * r.mean[i]) / (runs - 1)) / runs;
    }
    return r;
}

MeanDifference compareMeans(const MeanAndVariance& a, const MeanAndVariance& b) {
    MeanDifference r;
    EXPECT_EQ(a.mean.size(), b.mean.size());
    double channelDiff[3] = {}, channelVar[3] = {};
    for (size_t i = 0; i < std::min(a.mean.size(), b.mean.size()); ++i) {
        const double d = a.mean[i] - b.mean[i];
        const double v = a.varianceOfMean[i] + b.varianceOfMean[i];
        if (v > 0.0)
            r.worstPixelT = std::max(r.worstPixelT, std::abs(d) / std::sqrt(v));
        else
            EXPECT_NEAR(d, 0.0, 1e-6) << "noise-free value " << i;
        channelDiff[i % 3] += d;
        channelVar[i % 3] += v;
    }
    for (int c = 0; c < 3; ++c) r.channelZ[c] = std::abs(channelDiff[c]) / std::sqrt(channelVar[c]);
    return r;
}

std::vector<double> meanSquaredErrors(const std::vector<ImageF>& images, const ImageF& reference) {
    std::vector<double> out;
    for (const ImageF& img : images) {
        double mse = 0.0;
        for (size_t i = 0; i < img.pixels.size(); ++i) {
            const double d = img.pixels[i] - reference.pixels[i];
            mse += d * d;
        }
        out.push_back(mse / double(img.pixels.size()));
    }
    return out;
}

std::pair<double, double> meanAndVarianceOfMean(const std::vector<double>& values) {
    const double n = double(values.size());
    double mean = 0.0;
    for (double x : values) mean += x / n;
    double ss = 0.0;
    for (double x : values) ss += (x - mean) * (x - mean);
    return {mean, ss / (n - 1.0) / n};
}

std::vector<ImageF> GpuTest::renders(const Scene& scene, const RenderSettings& settings,
                                     uint32_t spp, uint32_t runs, uint32_t firstSeed) {
    std::vector<ImageF> images;
    auto renderer = Renderer::create(*context_, scene, settings);
    EXPECT_TRUE(renderer.ok()) << renderer.message();
    if (!renderer) return images;
    Renderer& r = **renderer;
    for (uint32_t run = 0; run < runs; ++run) {
        EXPECT_TRUE(r.reset().ok());
        r.setSeed(firstSeed + run);
        Status s = r.render(spp);
        EXPECT_TRUE(s.ok()) << s.message();
        auto nonFinite = r.nonFiniteSamples();
        if (nonFinite) {
            EXPECT_EQ(*nonFinite, 0u) << "NaN/Inf samples";
        }
        auto image = r.image();
        EXPECT_TRUE(image.ok());
        if (!image) return {};
        images.push_back(std::move(image.value()));
    }
    return images;
}

GpuTest::Estimate GpuTest::estimate(const Scene& scene, RenderSettings settings, uint32_t spp,
                                    uint32_t runs) {
    std::vector<ImageF> images = renders(scene, settings, spp, runs, 1000);
    if (images.size() != runs) return {};
    MeanAndVariance mv = perPixel(images);
    Estimate e;
    e.mean = images[0];
    for (size_t i = 0; i < mv.mean.size(); ++i) e.mean.pixels[i] = float(mv.mean[i]);
    e.varianceOfMean = std::move(mv.varianceOfMean);
    return e;
}

}  // namespace previs::testing
