// Lighting fitted to the plate (render/lighting_fit.h): a Lambertian floor with a box on it
// under a sky and a lamp whose captured radiance clipped 50× low. The "plate" and the box's
// "L_or" are computed here independently of the fit — every texel of the full map with its own
// shadow ray — so the test checks the fit's model (coarse map, a cluster's brightest texels)
// as well as its solver.

#include "render/lighting_fit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "render/cpu_tracer.h"

namespace previs {
namespace {

constexpr int kMapW = 64, kMapH = 32;
constexpr float kAlbedo = 0.5f;

// Quads as two triangles each, all real.
void addQuad(Geometry& g, glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) {
    const uint32_t base = uint32_t(g.positions.size());
    for (const glm::vec3& p : {a, b, c, d}) {
        g.positions.push_back(p);
        g.normals.push_back(glm::normalize(glm::cross(b - a, d - a)));
        g.uvs.emplace_back(0.0f);
    }
    g.triangles.emplace_back(base, base + 1, base + 2);
    g.triangles.emplace_back(base, base + 2, base + 3);
    g.triangleMaterials.insert(g.triangleMaterials.end(), 2, 0);
    g.triangleIsReal.insert(g.triangleIsReal.end(), 2, 1);
}

// A 4 m floor and a 0.4 m box standing on it at the origin.
Geometry set() {
    Geometry g;
    addQuad(g, {-2, 0, -2}, {-2, 0, 2}, {2, 0, 2}, {2, 0, -2});
    const float s = 0.2f, h = 0.4f;
    addQuad(g, {-s, h, -s}, {-s, h, s}, {s, h, s}, {s, h, -s});    // top
    addQuad(g, {-s, 0, s}, {s, 0, s}, {s, h, s}, {-s, h, s});      // +z
    addQuad(g, {s, 0, -s}, {-s, 0, -s}, {-s, h, -s}, {s, h, -s});  // −z
    addQuad(g, {s, 0, s}, {s, 0, -s}, {s, h, -s}, {s, h, s});      // +x
    addQuad(g, {-s, 0, -s}, {-s, 0, s}, {-s, h, s}, {-s, h, -s});  // −x
    return g;
}

glm::vec3 direction(int x, int y) {
    const double phi = ((x + 0.5) / kMapW - 0.5) * 2.0 * M_PI;
    const double lat = (0.5 - (y + 0.5) / kMapH) * M_PI;
    return glm::vec3(std::cos(lat) * std::cos(phi), std::sin(lat), std::cos(lat) * std::sin(phi));
}

double solidAngle(int y) {
    return 2.0 * M_PI / kMapW * (std::cos(M_PI * y / kMapH) - std::cos(M_PI * (y + 1) / kMapH));
}

// A dim blue-grey sky and a warm lamp 40° up (3×2 texels).
cv::Mat sky(float lamp) {
    cv::Mat m(kMapH, kMapW, CV_32FC3, cv::Scalar(0.35, 0.4, 0.5));
    for (int y = 10; y < 12; ++y)
        for (int x = 20; x < 23; ++x)
            m.at<cv::Vec3f>(y, x) = cv::Vec3f(lamp, 0.9f * lamp, 0.8f * lamp);
    return m;
}

// Lambertian radiance: albedo/π × ∫ L cos V dω over every texel (the reference integration).
glm::vec3 radiance(const CpuTracer& tracer, const cv::Mat& map, glm::vec3 p, glm::vec3 n) {
    glm::dvec3 e(0.0);
    for (int y = 0; y < kMapH; ++y)
        for (int x = 0; x < kMapW; ++x) {
            const glm::vec3 d = direction(x, y);
            const float c = glm::dot(n, d);
            if (c <= 0.0f) continue;
            shader::Ray ray{p + 1e-3f * n, 0.0f, d, 1e30f};
            if (tracer.occluded(ray, true)) continue;
            const cv::Vec3f l = map.at<cv::Vec3f>(y, x);
            e += glm::dvec3(l[0], l[1], l[2]) * (double(c) * solidAngle(y));
        }
    return glm::vec3(e * double(kAlbedo / M_PI));
}

struct Case {
    std::vector<PlateSample> samples;
    cv::Mat captured;
    std::vector<std::vector<int>> clusters;
};

// Floor samples around the box (its top too), the plate lit by `truth` × plateGain with 2 %
// noise and 5 % of the samples specular outliers (3×), L_or by `captured`.
Case makeCase(const CpuTracer& tracer, const cv::Mat& truth, const cv::Mat& captured,
              glm::vec3 plateGain) {
    Case c;
    c.captured = captured;
    std::mt19937 rng(17);
    std::normal_distribution<float> noise(0.0f, 0.02f);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    for (int i = 0; i < 30; ++i)
        for (int j = 0; j < 30; ++j) {
            glm::vec3 p(-1.2f + 2.4f * i / 29.0f, 0.0f, -1.2f + 2.4f * j / 29.0f);
            glm::vec3 n(0, 1, 0);
            if (std::abs(p.x) < 0.2f && std::abs(p.z) < 0.2f) p.y = 0.4f;  // on the box's top
            PlateSample s;
            s.position = p;
            s.normal = n;
            s.real = radiance(tracer, captured, p, n);
            s.plate = plateGain * radiance(tracer, truth, p, n) * (1.0f + noise(rng));
            if (u(rng) < 0.05f) s.plate *= 3.0f;
            c.samples.push_back(s);
        }
    cv::Mat clipped = cv::Mat::zeros(captured.size(), CV_8U);
    for (int y = 10; y < 12; ++y)
        for (int x = 20; x < 23; ++x) clipped.at<uint8_t>(y, x) = 255;
    c.clusters = clippedClusters(clipped);
    return c;
}

TEST(LightingFit, RecoversAClippedLampFromLitAndShadowedFloor) {
    const Geometry g = set();
    auto tracer = CpuTracer::create(g);
    ASSERT_TRUE(tracer.ok()) << tracer.message();
    // The lamp's true radiance 800 was captured as 16 (an 8-bit fisheye's clip).
    const Case c = makeCase(*tracer, sky(800.0f), sky(16.0f), glm::vec3(1.0f));
    ASSERT_EQ(c.clusters.size(), 1u);
    EXPECT_EQ(c.clusters[0].size(), 6u);
    Result<LightingFit> fit = fitLightingToPlate(*tracer, c.captured, c.clusters, c.samples);
    ASSERT_TRUE(fit.ok()) << fit.message();
    std::printf("lamp gain %.2f (truth 50), global gain %.3f %.3f %.3f, residual %.3f -> %.3f\n",
                fit->clusterGains[0], fit->globalGain[0], fit->globalGain[1], fit->globalGain[2],
                fit->residualBefore, fit->residualAfter);
    // 900 samples with 2 % noise determine the gain to well under 1 %; the coarse 32×16 map for
    // the sky's share of irradiance errs by a few per cent of the sky's part, which is ~1/20 of
    // the total once the lamp is right: 5 % on the gain.
    EXPECT_NEAR(fit->clusterGains[0] / 50.0, 1.0, 0.05);
    for (double gain : fit->globalGain) EXPECT_NEAR(gain, 1.0, 0.03);
    // The plate's 2 % noise alone leaves a median |log residual| of 0.0135 (0.674 σ).
    EXPECT_LT(fit->residualAfter, 0.02);
    EXPECT_GT(fit->residualBefore, 1.0);  // 50× too dim a lamp: log residual ≫ 1

    // The fitted map lights the floor as the truth does.
    const LightingCorrection correction = correctionFromFit(c.captured, c.clusters, *fit);
    size_t unmatched = 99;
    const cv::Mat fitted = applyCorrection(c.captured, c.clusters, correction, &unmatched);
    EXPECT_EQ(unmatched, 0u);
    const glm::vec3 lit = radiance(*tracer, fitted, {1.0f, 0.0f, 0.5f}, {0, 1, 0});
    const glm::vec3 truthLit = radiance(*tracer, sky(800.0f), {1.0f, 0.0f, 0.5f}, {0, 1, 0});
    EXPECT_NEAR(lit.g / truthLit.g, 1.0, 0.05);
}

TEST(LightingFit, AGlobalGainWithNothingClipped) {
    const Geometry g = set();
    auto tracer = CpuTracer::create(g);
    ASSERT_TRUE(tracer.ok());
    // A plate 1.5× brighter in red, 1.2× in green, 0.9× in blue than the box renders: a
    // white-balance or exposure error, no clipped light.
    Case c = makeCase(*tracer, sky(16.0f), sky(16.0f), glm::vec3(1.5f, 1.2f, 0.9f));
    Result<LightingFit> fit = fitLightingToPlate(*tracer, c.captured, {}, c.samples);
    ASSERT_TRUE(fit.ok()) << fit.message();
    EXPECT_NEAR(fit->globalGain[0], 1.5, 0.02);
    EXPECT_NEAR(fit->globalGain[1], 1.2, 0.02);
    EXPECT_NEAR(fit->globalGain[2], 0.9, 0.02);
}

TEST(LightingFit, TooFewSamplesOrNoImprovementFail) {
    const Geometry g = set();
    auto tracer = CpuTracer::create(g);
    ASSERT_TRUE(tracer.ok());
    Case c = makeCase(*tracer, sky(800.0f), sky(16.0f), glm::vec3(1.0f));
    c.samples.resize(20);
    EXPECT_FALSE(fitLightingToPlate(*tracer, c.captured, c.clusters, c.samples).ok());
    // Non-finite and black samples are not used.
    c.samples.assign(100, PlateSample{});
    EXPECT_FALSE(fitLightingToPlate(*tracer, c.captured, c.clusters, c.samples).ok());
}

// A later snapshot's lamp, found anew with one more texel (its direction 2.8° off: a texel here is
// 5.6°), takes the fitted gain; a lamp elsewhere does not (it waits for its own fit).
TEST(LightingFit, ACorrectionCarriesOverByDirection) {
    const cv::Mat captured = sky(16.0f);
    LightingCorrection correction;
    correction.clusters.push_back({clusterDirection(captured, {10 * kMapW + 20}), 50.0});
    cv::Mat later = sky(16.0f);
    later.at<cv::Vec3f>(25, 50) = cv::Vec3f(16.0f, 16.0f, 16.0f);
    const std::vector<std::vector<int>> clusters{{10 * kMapW + 20, 10 * kMapW + 21},
                                                 {25 * kMapW + 50}};
    size_t unmatched = 0;
    const cv::Mat corrected = applyCorrection(later, clusters, correction, &unmatched);
    EXPECT_EQ(unmatched, 1u);
    EXPECT_FLOAT_EQ(corrected.at<cv::Vec3f>(10, 21)[0], 800.0f);
    EXPECT_FLOAT_EQ(corrected.at<cv::Vec3f>(25, 50)[0], 16.0f);
    EXPECT_FLOAT_EQ(corrected.at<cv::Vec3f>(0, 0)[2], 0.5f);
}

// Rays from a camera above the floor find the floor and the box's top with normals facing up.
TEST(LightingFit, RaysFindTheRealSurfaces) {
    const Geometry g = set();
    auto tracer = CpuTracer::create(g);
    ASSERT_TRUE(tracer.ok());
    const glm::vec3 eye(0.0f, 2.0f, 0.0f);
    const auto hits = realSurfacesAlongRays(
        *tracer, eye,
        {glm::normalize(glm::vec3(1, -1, 0)), glm::vec3(0, -1, 0), glm::vec3(0, 1, 0)});
    ASSERT_TRUE(hits[0] && hits[1]);
    EXPECT_FALSE(hits[2]);
    EXPECT_NEAR(hits[0]->position.y, 0.0f, 1e-4f);
    EXPECT_NEAR(hits[0]->position.x, 2.0f, 1e-4f);
    EXPECT_NEAR(hits[1]->position.y, 0.4f, 1e-4f);
    EXPECT_NEAR(hits[1]->normal.y, 1.0f, 1e-5f);
}

TEST(LightingFit, ClustersJoinAcrossTheSeam) {
    cv::Mat clipped = cv::Mat::zeros(kMapH, kMapW, CV_8U);
    clipped.at<uint8_t>(5, 0) = 255;
    clipped.at<uint8_t>(5, kMapW - 1) = 255;
    clipped.at<uint8_t>(20, 30) = 255;
    const auto clusters = clippedClusters(clipped);
    ASSERT_EQ(clusters.size(), 2u);
    EXPECT_TRUE(clippedClusters(cv::Mat::zeros(kMapH, kMapW, CV_8U)).empty());
}

}  // namespace
}  // namespace previs
