// The path tracer against answers known in closed form. Tolerances come from the noise each
// render measures (variance of the mean over independent seeds), never tuned until green;
// seeds are fixed so every run draws the same samples.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <glm/gtc/matrix_transform.hpp>
#include <numeric>
#include <optional>

#include "gpu/shaders/shared/bsdf.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

constexpr float kPi = 3.14159265358979f;

float radians(float deg) { return deg * kPi / 180.0f; }

// Luminance-free helpers: every test scene here is grey, so channel 0 stands for all.
float pixel(const ImageF& img, uint32_t x, uint32_t y) { return img.at(x, y, 0); }

// The camera ray through image position (px, py) in pixels, as trace_paths.comp builds it.
glm::vec3 cameraDirection(const Camera& c, uint32_t w, uint32_t h, float px, float py) {
    float tanY = std::tan(0.5f * c.fovYRad);
    glm::vec3 d((px / float(w) * 2.0f - 1.0f) * tanY * float(w) / float(h),
                (1.0f - py / float(h) * 2.0f) * tanY, -1.0f);
    return glm::normalize(glm::mat3(c.worldFromCamera) * d);
}

glm::vec3 cameraPosition(const Camera& c) { return glm::vec3(c.worldFromCamera[3]); }

// Mean of f over a pixel's footprint by an n×n midpoint rule (the box pixel filter).
template <typename F>
double pixelAverage(uint32_t x, uint32_t y, int n, F f) {
    double sum = 0.0;
    for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) sum += f(float(x) + (i + 0.5f) / n, float(y) + (j + 0.5f) / n);
    return sum / (n * n);
}

class IntegratorTest : public GpuTest {};

// Per-pixel bound on |measured − expected| / σ, where σ² is the variance of the mean estimated
// from 16 independent runs: the pixel statistic follows Student's t with 15 degrees of freedom,
// and 6.6 is its two-sided critical value for a Šidák-corrected 1% level over 1024 pixels.
constexpr int kRuns = 16;
constexpr double kPixelT = 6.6;

// Where the camera ray through (px, py) meets the floor y = 0; none where it looks up.
std::optional<glm::vec3> floorHit(const Camera& cam, const RenderSettings& rs, float px, float py) {
    const glm::vec3 d = cameraDirection(cam, rs.width, rs.height, px, py);
    if (d.y >= 0.0f) return std::nullopt;
    const glm::vec3 eye = cameraPosition(cam);
    return eye + d * (-eye.y / d.y);
}

struct ClosedFormCheck {
    int tested = 0;              // pixels compared
    double worstRelative = 0.0;  // the largest |got − expected| / expected among them
};

// Every pixel's red channel against `expected` at the points of its footprint (an n×n midpoint
// rule: the box filter), which gives none where the closed form does not hold (the pixel is then
// left out): within kPixelT of the pixel's measured noise plus `relative` of the value.
template <typename Estimate, typename F>
ClosedFormCheck expectClosedForm(const Estimate& e, const RenderSettings& rs, int n,
                                 double relative, F expected) {
    ClosedFormCheck check;
    for (uint32_t y = 0; y < rs.height; ++y)
        for (uint32_t x = 0; x < rs.width; ++x) {
            bool holds = true;
            const double want = pixelAverage(x, y, n, [&](float px, float py) {
                const std::optional<double> v = expected(px, py);
                holds = holds && v.has_value();
                return v.value_or(0.0);
            });
            if (!holds) continue;
            ++check.tested;
            const double got = pixel(e.mean, x, y);
            const double sigma = std::sqrt(e.varianceOfMean[(y * rs.width + x) * 3]);
            EXPECT_NEAR(got, want, kPixelT * sigma + relative * want) << "pixel " << x << "," << y;
            check.worstRelative = std::max(check.worstRelative, std::abs(got - want) / want);
        }
    return check;
}

// White furnace: inside a uniform environment of radiance 1, an albedo-1 object neither creates
// nor loses energy, so every pixel is 1.
Scene furnaceScene(const Material& material) {
    Scene s;
    addSphere(s, glm::vec3(0.0f), 1.0f, addMaterial(s, material));
    s.environment = uniformEnvironment(glm::vec3(1.0f));
    s.cameras.push_back(lookAt({0, 0, 4}, {0, 0, 0}, {0, 1, 0}, radians(40)));
    return s;
}

TEST_F(IntegratorTest, WhiteFurnaceLambertianSphere) {
    Scene s = furnaceScene(lambert(glm::vec3(1.0f)));
    RenderSettings rs = renderSettings(24, 24, 64);
    Estimate e = estimate(s, rs, 16, kRuns);
    double sum = 0.0, var = 0.0;
    double worstZ = 0.0;
    size_t n = size_t(rs.width) * rs.height;
    for (size_t i = 0; i < n; ++i) {
        double v = e.mean.pixels[i * 3];
        sum += v;
        var += e.varianceOfMean[i * 3];
        if (e.varianceOfMean[i * 3] > 0.0)
            worstZ = std::max(worstZ, std::abs(v - 1.0) / std::sqrt(e.varianceOfMean[i * 3]));
        else
            EXPECT_NEAR(v, 1.0, 1e-5) << "noise-free pixel " << i;
    }
    double mean = sum / n;
    double stdErr = std::sqrt(var) / n;
    // 4 standard errors of the image mean (the pixels are independent); per pixel, kPixelT.
    EXPECT_NEAR(mean, 1.0, 4.0 * stdErr) << "standard error " << stdErr;
    EXPECT_LT(worstZ, kPixelT);
}

TEST_F(IntegratorTest, WhiteFurnaceMirrorSphereIsExact) {
    Scene s = furnaceScene(mirror());
    RenderSettings rs = renderSettings(24, 24, 64);
    ImageF img = render(s, rs, 4);
    for (float v : img.pixels) ASSERT_NEAR(v, 1.0f, 1e-5f);
}

TEST_F(IntegratorTest, WhiteFurnaceGlassSphereIsExact) {
    for (float ior : {1.33f, 1.5f, 2.4f}) {
        Scene s = furnaceScene(glass(ior));
        RenderSettings rs = renderSettings(24, 24, 256);
        ImageF img = render(s, rs, 8);
        // Each path carries weight 1: Fresnel reflection and refraction are chosen with their
        // exact probabilities and the η² factors cancel on the way out.
        for (float v : img.pixels) ASSERT_NEAR(v, 1.0f, 2e-4f) << "ior " << ior;
    }
}

// Rough glass in the furnace: the lobes' energy compensation (bsdf.h, glassEnergyScale, read from
// the tables the renderer uploads ahead of the materials) keeps every path's expected weight at
// 1 through any number of rough interfaces. The image mean must be 1 within 4 standard errors,
// less the tables' resolution: an interaction loses at most 2 % where θo ≤ 80° (test_bsdf,
// kGlassTableExcess), more only at grazing angles, which the cosine makes rare; a camera path
// meets the ball about twice (in and out) plus its internal reflections, so 3 % bounds the
// image's loss (a bound, not fitted). Single scattering alone gives an image mean of 0.979 at
// roughness 0.3 and 0.737 at roughness 1; compensated, 0.996 and 0.996 (± 0.001, ± 0.002).
TEST_F(IntegratorTest, WhiteFurnaceRoughGlassSphereKeepsItsEnergy) {
    for (float roughness : {0.3f, 1.0f}) {
        Material m = glass(1.5f);
        m.roughness = roughness;
        Scene s = furnaceScene(m);
        RenderSettings rs = renderSettings(24, 24, 256);
        Estimate e = estimate(s, rs, 16, 8);
        double sum = 0.0, var = 0.0;
        const size_t n = size_t(rs.width) * rs.height;
        for (size_t i = 0; i < n; ++i) {
            sum += e.mean.pixels[i * 3];
            var += e.varianceOfMean[i * 3];
        }
        const double mean = sum / n, stdErr = std::sqrt(var) / n;
        EXPECT_LE(mean, 1.0 + 4.0 * stdErr) << "roughness " << roughness;
        EXPECT_GE(mean, 1.0 - 0.03 - 4.0 * stdErr) << "roughness " << roughness;
        std::printf("rough glass furnace, roughness %.1f: image mean %.4f ± %.4f\n", roughness,
                    mean, stdErr);
    }
}

// A coarse smooth-shaded sphere (8×16 facets): its interpolated shading normals disagree with
// the facets' geometric normals by up to half a facet's angle, most near the silhouette, where
// the mirror direction about the shading normal points into the facet. Before shading-normal
// adaptation (bsdf.h, adaptShadingNormal) those paths were killed: 48×48 pixels, 16 spp, mirror
// 100 pixels below 1, worst 0.5625, image mean 0.99216; glass (max depth 256) 108 pixels, worst
// 0.5625, mean 0.99311.
TEST_F(IntegratorTest, WhiteFurnaceLowPolySmoothSphereKeepsItsSilhouette) {
    RenderSettings rs;
    rs.width = rs.height = 48;
    auto furnace = [&](const Material& material) {
        Scene s;
        addSphere(s, glm::vec3(0.0f), 1.0f, addMaterial(s, material), false, 8, 16);
        s.environment = uniformEnvironment(glm::vec3(1.0f));
        s.cameras.push_back(lookAt({0, 0, 4}, {0, 0, 0}, {0, 1, 0}, radians(40)));
        return render(s, rs, 16);
    };
    // The mirror: every path has weight 1 and, with the adapted normal, leaves the convex mesh
    // at its first reflection, so every pixel is exactly 1, silhouettes included.
    rs.maxDepth = 64;
    ImageF img = furnace(mirror());
    int off = 0;
    float worst = 1.0f;
    for (float v : img.pixels) {
        worst = std::min(worst, v);
        if (std::abs(v - 1.0f) > 1e-5f) ++off;
    }
    EXPECT_EQ(off, 0) << "worst pixel " << worst;
    // Glass: each path still weighs 1, but interpolated normals that disagree with the facets
    // break the reversibility that keeps light from being trapped in a true sphere: a few rays
    // that enter near the rim meet the inside beyond the critical angle on every facet and
    // circle forever (a CPU replica of this loop, 36864 paths: all remaining losses are paths
    // reaching the depth limit, 0.21% of the energy at depth 256, 0.03% at 4000; deeper paths
    // would run into lavapipe's loop limit). At depth 256 this render loses 0.23%; the bound
    // adds 4 Poisson standard deviations of the ~80 trapped samples (+44%). What is no longer
    // lost are the silhouette kills (0.69% before, which fails this bound).
    rs.maxDepth = 256;
    img = furnace(glass(1.5f));
    double sum = 0.0;
    for (size_t i = 0; i < img.pixels.size(); i += 3) sum += img.pixels[i];
    double mean = sum / double(img.pixels.size() / 3);
    EXPECT_NEAR(mean, 1.0, 3.3e-3);
    std::printf("low-poly glass furnace: image mean %.5f\n", mean);
    EXPECT_LE(mean, 1.0 + 1e-5);
}

// KHR_materials_volume absent: a thin-walled pane. Seen through a pane tilted 40°, a small
// emitter stays exactly where it is (a refracting surface would shift it), dimmed by the pane's
// slab transmittance 1 − 2F/(1 + F); and a thin-walled glass sphere in the white furnace is 1.
TEST_F(IntegratorTest, ThinWalledPaneDoesNotShiftWhatIsBehindIt) {
    const float le = 4.0f;
    Scene s;
    addQuad(s, {0, 0, -2}, {0.4f, 0, 0}, {0, 0.4f, 0}, addMaterial(s, emitter(glm::vec3(le))));
    s.cameras.push_back(lookAt({0, 0, 3}, {0, 0, 0}, {0, 1, 0}, radians(20)));
    RenderSettings rs = renderSettings(32, 32, 8);
    ImageF bare = render(s, rs, 64);
    Material pane = glass(1.5f);
    pane.thinWalled = true;
    const glm::vec3 paneNormal(std::sin(radians(40)), 0.0f, std::cos(radians(40)));
    addQuad(s, {0, 0, 0}, glm::vec3(std::cos(radians(40)), 0, -std::sin(radians(40))) * 3.0f,
            {0, 3, 0}, addMaterial(s, pane));
    Estimate e = estimate(s, rs, 16, kRuns);
    const Camera& cam = s.cameras[0];
    int covered = 0, uncovered = 0;
    double worstT = 0.0;
    for (uint32_t y = 0; y < rs.height; ++y) {
        for (uint32_t x = 0; x < rs.width; ++x) {
            size_t i = (size_t(y) * rs.width + x) * 3;
            float b = bare.pixels[i];
            double got = e.mean.pixels[i];
            if (b == 0.0f) {
                // Not a single sample of the bare render saw the emitter here; through the pane
                // none may either (a shifted image would light these pixels).
                ++uncovered;
                EXPECT_EQ(got, 0.0) << "pixel " << x << "," << y;
            } else if (b == le) {
                ++covered;
                double expected =
                    le * pixelAverage(x, y, 4, [&](float px, float py) {
                        float c = std::abs(glm::dot(
                            cameraDirection(cam, rs.width, rs.height, px, py), paneNormal));
                        float f = previs::shader::fresnelDielectric(c, 1.5f);
                        return 1.0 - 2.0 * f / (1.0 + f);
                    });
                worstT =
                    std::max(worstT, std::abs(got - expected) / std::sqrt(e.varianceOfMean[i]));
            }
        }
    }
    EXPECT_GT(covered, 20);
    EXPECT_GT(uncovered, 500);
    EXPECT_LT(worstT, kPixelT);

    Scene furnace;
    addSphere(furnace, glm::vec3(0.0f), 1.0f, addMaterial(furnace, pane));
    furnace.environment = uniformEnvironment(glm::vec3(1.0f));
    furnace.cameras.push_back(lookAt({0, 0, 4}, {0, 0, 0}, {0, 1, 0}, radians(40)));
    rs.width = rs.height = 24;
    rs.maxDepth = 256;
    ImageF img = render(furnace, rs, 8);
    for (float v : img.pixels) ASSERT_NEAR(v, 1.0f, 1e-5f);
}

// KHR_materials_volume with attenuation: a solid glass slab 0.5 m thick in the white furnace.
// A ray at angle θ enters with 1 − R, crosses with a = exp(−σ d / cos θt) per pass and leaves
// either face with 1 − R, bouncing with R in between: R + (1 − R)² a / (1 − R a). The clear
// channel (σ = 0) is exactly 1.
TEST_F(IntegratorTest, AbsorbingSlabFollowsBeerLambert) {
    Material slab = glass(1.5f);
    slab.attenuationColor = glm::vec3(0.5f, 0.8f, 1.0f);
    slab.attenuationDistanceM = 0.5f;
    const float thicknessM = 0.5f;
    Scene s;
    addBox(s, {-20, -20, -0.5f * thicknessM}, {20, 20, 0.5f * thicknessM}, addMaterial(s, slab));
    s.environment = uniformEnvironment(glm::vec3(1.0f));
    s.cameras.push_back(lookAt({0, 0, 3}, {0, 0, 0}, {0, 1, 0}, radians(20)));
    RenderSettings rs = renderSettings(16, 16, 256);
    Estimate e = estimate(s, rs, 16, kRuns);
    const Camera& cam = s.cameras[0];
    double worstT = 0.0;
    for (uint32_t y = 0; y < rs.height; ++y) {
        for (uint32_t x = 0; x < rs.width; ++x) {
            for (int c = 0; c < 3; ++c) {
                double sigma =
                    -std::log(double(slab.attenuationColor[c])) / slab.attenuationDistanceM;
                double expected = pixelAverage(x, y, 4, [&](float px, float py) {
                    double cosI = std::abs(cameraDirection(cam, rs.width, rs.height, px, py).z);
                    double r = previs::shader::fresnelDielectric(float(cosI), 1.5f);
                    double sinT = std::sqrt(1.0 - cosI * cosI) / 1.5;
                    double a = std::exp(-sigma * thicknessM / std::sqrt(1.0 - sinT * sinT));
                    return r + (1.0 - r) * (1.0 - r) * a / (1.0 - r * a);
                });
                size_t i = (size_t(y) * rs.width + x) * 3 + c;
                double got = e.mean.pixels[i];
                // The clear channel's samples are 1 to rounding, not bit for bit (the split at
                // the glass adds F and 1 − F): its variance is rounding's, so the difference
                // beyond the noise-free pixels' 1e-5 is what the t statistic judges.
                double beyondRounding = std::max(0.0, std::abs(got - expected) - 1e-5);
                if (e.varianceOfMean[i] > 0.0)
                    worstT = std::max(worstT, beyondRounding / std::sqrt(e.varianceOfMean[i]));
                else
                    EXPECT_NEAR(got, expected, 1e-5) << "noise-free pixel " << x << "," << y;
                if (c == 2) {
                    EXPECT_NEAR(got, 1.0, 2e-4);
                }
                if (x == 8 && y == 8) {
                    std::printf("slab channel %d: %.5f expected %.5f\n", c, got, expected);
                }
            }
        }
    }
    EXPECT_LT(worstT, kPixelT);
}

// llvmpipe ends all of an invocation's loops after 65535 iterations of them together
// (render/renderer.cpp): a long dispatch silently loses bounces, traversal steps and samples.
// The same samples (the sequence depends on the sample index only) rendered one per dispatch
// are the reference: sized dispatches must agree with it to rounding; on a CPU device, turning
// the sizing off reproduces the loss the guard exists for.
TEST_F(IntegratorTest, DispatchesStayInsideTheCpuDeviceLoopLimit) {
    Scene s = furnaceScene(mirror());
    RenderSettings rs = renderSettings(16, 16, 64);
    // The environment and the mirror would run photons, one sample a dispatch.
    rs.photons.mode = PhotonMode::Off;
    const uint32_t spp = 1024;
    auto renderWith = [&](uint32_t perDispatch, bool respectLimit) {
        RenderSettings settings = rs;
        settings.samplesPerDispatch = perDispatch;
        auto r = Renderer::create(ctx(), s, settings, {}, {.respectCpuLoopLimit = respectLimit});
        EXPECT_TRUE(r.ok()) << r.message();
        EXPECT_TRUE((*r)->render(spp).ok());
        return std::move(*r);
    };
    auto worstDifference = [](const Renderer& a, const Renderer& b) {
        Result<ImageF> x = a.image(Aov::Mixed);
        Result<ImageF> y = b.image(Aov::Mixed);
        EXPECT_TRUE(x.ok() && y.ok());
        float worst = 0.0f;
        for (size_t i = 0; i < x->pixels.size(); ++i)
            worst = std::max(worst, std::abs(x->pixels[i] - y->pixels[i]));
        return worst;
    };
    auto reference = renderWith(1, true);
    auto sized = renderWith(1024, true);
    // Only the summation order differs (compensated sums of values near 1).
    EXPECT_LT(worstDifference(*sized, *reference), 1e-6f);
    EXPECT_EQ(sized->diagnostics().loopLimitRisks(), 0u);
    RecordProperty("loopIterationsPerSample",
                   std::to_string(sized->diagnostics().loopIterationsPerSample()));
    if (!ctx().isCpuDevice()) GTEST_SKIP() << "the loop limit is llvmpipe's";

    auto unsized = renderWith(1024, false);
    const float lost = worstDifference(*unsized, *reference);
    // A cut dispatch loses whole samples (the sample loop ends early) and cuts paths short.
    // Lost samples do not darken the pixel (its mean is over the samples that reached the
    // accumulation, Aov::SampleCount), so the loss shows as missing samples.
    Result<ImageF> counts = unsized->image(Aov::SampleCount);
    ASSERT_TRUE(counts.ok());
    const float fewest = *std::min_element(counts->pixels.begin(), counts->pixels.end());
    std::printf(
        "%.0f loop iterations per sample; unsized 1024-sample dispatches: worst error "
        "%.3g, fewest samples in a pixel %.0f of %u\n",
        sized->diagnostics().loopIterationsPerSample(), lost, fewest, spp);
    EXPECT_LT(fewest, float(spp)) << "llvmpipe no longer cuts long loops? (then the guard can go)";
    EXPECT_GT(unsized->diagnostics().loopLimitRisks(), 0u);
    Result<ImageF> sizedCounts = sized->image(Aov::SampleCount);
    ASSERT_TRUE(sizedCounts.ok());
    for (float n : sizedCounts->pixels) ASSERT_EQ(n, float(spp));
}

// A Lambertian plane (albedo ρ) under a point light of intensity I at height h:
// L = ρ/π · I cosθ / d² = ρ I h / (π d³) (inverse-square cosine law).
// previsd's start says "compiling pipelines: N/M" from Renderer::create's progress: the total
// before the first compile, then one step per pipeline up to it. A mirror lit by a point light
// with photons on and the denoiser compiles trace_paths, the 7 photon passes and the
// denoiser's 4 stages.
TEST_F(IntegratorTest, CreateCountsItsPipelinesUpToATotalKnownFirst) {
    Scene s;
    addSphere(s, glm::vec3(0.0f), 1.0f, addMaterial(s, mirror()));
    s.lights.push_back(pointLight({0.0f, 3.0f, 0.0f}, 1.0f));
    s.cameras.push_back(lookAt({0, 0, 4}, {0, 0, 0}, {0, 1, 0}, radians(40)));
    RenderSettings rs;
    rs.width = rs.height = 16;
    rs.photons.mode = PhotonMode::On;
    rs.denoise = true;
    std::vector<std::pair<size_t, size_t>> heard;
    auto r = Renderer::create(
        ctx(), s, rs, [&heard](size_t done, size_t total) { heard.emplace_back(done, total); });
    ASSERT_TRUE(r) << r.message();
    ASSERT_EQ(heard.size(), 13u);
    for (size_t i = 0; i < heard.size(); ++i)
        EXPECT_EQ(heard[i], std::pair(i, size_t(12))) << "call " << i;
    EXPECT_TRUE((*r)->photonsActive());
}

TEST_F(IntegratorTest, PointLightFollowsInverseSquareCosineLaw) {
    const float h = 1.0f, intensity = 10.0f, rho = 0.75f;
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 50}, {50, 0, 0}, addMaterial(s, lambert(glm::vec3(rho))));
    const PunctualLight light = pointLight({0.0f, h, 0.0f}, intensity);
    s.lights.push_back(light);
    s.cameras.push_back(lookAt({0.3f, 3, 0.2f}, {0.3f, 0, 0}, {0, 0, -1}, radians(70)));
    RenderSettings rs = renderSettings(32, 32, 1);
    Estimate e = estimate(s, rs, 8, kRuns);
    // The pixel-jitter noise, plus 1e-4 relative for float arithmetic and the quadrature of the
    // expected pixel average.
    const ClosedFormCheck check =
        expectClosedForm(e, rs, 8, 1e-4, [&](float px, float py) -> std::optional<double> {
            const std::optional<glm::vec3> p = floorHit(s.cameras[0], rs, px, py);
            if (!p) return std::nullopt;
            const float dist = glm::length(light.position - *p);
            return double(rho) * intensity * h / (kPi * dist * dist * dist);
        });
    EXPECT_EQ(check.tested, int(rs.width * rs.height));
    RecordProperty("worstRelativeError", std::to_string(check.worstRelative));
}

// A Lambertian plane under a spherical emitter of radius R and radiance Le whose centre is at
// distance d and angle θ from the normal (sphere above the horizon): E = π Le (R/d)² cosθ, so
// L = ρ Le (R/d)² cosθ.
TEST_F(IntegratorTest, EmissiveSphereGivesClosedFormIrradiance) {
    const float radius = 0.5f, le = 4.0f, rho = 0.9f;
    const glm::vec3 center(0.0f, 2.0f, 0.0f);
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 50}, {50, 0, 0}, addMaterial(s, lambert(glm::vec3(rho))));
    addSphere(s, center, radius, addMaterial(s, emitter(glm::vec3(le))), false, 96, 192);
    s.cameras.push_back(lookAt({0, 1.2f, 3}, {0, 0, 0}, {0, 1, 0}, radians(50)));
    RenderSettings rs = renderSettings(24, 24, 1);
    Estimate e = estimate(s, rs, 32, kRuns);
    // The measured noise, plus 1% for the tessellated sphere (96×192 facets have a projected
    // area about 0.05% below the true sphere; margin for the quadrature).
    const ClosedFormCheck check =
        expectClosedForm(e, rs, 6, 0.01, [&](float px, float py) -> std::optional<double> {
            const std::optional<glm::vec3> p = floorHit(s.cameras[0], rs, px, py);
            if (!p) return std::nullopt;
            const glm::vec3 toC = center - *p;
            const float dist = glm::length(toC);
            const float cosT = toC.y / dist;
            // Only where the whole sphere is above the horizon and the camera ray does not pass
            // near the sphere.
            if (std::acos(cosT) + std::asin(radius / dist) > 0.5f * kPi) return std::nullopt;
            return double(rho) * le * (radius / dist) * (radius / dist) * cosT;
        });
    EXPECT_GT(check.tested, 200);
}

// The scene of the convergence tests: a small area light over a floor and a sphere, a dim sky.
Scene convergenceScene() {
    Scene s;
    uint32_t white = addMaterial(s, lambert(glm::vec3(0.7f)));
    addQuad(s, {0, 0, 0}, {0, 0, 3}, {3, 0, 0}, white);
    addSphere(s, {0, 0.4f, 0}, 0.4f, addMaterial(s, lambert(glm::vec3(0.8f, 0.3f, 0.2f))), false,
              16, 32);
    addQuad(s, {0, 1.5f, 0}, {0.3f, 0, 0}, {0, 0, 0.3f}, addMaterial(s, emitter(glm::vec3(8))));
    s.environment = uniformEnvironment(glm::vec3(0.2f));
    s.cameras.push_back(lookAt({0, 1, 2.5f}, {0, 0.3f, 0}, {0, 1, 0}, radians(45)));
    return s;
}

RenderSettings convergenceSettings(Sampler sampler) {
    RenderSettings rs = renderSettings(12, 12, 4);
    rs.samplesPerDispatch = 256;
    rs.sampler = sampler;
    return rs;
}

// The renderer's image after `spp` samples of a fresh accumulation with `seed`.
ImageF renderWithSeed(Renderer& r, uint32_t seed, uint32_t spp) {
    EXPECT_TRUE(r.reset().ok());
    r.setSeed(seed);
    EXPECT_TRUE(r.render(spp).ok());
    return r.image().value();
}

// The squared differences of every channel of every pixel, summed.
double sumSquaredError(const ImageF& img, const ImageF& reference) {
    double sum = 0.0;
    for (size_t i = 0; i < img.pixels.size(); ++i) {
        double d = img.pixels[i] - reference.pixels[i];
        sum += d * d;
    }
    return sum;
}

// Least-squares slope of y against x.
double slopeOf(const std::vector<double>& x, const std::vector<double>& y) {
    double mx = std::accumulate(x.begin(), x.end(), 0.0) / double(x.size());
    double my = std::accumulate(y.begin(), y.end(), 0.0) / double(y.size());
    double sxy = 0.0, sxx = 0.0;
    for (size_t i = 0; i < x.size(); ++i) {
        sxy += (x[i] - mx) * (y[i] - my);
        sxx += (x[i] - mx) * (x[i] - mx);
    }
    return sxy / sxx;
}

// With independent samples the error against a high-sample reference falls as 1/√spp: log-log
// slope −0.5 ± 0.05. A bias would flatten the slope as the noise falls below it.
TEST_F(IntegratorTest, ErrorFallsAsInverseSquareRootOfSamples) {
    Scene s = convergenceScene();
    RenderSettings rs = convergenceSettings(Sampler::Independent);
    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    Renderer& r = **renderer;
    // Reference noise adds σ²/16384 to each MSE: 1.6% at 256 spp, a slope change below 0.005.
    ImageF reference = renderWithSeed(r, 999, 16384);
    std::vector<double> logN, logErr;
    for (uint32_t spp : {4u, 16u, 64u, 256u}) {
        double mse = 0.0;
        const int runs = 4;
        for (int run = 0; run < runs; ++run)
            mse += sumSquaredError(renderWithSeed(r, uint32_t(run + 1), spp), reference);
        mse /= runs * double(reference.pixels.size());
        logN.push_back(std::log(double(spp)));
        logErr.push_back(0.5 * std::log(mse));
    }
    double slope = slopeOf(logN, logErr);
    RecordProperty("slope", std::to_string(slope));
    EXPECT_NEAR(slope, -0.5, 0.05);
}

// With Sobol' samples the error falls at least as fast as 1/√spp (stratification can only make
// it faster: about spp^−0.75 where the integrand is smooth in the stratified dimensions). Each
// of 8 seeds gives one log-log slope over 4-256 spp; their mean must not exceed −0.5 by more
// than 2.998 standard errors (Student's t, one-sided 1%, 7 degrees of freedom). A bias would
// flatten the slope toward 0 as the noise falls below it.
TEST_F(IntegratorTest, SobolErrorFallsAtLeastAsFastAsInverseSquareRoot) {
    Scene s = convergenceScene();
    auto renderer = Renderer::create(ctx(), s, convergenceSettings(Sampler::Sobol));
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    Renderer& r = **renderer;
    // Sobol's reference error at 16384 spp is below the independent one's, which the test
    // above bounds at a slope change below 0.005.
    ImageF reference = renderWithSeed(r, 999, 16384);
    const int runs = 8;
    std::vector<double> slopes;
    for (int run = 0; run < runs; ++run) {
        std::vector<double> logN, logErr;
        for (uint32_t spp : {4u, 16u, 64u, 256u}) {
            ImageF img = renderWithSeed(r, uint32_t(run + 1), spp);
            double mse = sumSquaredError(img, reference) / double(img.pixels.size());
            logN.push_back(std::log(double(spp)));
            logErr.push_back(0.5 * std::log(mse));
        }
        slopes.push_back(slopeOf(logN, logErr));
    }
    double mean = std::accumulate(slopes.begin(), slopes.end(), 0.0) / runs;
    double ss = 0.0;
    for (double v : slopes) ss += (v - mean) * (v - mean);
    double stdErr = std::sqrt(ss / (runs - 1) / runs);
    RecordProperty("slope", std::to_string(mean));
    RecordProperty("slopeStdErr", std::to_string(stdErr));
    EXPECT_LE(mean, -0.5 + 2.998 * stdErr);
}

// Accumulation stays exact over a million samples per pixel (compensated sums), where the paper's
// running average (Eq. 3) in 32-bit floats drifts.
TEST_F(IntegratorTest, MillionSampleAccumulationIsExact) {
    const float value = 0.1f;
    Scene s;
    s.environment = uniformEnvironment(glm::vec3(value));
    s.cameras.push_back(lookAt({0, 0, 0}, {0, 0, -1}, {0, 1, 0}, radians(60)));
    RenderSettings rs;
    // Two pixels: the cost is the sample count (one SIMD batch on a CPU device).
    rs.width = 2;
    rs.height = 1;
    rs.samplesPerDispatch = 1024;
    const uint32_t spp = 1u << 20;
    ImageF img = render(s, rs, spp);
    for (float v : img.pixels) ASSERT_NEAR(v, value, 2e-7f * value);

    // What Eq. 3 would give, L_acc = ((n−1)·L_acc + L)/n in float, for the same samples.
    float acc = 0.0f;
    for (uint32_t n = 1; n <= spp; ++n) acc = (float(n - 1) * acc + value) / float(n);
    RecordProperty("runningAverageRelativeError", std::to_string(std::abs(acc - value) / value));
    EXPECT_GT(std::abs(acc - value) / value, 1e-5f) << "the naive average no longer drifts?";
}

// Self-intersection: a plane under a directional light at 45° has the same radiance everywhere,
// at any scale; acne would show as dark pixels. Light leaks: inside a closed box lit from
// outside, everything is black.
TEST_F(IntegratorTest, NoAcneOrLeaksFromMillimetreToKilometre) {
    for (float scale : {1e-3f, 1.0f, 1e3f}) {
        const float rho = 0.5f, lux = 2.0f;
        Scene s;
        addQuad(s, {0, 0, 0}, {0, 0, 100 * scale}, {100 * scale, 0, 0},
                addMaterial(s, lambert(glm::vec3(rho))));
        // A sliver and a zero-area triangle nearby must not disturb anything either.
        addMesh(s,
                {{0, 0.1f * scale, 0},
                 {10 * scale, 0.1f * scale, 1e-6f * scale},
                 {20 * scale, 0.1f * scale, 0}},
                {{0, 1, 0}, {0, 1, 0}, {0, 1, 0}}, {{0, 1, 2}, {0, 0, 1}}, 0, false);
        PunctualLight sun;
        sun.type = LightType::Directional;
        sun.direction = glm::normalize(glm::vec3(1, -1, 0));
        sun.intensity = lux;
        s.lights.push_back(sun);
        s.cameras.push_back(lookAt(glm::vec3(0, 2, 3) * scale, glm::vec3(0, 0, -1) * scale,
                                   {0, 1, 0}, radians(30)));
        RenderSettings rs = renderSettings(32, 32, 1);
        ImageF img = render(s, rs, 2);
        const float expected = rho / kPi * lux * std::sqrt(0.5f);
        for (uint32_t y = 0; y < rs.height; ++y)
            for (uint32_t x = 0; x < rs.width; ++x)
                ASSERT_NEAR(pixel(img, x, y), expected, 1e-5f * expected)
                    << "scale " << scale << " pixel " << x << "," << y;

        Scene box;
        addBox(box, glm::vec3(-1) * scale, glm::vec3(1) * scale,
               addMaterial(box, lambert(glm::vec3(0.8f))), false, true);
        box.lights = s.lights;
        box.environment = uniformEnvironment(glm::vec3(1.0f));
        box.cameras.push_back(lookAt(glm::vec3(0.2f, 0.1f, 0.3f) * scale,
                                     glm::vec3(1, -1, -1) * scale, {0, 1, 0}, radians(90)));
        rs.maxDepth = 8;
        ImageF inside = render(box, rs, 8);
        for (float v : inside.pixels) ASSERT_EQ(v, 0.0f) << "light leaked in at scale " << scale;
    }
}

// An environment with a 1e5-radiance sun: a Lambertian plane (albedo 1, direct light only)
// reflects L = E/π with E = Σ L_texel ∫_texel cosθ dω, exact for nearest-texel lookup because
// the map's rows are circles of constant θ around the plane's normal (+Y).
TEST_F(IntegratorTest, EnvironmentWithIntenseSunMatchesIrradianceSum) {
    const uint32_t w = 64, hgt = 32;
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 1000}, {1000, 0, 0}, addMaterial(s, lambert(glm::vec3(1.0f))));
    EnvironmentMap env = uniformEnvironment(glm::vec3(0.5f), w, hgt);
    env.radiance[size_t(8) * w + 40] = glm::vec3(1e5f);  // a 1-texel sun 33.75° up
    s.environment = env;
    s.cameras.push_back(lookAt({0, 1, 0}, {0, 0, -1}, {0, 1, 0}, radians(60)));
    RenderSettings rs = renderSettings(16, 16, 1);
    Estimate e = estimate(s, rs, 16, kRuns);
    double irradiance = 0.0;
    for (uint32_t row = 0; row < hgt / 2; ++row) {
        double t0 = kPi * row / hgt, t1 = kPi * (row + 1) / hgt;
        double band =
            (2.0 * kPi / w) * 0.5 * (std::sin(t1) * std::sin(t1) - std::sin(t0) * std::sin(t0));
        for (uint32_t col = 0; col < w; ++col) irradiance += env.radiance[row * w + col].x * band;
    }
    double expected = irradiance / kPi;
    double sum = 0.0, var = 0.0;
    size_t n = size_t(rs.width) * rs.height;
    for (size_t i = 0; i < n; ++i) {
        sum += e.mean.pixels[i * 3];
        var += e.varianceOfMean[i * 3];
    }
    double stdErr = std::sqrt(var) / n;
    EXPECT_NEAR(sum / n, expected, 4.0 * stdErr + 1e-5 * expected) << "standard error " << stdErr;
}

// Grazing and exactly tangent camera rays over a plane produce no NaN (the fixture checks every
// sample and pixel) and see the plane or the sky, nothing in between.
TEST_F(IntegratorTest, TangentRaysStayFinite) {
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 10}, {10, 0, 0}, addMaterial(s, lambert(glm::vec3(0.5f))));
    addSphere(s, {0, 0.5f, -3}, 0.5f, addMaterial(s, mirror()));
    s.environment = uniformEnvironment(glm::vec3(1.0f));
    s.cameras.push_back(lookAt({0, 0, 5}, {0, 0, -5}, {0, 1, 0}, radians(30)));
    RenderSettings rs = renderSettings(16, 16, 8);
    render(s, rs, 16);
}

// The specialised pipeline runs less code and gives the same image as the general one (same
// random sequence; differences only from float rounding).
TEST_F(IntegratorTest, SpecialisedPipelineMatchesGeneral) {
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 2}, {2, 0, 0}, addMaterial(s, lambert(glm::vec3(0.6f))));
    addSphere(s, {0, 0.3f, 0}, 0.3f, addMaterial(s, lambert(glm::vec3(0.2f, 0.5f, 0.8f))));
    s.lights.push_back(pointLight({1, 2, 1}, 5.0f));
    s.cameras.push_back(lookAt({0, 1, 2}, {0, 0.2f, 0}, {0, 1, 0}, radians(45)));
    RenderSettings rs = renderSettings(16, 16, 6);
    auto specialised = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(specialised.ok());
    SceneFeatures f = (*specialised)->features();
    EXPECT_FALSE(f.environment || f.emissive || f.specular || f.transmission || f.thinLens ||
                 f.textures);
    EXPECT_TRUE(f.punctual);
    ImageF a = render(s, rs, 16);
    ImageF b = render(s, rs, 16, {.generalPipeline = true});
    for (size_t i = 0; i < a.pixels.size(); ++i)
        ASSERT_NEAR(a.pixels[i], b.pixels[i], 1e-4f * std::max(1.0f, a.pixels[i]));
}

}  // namespace
}  // namespace previs::testing
