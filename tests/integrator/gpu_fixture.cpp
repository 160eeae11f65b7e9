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

ImageF GpuTest::render(const Scene& scene, const RenderSettings& settings, uint32_t spp) {
    auto renderer = Renderer::create(*context_, scene, settings);
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

GpuTest::Estimate GpuTest::estimate(const Scene& scene, RenderSettings settings, uint32_t spp,
                                    uint32_t runs) {
    // One renderer (one pipeline compile), re-seeded for each independent run.
    std::vector<ImageF> images;
    auto renderer = Renderer::create(*context_, scene, settings);
    EXPECT_TRUE(renderer.ok()) << renderer.message();
    if (!renderer) return {};
    for (uint32_t r = 0; r < runs; ++r) {
        Renderer& rr = **renderer;
        EXPECT_TRUE(rr.reset().ok());
        rr.setSeed(1000 + r);
        Status s = rr.render(spp);
        EXPECT_TRUE(s.ok()) << s.message();
        auto nonFinite = rr.nonFiniteSamples();
        if (nonFinite) {
            EXPECT_EQ(*nonFinite, 0u) << "NaN/Inf samples";
        }
        auto image = rr.image();
        EXPECT_TRUE(image.ok());
        if (!image) return {};
        images.push_back(std::move(image.value()));
    }
    Estimate e;
    e.mean = images[0];
    size_t n = e.mean.pixels.size();
    e.varianceOfMean.assign(n, 0.0);
    for (size_t i = 0; i < n; ++i) {
        double sum = 0.0, sum2 = 0.0;
        for (const auto& img : images) {
            sum += img.pixels[i];
            sum2 += double(img.pixels[i]) * img.pixels[i];
        }
        double mean = sum / runs;
        double var = std::max(0.0, (sum2 - runs * mean * mean) / (runs - 1));
        e.mean.pixels[i] = float(mean);
        e.varianceOfMean[i] = var / runs;
    }
    return e;
}

}  // namespace previs::testing
