// The denoiser (render/denoiser.h, gpu/shaders/denoise.comp): exact where the signal is flat,
// never touching the plate, edges kept, and measured bias: converging to the undenoised image at
// high sample counts, reducing the error at low ones. Tolerances come from the measured noise.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>

#include "shared/denoise.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

ImageF take(Result<ImageF> result) {
    if (!result.ok()) {
        ADD_FAILURE() << result.message();
        return {};
    }
    return std::move(result).value();
}

// DESIGN.md §4's relMSE of `a` against `ref`, and the RMSE.
double relMse(const ImageF& a, const ImageF& ref) {
    double sum = 0.0;
    for (size_t i = 0; i < ref.pixels.size(); ++i) {
        const double d = double(a.pixels[i]) - ref.pixels[i];
        sum += d * d / (double(ref.pixels[i]) * ref.pixels[i] + 0.01);
    }
    return sum / double(ref.pixels.size());
}
double rmse(const ImageF& a, const ImageF& ref) {
    double sum = 0.0;
    for (size_t i = 0; i < ref.pixels.size(); ++i) {
        const double d = double(a.pixels[i]) - ref.pixels[i];
        sum += d * d;
    }
    return std::sqrt(sum / double(ref.pixels.size()));
}

ImageF constantPlate(uint32_t w, uint32_t h, float v) {
    ImageF p;
    p.width = w;
    p.height = h;
    p.channels = 3;
    p.pixels.assign(size_t(w) * h * 3, v);
    return p;
}

// A real floor and box under a real sun and sky, a virtual sphere: shadows, occlusion and
// colour bleeding in L_om − L_or (as test_differential.cpp's set).
Scene differentialSet(bool withSky) {
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 2}, {2, 0, 0}, addMaterial(s, lambert(glm::vec3(0.7f))), true);
    addBox(s, {-0.9f, 0, -0.3f}, {-0.5f, 0.4f, 0.1f},
           addMaterial(s, lambert(glm::vec3(0.8f, 0.1f, 0.1f))), true);
    addSphere(s, {0.3f, 0.3f, 0.0f}, 0.25f, addMaterial(s, lambert(glm::vec3(0.1f, 0.8f, 0.2f))),
              false, 16, 32);
    PunctualLight sun;
    sun.type = LightType::Directional;
    sun.direction = glm::normalize(glm::vec3(-1, -1, 0));
    sun.intensity = 3.0f;
    sun.isReal = true;
    s.lights.push_back(sun);
    if (withSky) s.environment = uniformEnvironment(glm::vec3(0.3f));
    s.cameras.push_back(lookAt({0, 3, 0.01f}, {0, 0, 0}, {0, 0, -1}, glm::radians(60.0f)));
    return s;
}

RenderSettings settingsFor(uint32_t w, uint32_t h, uint32_t maxDepth) {
    RenderSettings rs;
    rs.width = w;
    rs.height = h;
    rs.maxDepth = maxDepth;
    rs.differential = true;
    rs.denoise = true;
    return rs;
}

class DenoiseTest : public GpuTest {};

// The filter is normalised and sums differences to the centre: a flat signal comes out bit for
// bit, whatever the guides (random depths, normals and variances, some unknown) say.
TEST_F(DenoiseTest, FlatImageStaysExactlyFlat) {
    constexpr uint32_t kW = 48, kH = 40;
    auto denoiser = Denoiser::create(ctx(), kW, kH);
    ASSERT_TRUE(denoiser.ok()) << denoiser.message();
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<glm::vec4> guides(size_t(kW) * kH * PV_GUIDE_COUNT, glm::vec4(0.0f));
    std::vector<float> variance(size_t(kW) * kH);
    for (size_t i = 0; i < size_t(kW) * kH; ++i) {
        guides[i * PV_GUIDE_COUNT + PV_GUIDE_ALBEDO_DEPTH] =
            glm::vec4(0.6f, 0.3f, 0.9f, 1.0f + 5.0f * u(rng));
        guides[i * PV_GUIDE_COUNT + PV_GUIDE_NORMAL] =
            glm::vec4(u(rng) - 0.5f, u(rng) - 0.5f, 1.0f, 1.0f);
        variance[i] = u(rng) < 0.3f ? -1.0f : u(rng);
    }
    for (glm::vec3 colour : {glm::vec3(0.3f, 0.7f, 1.9f), glm::vec3(-0.25f, 1e4f, 0.0f)}) {
        ImageF flat;
        flat.width = kW;
        flat.height = kH;
        flat.channels = 3;
        for (size_t i = 0; i < size_t(kW) * kH; ++i)
            for (int c = 0; c < 3; ++c) flat.pixels.push_back(colour[c]);
        ImageF out = take(denoiser->apply(flat, guides, variance));
        ASSERT_EQ(out.pixels.size(), flat.pixels.size());
        EXPECT_EQ(std::memcmp(out.pixels.data(), flat.pixels.data(), flat.pixels.size() * 4), 0);
    }
}

// The guides cost nothing to the samples: a renderer with the denoiser's guides accumulates the
// same bits as one without. And the guides are right: a floor of known albedo at a known depth.
TEST_F(DenoiseTest, GuidesLeaveTheSamplesUnchangedAndMeasureTheFirstHit) {
    Scene s = differentialSet(true);
    RenderSettings rs = settingsFor(32, 32, 4);
    RenderSettings plain = rs;
    plain.denoise = false;
    ImageF withGuides = render(s, rs, 4);
    ImageF without = render(s, plain, 4);
    ASSERT_EQ(withGuides.pixels.size(), without.pixels.size());
    EXPECT_EQ(
        std::memcmp(withGuides.pixels.data(), without.pixels.data(), without.pixels.size() * 4), 0);

    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    ASSERT_TRUE((*renderer)->render(8).ok());
    ImageF albedo = take((*renderer)->image(Aov::Albedo));
    ImageF depth = take((*renderer)->image(Aov::Depth));
    ImageF normal = take((*renderer)->image(Aov::Normal));
    // A corner pixel sees the floor (the sphere and box are near the middle and left): the
    // camera 3 m above it, 60° field of view. The pixel centre's ray is 3 / cos θ long.
    const uint32_t x = 30, y = 30;
    const size_t i = size_t(y) * rs.width + x;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(albedo.pixels[i * 3 + c], 0.7f, 1e-5f);
    const float t = std::tan(glm::radians(30.0f));
    const glm::vec2 ndc((x + 0.5f) / 16.0f - 1.0f, 1.0f - (y + 0.5f) / 16.0f);
    const float expected = 3.0f * glm::length(glm::vec3(ndc * t, 1.0f));
    // Jitter over the pixel: the distance varies by about a pixel's footprint (≈ 1 %).
    EXPECT_NEAR(depth.pixels[i], expected, 0.01f * expected);
    EXPECT_NEAR(normal.pixels[i * 3 + 1], 1.0f, 1e-5f);  // the floor's +Y
    // Misses are far away.
    RenderSettings noGuides = plain;
    auto bare = Renderer::create(ctx(), s, noGuides);
    ASSERT_TRUE(bare.ok());
    EXPECT_FALSE((*bare)->image(Aov::Depth).ok());
    EXPECT_FALSE((*bare)->image(Aov::Composite, true).ok());
}

// Where no virtual object changes anything (L_om − L_or exactly 0, no virtual first hit) and no
// influenced pixel lies within the filter's reach, the denoised composite is the plate bit for
// bit: direct light only and a sun, so the sphere's influence is its own pixels and its shadow.
TEST_F(DenoiseTest, PlatePixelsAreBitUnchanged) {
    Scene s = differentialSet(false);
    RenderSettings rs = settingsFor(64, 64, 1);
    rs.denoiseSettings.iterations = 3;  // reach 2·(1 + 2 + 4) = 14 pixels
    constexpr int kReach = 14;
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> logv(-3.0f, 3.0f);
    ImageF plate = constantPlate(rs.width, rs.height, 0.0f);
    for (float& v : plate.pixels) v = std::pow(10.0f, logv(rng));
    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    ASSERT_TRUE((*renderer)->setPlate(plate).ok());
    ASSERT_TRUE((*renderer)->render(16).ok());
    ImageF composite = take((*renderer)->image(Aov::Composite));
    ImageF denoised = take((*renderer)->image(Aov::Composite, true));
    const int w = int(rs.width), h = int(rs.height);
    std::vector<bool> influenced(size_t(w) * h);
    for (size_t i = 0; i < influenced.size(); ++i)
        for (int c = 0; c < 3; ++c)
            if (composite.pixels[i * 3 + c] != plate.pixels[i * 3 + c]) influenced[i] = true;
    size_t plateOnly = 0, changed = 0;
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            const size_t i = size_t(y) * w + x;
            bool near = false;
            for (int dy = -kReach; dy <= kReach && !near; ++dy)
                for (int dx = -kReach; dx <= kReach && !near; ++dx) {
                    const int qx = x + dx, qy = y + dy;
                    near =
                        qx >= 0 && qy >= 0 && qx < w && qy < h && influenced[size_t(qy) * w + qx];
                }
            for (int c = 0; c < 3; ++c)
                changed += denoised.pixels[i * 3 + c] != composite.pixels[i * 3 + c];
            if (near) continue;
            ++plateOnly;
            for (int c = 0; c < 3; ++c)
                ASSERT_EQ(denoised.pixels[i * 3 + c], plate.pixels[i * 3 + c]) << x << "," << y;
        }
    }
    // Neither half of the test is empty: plate pixels were checked, and the shadow was filtered.
    EXPECT_GT(plateOnly, size_t(w * h / 10));
    EXPECT_GT(changed, size_t(0));
}

// Two planes facing the camera with the same albedo and normal, 1 m and 3 m away, the near one
// brightly lit by a light just in front of it: only depth tells them apart. Bleeding across the
// edge (the mean error in the three columns beside it against a long reference) stays under 5 %
// of the contrast across the edge, beyond the measured noise of that mean.
TEST_F(DenoiseTest, DepthEdgeDoesNotBleed) {
    Scene s;
    const uint32_t grey = addMaterial(s, lambert(glm::vec3(0.5f)));
    addQuad(s, {-1.0f, 0, -1.0f}, {1.0f, 0, 0}, {0, 1.0f, 0}, grey, false);  // x in [−2, 0]
    addQuad(s, {0, 0, -3.0f}, {3.0f, 0, 0}, {0, 3.0f, 0}, grey, false);
    PunctualLight lamp;
    lamp.position = {-0.4f, 0.0f, -0.7f};
    lamp.intensity = 5.0f;
    s.lights.push_back(lamp);
    s.environment = uniformEnvironment(glm::vec3(0.5f));
    s.cameras.push_back(lookAt({0, 0, 0}, {0, 0, -1}, {0, 1, 0}, glm::radians(40.0f)));
    RenderSettings rs = settingsFor(64, 64, 4);
    rs.differential = false;
    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    Renderer& r = **renderer;
    r.setSeed(99);
    ASSERT_TRUE(r.render(512).ok());
    ImageF ref = take(r.image(Aov::Composite));
    // The edge x = 0 is the boundary between columns 31 (near) and 32 (far).
    auto bandMean = [&](const ImageF& img, int x0, int x1) {
        double sum = 0.0;
        for (uint32_t y = 0; y < rs.height; ++y)
            for (int x = x0; x < x1; ++x)
                for (int c = 0; c < 3; ++c) sum += img.at(x, y, c);
        return sum / (rs.height * (x1 - x0) * 3);
    };
    const double contrast = bandMean(ref, 29, 32) - bandMean(ref, 32, 35);
    ASSERT_GT(contrast, 1.0);  // the lamp makes the near side bright (checks the scene)
    std::vector<double> farBleed, nearBleed;
    for (uint32_t seed = 0; seed < 6; ++seed) {
        ASSERT_TRUE(r.reset().ok());
        r.setSeed(seed);
        ASSERT_TRUE(r.render(4).ok());
        ImageF den = take(r.image(Aov::Composite, true));
        farBleed.push_back(bandMean(den, 32, 35) - bandMean(ref, 32, 35));
        nearBleed.push_back(bandMean(ref, 29, 32) - bandMean(den, 29, 32));
    }
    for (const auto& bleed : {farBleed, nearBleed}) {
        auto [mean, varianceOfMean] = meanAndVarianceOfMean(bleed);
        EXPECT_LT(std::abs(mean), 0.05 * contrast + 4.0 * std::sqrt(varianceOfMean))
            << "bleed " << mean << " of contrast " << contrast;
    }
}

// Bias: at 256 spp the denoised composite is as close to the undenoised one as the undenoised
// one's own noise allows. Two independent 256-spp renders differ by twice the noise's relMSE;
// a filter without bias removes at most that noise, so it must stay below that difference
// (a filter that blurred the shadow's edge would add its bias on top and exceed it).
TEST_F(DenoiseTest, ConvergesToTheUndenoisedImageAtHighSampleCounts) {
    Scene s = differentialSet(true);
    RenderSettings rs = settingsFor(64, 64, 4);
    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    Renderer& r = **renderer;
    ASSERT_TRUE(r.setPlate(constantPlate(rs.width, rs.height, 0.5f)).ok());
    ImageF undenoised[2], denoised[2];
    for (int k = 0; k < 2; ++k) {
        ASSERT_TRUE(r.reset().ok());
        r.setSeed(200 + k);
        ASSERT_TRUE(r.render(256).ok());
        undenoised[k] = take(r.image(Aov::Composite));
        denoised[k] = take(r.image(Aov::Composite, true));
    }
    const double noiseTwice = relMse(undenoised[0], undenoised[1]);
    for (int k = 0; k < 2; ++k) {
        const double change = relMse(denoised[k], undenoised[k]);
        EXPECT_LT(change, noiseTwice) << "run " << k;
        EXPECT_GT(change, 0.0);
    }
}

// The RMSE of 4-spp composites over seeds 300..303, undenoised over denoised, against a
// 1024-spp render at the same resolution scale (the error the filter can remove is the noise;
// what a scale loses in resolution is the upsampler's, tests/integrator/test_resolution_scale.cpp).
// Every denoised frame has the output's size and is finite.
double denoiseGainAt4Spp(GpuContext& ctx, float resolutionScale) {
    Scene s = differentialSet(true);
    RenderSettings rs = settingsFor(64, 64, 4);
    auto renderer = Renderer::create(ctx, s, rs);
    EXPECT_TRUE(renderer.ok()) << renderer.message();
    if (!renderer.ok()) return 0.0;
    Renderer& r = **renderer;
    EXPECT_TRUE(r.setPlate(constantPlate(rs.width, rs.height, 0.5f)).ok());
    EXPECT_TRUE(r.setResolutionScale(resolutionScale).ok());
    r.setSeed(77);
    EXPECT_TRUE(r.render(1024).ok());
    ImageF ref = take(r.image(Aov::Composite));
    double before = 0.0, after = 0.0;
    for (uint32_t seed = 300; seed < 304; ++seed) {
        EXPECT_TRUE(r.reset().ok());
        r.setSeed(seed);
        EXPECT_TRUE(r.render(4).ok());
        ImageF denoised = take(r.image(Aov::Composite, true));
        EXPECT_EQ(denoised.width, rs.width);
        EXPECT_EQ(denoised.height, rs.height);
        EXPECT_TRUE(std::all_of(denoised.pixels.begin(), denoised.pixels.end(),
                                [](float v) { return std::isfinite(v); }));
        const double b = rmse(take(r.image(Aov::Composite)), ref);
        const double a = rmse(denoised, ref);
        std::printf("seed %u, scale %.2f: RMSE %.5f undenoised, %.5f denoised, gain %.2fx\n", seed,
                    resolutionScale, b, a, b / a);
        before += b;
        after += a;
    }
    return before / after;
}

// At 4 spp the denoiser cuts the RMSE against a long reference. Measured over seeds 300..303
// when this test was written: 1.48×, 1.63×, 1.45×, 1.59× (printed); the mean gain is asserted
// above 1.3, below the smallest seed's with room for other devices' float differences.
TEST_F(DenoiseTest, ReducesTheErrorAtLowSampleCounts) {
    constexpr double kMinGain = 1.3;
    EXPECT_GT(denoiseGainAt4Spp(ctx(), 1.0f), kMinGain);
}

// At a resolution scale below 1 the traced pixels are filtered, then upsampled. At scale 1/2,
// measured when this test was written: 1.39×, 1.27×, 1.14×, 1.24× (printed), the gain of the
// summed RMSE 1.26×; that is asserted above 1.15, about two seeds' spread below.
TEST_F(DenoiseTest, AtAResolutionScaleTheTracedPixelsAreFiltered) {
    constexpr double kMinGain = 1.15;
    EXPECT_GT(denoiseGainAt4Spp(ctx(), 0.5f), kMinGain);
}

}  // namespace
}  // namespace previs::testing
