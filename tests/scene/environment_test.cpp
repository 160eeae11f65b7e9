// Environment maps: loading real maps (checked against envmap_stats.json), and the shared
// sampling math of gpu/shaders/shared/env_sampling.h run on the CPU: uv <-> direction round trip,
// the pdf integrating to 1, chi-square goodness of fit of envSample against envPdf (pbrt-v4
// sampling_test.cpp style), rotation consistency and robustness at the poles.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "image/image.h"
#include "scene/environment_map.h"
#include "scene/environment_sampler.h"
#include "tests/support/chi2.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

const std::string kEnvDir = testing::sharedDataDir() + "envmaps/";

// Two chi-square tests (real map, synthetic sun map) share the 1% family-wise significance.
constexpr int kChiSquareTests = 2;
constexpr double kSignificance = 0.01;

EnvironmentMap loadOrDie(const std::string& relative) {
    Result<EnvironmentMap> map = loadEnvironmentMap(kEnvDir + relative);
    EXPECT_TRUE(map.ok()) << map.message();
    return map.ok() ? std::move(map).value() : EnvironmentMap{};
}

// Solid-angle weighted mean exactly as envmap_stats.json defines it.
glm::dvec3 weightedMean(const EnvironmentMap& map) {
    glm::dvec3 sum(0.0);
    double weight = 0.0;
    for (uint32_t y = 0; y < map.height; ++y) {
        const double s = std::sin(M_PI * (y + 0.5) / map.height);
        for (uint32_t x = 0; x < map.width; ++x) {
            sum += glm::dvec3(map.radiance[size_t(y) * map.width + x]) * s;
            weight += s;
        }
    }
    return sum / weight;
}

TEST(EnvironmentMap, RealMapsMatchStats) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    std::ifstream f(kEnvDir + "envmap_stats.json");
    ASSERT_TRUE(f) << "missing " << kEnvDir << "envmap_stats.json";
    const nlohmann::json stats = nlohmann::json::parse(f);
    for (const char* name :
         {"blender_studiolights_world/city.exr", "blender_studiolights_world/night.exr",
          "polyhaven_1k_hdr/studio_small_03_1k.hdr", "polyhaven_1k_hdr/rooitou_park_1k.hdr"}) {
        SCOPED_TRACE(name);
        const nlohmann::json& s = stats["maps"][name];
        EnvironmentMap map = loadOrDie(name);
        ASSERT_EQ(map.width, s["width"].get<uint32_t>());
        ASSERT_EQ(map.height, s["height"].get<uint32_t>());
        const glm::dvec3 mean = weightedMean(map);
        for (int c = 0; c < 3; ++c) {
            const double expected = s["solid_angle_weighted_mean_rgb"][c].get<double>();
            // Negative texels (DWAB ringing, ~1e-3) are clamped to 0 at load; the stats kept
            // them, so allow 0.5% relative.
            EXPECT_NEAR(mean[c], expected, 5e-3 * expected + 1e-4) << "channel " << c;
        }
        // Orientation and channel order: the brightest pixel is where the stats say.
        size_t best = 0;
        float bestLum = -1.0f;
        for (size_t i = 0; i < map.radiance.size(); ++i) {
            if (luminance(map.radiance[i]) > bestLum) {
                bestLum = luminance(map.radiance[i]);
                best = i;
            }
        }
        EXPECT_EQ(best % map.width, s["brightest_pixel_xy"][0].get<size_t>());
        EXPECT_EQ(best / map.width, s["brightest_pixel_xy"][1].get<size_t>());
        for (const glm::vec3& r : map.radiance)
            ASSERT_TRUE(r.r >= 0.0f && r.g >= 0.0f && r.b >= 0.0f &&
                        std::isfinite(r.r + r.g + r.b));
    }
}

// `--env studio`: generated, not read from a file (nothing to install or find); neutral grey, lit
// from above by its key softbox, valid for importance sampling.
TEST(EnvironmentMap, StudioIsBuiltInNeutralAndLitFromAbove) {
    Result<EnvironmentMap> map = loadEnvironmentMap(kStudioEnvironment);
    ASSERT_TRUE(map.ok()) << map.message();
    ASSERT_EQ(map->width, 2 * map->height);
    ASSERT_EQ(map->radiance.size(), size_t(map->width) * map->height);
    // Irradiance on a surface facing up and on one facing down, E = Σ L cosθ dω.
    double up = 0.0, down = 0.0;
    for (uint32_t y = 0; y < map->height; ++y) {
        const double elevation = (0.5 - (y + 0.5) / map->height) * M_PI;
        const double dOmega =
            (2.0 * M_PI / map->width) * (M_PI / map->height) * std::cos(elevation);
        for (uint32_t x = 0; x < map->width; ++x) {
            const glm::vec3 l = map->radiance[size_t(y) * map->width + x];
            ASSERT_TRUE(std::isfinite(l.r) && l.r >= 0.0f);
            ASSERT_EQ(l.r, l.g);  // colourless
            ASSERT_EQ(l.r, l.b);
            (elevation > 0.0 ? up : down) += l.r * std::abs(std::sin(elevation)) * dOmega;
        }
    }
    std::printf("studio: irradiance from above %.3f, from below %.3f\n", up, down);
    EXPECT_GT(up, 4.0 * down);
    // A white Lambertian surface facing up has radiance E/π: about 1, neither black nor blown out.
    EXPECT_GT(up / M_PI, 0.5);
    EXPECT_LT(up / M_PI, 3.0);
    // The key softbox sits 45° up toward u = 0.625 (azimuth +45°, DESIGN.md §4).
    const uint32_t keyX = uint32_t(0.625 * map->width);
    const uint32_t keyY = uint32_t(0.25 * map->height);
    EXPECT_EQ(map->radiance[size_t(keyY) * map->width + keyX].r, 8.0f);
    EXPECT_GT(buildEnvironmentDistribution(*map).integral, 0.0f);
}

TEST(EnvironmentMap, ErrorsNameTheFile) {
    Result<EnvironmentMap> missing = loadEnvironmentMap("/nonexistent/sky.exr");
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.message().find("sky.exr"), std::string::npos) << missing.message();
    Result<EnvironmentMap> ldr = loadEnvironmentMap("/nonexistent/sky.png");
    ASSERT_FALSE(ldr.ok());
    EXPECT_NE(ldr.message().find("sky.png"), std::string::npos) << ldr.message();
}

// A constant sky with a 2x2-texel sun of radiance 1e5: the sun carries ~97% of the weight.
EnvironmentMap sunMap(uint32_t w = 128, uint32_t h = 64) {
    EnvironmentMap map;
    map.width = w;
    map.height = h;
    map.radiance.assign(size_t(w) * h, glm::vec3(0.5f, 0.6f, 0.7f));
    for (uint32_t y = 20; y < 22; ++y)
        for (uint32_t x = 37; x < 39; ++x) map.radiance[size_t(y) * w + x] = glm::vec3(1e5f);
    // A black band and a black row: zero-probability regions must never be sampled.
    for (uint32_t x = 0; x < w; ++x) map.radiance[size_t(h * 25 / 32) * w + x] = glm::vec3(0.0f);
    for (uint32_t y = 0; y < h; ++y) map.radiance[size_t(y) * w + 5] = glm::vec3(0.0f);
    return map;
}

TEST(EnvironmentSampling, UvDirectionRoundTrip) {
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> uni(0.0f, 1.0f);
    double worst = 0.0;
    for (int i = 0; i < 100000; ++i) {
        const glm::vec2 uv(uni(rng), uni(rng) * 0.998f + 0.001f);
        const glm::vec3 d = EnvironmentSampler::uvToDirection(uv);
        EXPECT_NEAR(glm::length(d), 1.0f, 1e-5f);
        const glm::vec2 back = EnvironmentSampler::directionToUv(d);
        float du = std::abs(back.x - uv.x);
        du = std::min(du, 1.0f - du);  // u wraps
        worst = std::max({worst, double(du), double(std::abs(back.y - uv.y))});
    }
    EXPECT_LT(worst, 2e-5) << "uv -> direction -> uv";
    // DESIGN.md §4 anchors: +X at u = 0.5, +Z at u = 0.75, up at v = 0.
    const glm::vec2 px = EnvironmentSampler::directionToUv({1, 0, 0});
    EXPECT_FLOAT_EQ(px.x, 0.5f);
    EXPECT_FLOAT_EQ(px.y, 0.5f);
    EXPECT_FLOAT_EQ(EnvironmentSampler::directionToUv({0, 0, 1}).x, 0.75f);
    EXPECT_FLOAT_EQ(EnvironmentSampler::directionToUv({0, 1, 0}).y, 0.0f);
    EXPECT_FLOAT_EQ(EnvironmentSampler::directionToUv({0, -1, 0}).y, 1.0f);
}

// ∫ pdf dω over the sphere by the midpoint rule on a fine (θ, φ) grid not aligned with the
// texels; dω = sinθ dθ dφ keeps the integrand bounded at the poles (a grid in cosθ would meet the
// pdf's integrable 1/sinθ there and converge slowly).
double integratePdf(const EnvironmentSampler& sampler, int nTheta, int nPhi) {
    double sum = 0.0;
    for (int i = 0; i < nTheta; ++i) {
        const double theta = M_PI * (i + 0.5) / nTheta;
        const double sinTheta = std::sin(theta);
        for (int j = 0; j < nPhi; ++j) {
            const double phi = -M_PI + 2.0 * M_PI * (j + 0.5) / nPhi;
            const glm::vec3 d(sinTheta * std::cos(phi), std::cos(theta), sinTheta * std::sin(phi));
            sum += double(sampler.pdf(d)) * sinTheta;
        }
    }
    const double integral = sum * (M_PI / nTheta) * (2.0 * M_PI / nPhi);
    std::printf("integral of pdf = %.6f\n", integral);
    return integral;
}

// ∫ pdf dω with pieces aligned to the texels (unrotated map), `sub` × `sub` per texel: on each
// piece ∫ pdf dω = pdf(centre) · sinθ(centre) · Δθ · Δφ exactly, because the pdf is
// pdf_uv / (2π² sinθ) with pdf_uv constant on a texel. So this checks the lookup, the Jacobian
// and the normalisation up to float rounding.
double integratePdfAligned(const EnvironmentSampler& sampler, int sub) {
    const EnvironmentMap& map = sampler.map();
    const double dTheta = M_PI / (map.height * sub);
    const double dPhi = 2.0 * M_PI / (map.width * sub);
    double sum = 0.0;
    for (uint32_t i = 0; i < map.height * sub; ++i) {
        const double theta = (i + 0.5) * dTheta;
        for (uint32_t j = 0; j < map.width * sub; ++j) {
            const double phi = -M_PI + (j + 0.5) * dPhi;
            const glm::vec3 d(std::sin(theta) * std::cos(phi), std::cos(theta),
                              std::sin(theta) * std::sin(phi));
            sum += double(sampler.pdf(d)) * std::sin(theta);
        }
    }
    const double integral = sum * dTheta * dPhi;
    std::printf("integral of pdf (texel-aligned) = %.7f\n", integral);
    return integral;
}

TEST(EnvironmentSampling, PdfIntegratesToOne) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    // Texel-aligned quadrature is exact for this pdf: only float rounding of the CDFs (~1e-7
    // per entry) and of sinθ remains; 1e-4 is generous.
    EnvironmentSampler sun(sunMap());
    EXPECT_NEAR(integratePdfAligned(sun, 3), 1.0, 1e-4);
    EnvironmentSampler real(loadOrDie("polyhaven_1k_hdr/studio_small_03_1k.hdr"));
    EXPECT_NEAR(integratePdfAligned(real, 1), 1.0, 1e-4);

    // A grid not aligned with the texels checks the same independently of the texel layout,
    // at the cost of quadrature error from cells straddling texel edges: the sun's 4 texels
    // (97% of the mass) are each covered by ~19x19 grid points, so up to ~1/19 of their mass can
    // be misplaced (measured 2.7%): 6e-2. The uniform fallback is smooth: 2e-3.
    EXPECT_NEAR(integratePdf(sun, 1200, 2400), 1.0, 6e-2);
    EnvironmentMap black;
    black.width = 64;
    black.height = 32;
    black.radiance.assign(64 * 32, glm::vec3(0.0f));
    EnvironmentSampler uniform(black);
    EXPECT_EQ(uniform.distribution().integral, 0.0f);
    EXPECT_NEAR(integratePdf(uniform, 400, 800), 1.0, 2e-3);
    EXPECT_NEAR(integratePdfAligned(uniform, 4), 1.0, 1e-4);
    // Uniform fallback: pdf ≈ 1/(4π) at the equator.
    EXPECT_NEAR(uniform.pdf({1, 0, 0}), 1.0 / (4.0 * M_PI), 1e-3);
}

// Expected fraction of samples per (cosθ, φ) cell: cells are split at every texel edge, and on
// each piece ∫ pdf dω = pdf(centre) · sinθ(centre) · Δθ · Δφ exactly, because the pdf is
// pdf_uv / (2π² sinθ) with pdf_uv constant on a texel and dω = sinθ dθ dφ.
std::vector<double> expectedFractions(const EnvironmentSampler& sampler, int nCos, int nPhi) {
    const EnvironmentMap& map = sampler.map();
    // θ breakpoints: cells (uniform in cosθ) and texel rows.
    std::vector<double> thetas;
    for (int i = 0; i <= nCos; ++i) thetas.push_back(std::acos(1.0 - 2.0 * i / nCos));
    for (uint32_t y = 0; y <= map.height; ++y) thetas.push_back(M_PI * y / map.height);
    // φ breakpoints: cells and texel columns, which sit at φ_map − rotation in the world.
    std::vector<double> phis;
    for (int j = 0; j <= nPhi; ++j) phis.push_back(-M_PI + 2.0 * M_PI * j / nPhi);
    for (uint32_t x = 0; x < map.width; ++x) {
        double phi = 2.0 * M_PI * (double(x) / map.width - 0.5) - map.rotationRad;
        phi = std::remainder(phi, 2.0 * M_PI);
        phis.push_back(phi);
    }
    for (auto* v : {&thetas, &phis}) {
        std::sort(v->begin(), v->end());
        v->erase(std::unique(v->begin(), v->end(),
                             [](double a, double b) { return std::abs(a - b) < 1e-12; }),
                 v->end());
    }
    std::vector<double> expected(size_t(nCos) * nPhi, 0.0);
    for (size_t a = 0; a + 1 < thetas.size(); ++a) {
        const double theta = 0.5 * (thetas[a] + thetas[a + 1]);
        const double dTheta = thetas[a + 1] - thetas[a];
        const int cell = std::min(nCos - 1, int((1.0 - std::cos(theta)) / 2.0 * nCos));
        for (size_t b = 0; b + 1 < phis.size(); ++b) {
            const double phi = 0.5 * (phis[b] + phis[b + 1]);
            const double dPhi = phis[b + 1] - phis[b];
            const int column = std::min(nPhi - 1, int((phi + M_PI) / (2.0 * M_PI) * nPhi));
            const glm::vec3 d(std::sin(theta) * std::cos(phi), std::cos(theta),
                              std::sin(theta) * std::sin(phi));
            expected[size_t(cell) * nPhi + column] +=
                double(sampler.pdf(d)) * std::sin(theta) * dTheta * dPhi;
        }
    }
    return expected;
}

struct ChiSquare {
    double statistic;
    int dof;
    double pValue;
    double zeroCellSamples;
};

ChiSquare chiSquareTest(const EnvironmentSampler& sampler, int sampleCount, uint32_t seed) {
    const int nCos = 32;
    const int nPhi = 64;
    std::vector<double> observed(size_t(nCos) * nPhi, 0.0);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> uni(0.0f, 1.0f);
    for (int i = 0; i < sampleCount; ++i) {
        const EnvironmentSampler::Sample s = sampler.sample({uni(rng), uni(rng)});
        if (!(s.pdfSolidAngle > 0.0f)) continue;
        const double cosTheta = std::clamp(double(s.direction.y), -1.0, 1.0);
        const double phi = std::atan2(double(s.direction.z), double(s.direction.x));
        const int cell = std::min(nCos - 1, int((1.0 - cosTheta) / 2.0 * nCos));
        const int column = std::clamp(int((phi + M_PI) / (2.0 * M_PI) * nPhi), 0, nPhi - 1);
        observed[size_t(cell) * nPhi + column] += 1.0;
    }
    std::vector<double> expected = expectedFractions(sampler, nCos, nPhi);
    // Sort cells by expected count and pool the small ones until each pool expects >= 5.
    std::vector<size_t> order(expected.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(),
              [&](size_t a, size_t b) { return expected[a] < expected[b]; });
    ChiSquare result{0.0, -1, 0.0, 0.0};
    double pooledObs = 0.0;
    double pooledExp = 0.0;
    for (size_t k : order) {
        const double e = expected[k] * sampleCount;
        if (e == 0.0) {
            result.zeroCellSamples += observed[k];
            continue;
        }
        if (e < 5.0) {
            pooledObs += observed[k];
            pooledExp += e;
            if (pooledExp >= 5.0) {
                result.statistic += (pooledObs - pooledExp) * (pooledObs - pooledExp) / pooledExp;
                ++result.dof;
                pooledObs = pooledExp = 0.0;
            }
            continue;
        }
        result.statistic += (observed[k] - e) * (observed[k] - e) / e;
        ++result.dof;
    }
    if (pooledExp > 0.0) {
        result.statistic += (pooledObs - pooledExp) * (pooledObs - pooledExp) / pooledExp;
        ++result.dof;
    }
    result.pValue = testing::incompleteGammaQ(0.5 * result.dof, 0.5 * result.statistic);
    return result;
}

void expectGoodFit(const EnvironmentSampler& sampler, uint32_t seed) {
    const ChiSquare chi = chiSquareTest(sampler, 1000000, seed);
    // Šidák: each of the kChiSquareTests tests at 1 - (1 - α)^(1/n).
    const double alpha = testing::sidakLevel(kSignificance, kChiSquareTests);
    std::printf("chi2 = %.1f, dof = %d, p = %.4f (reject below %.5f)\n", chi.statistic, chi.dof,
                chi.pValue, alpha);
    EXPECT_GT(chi.pValue, alpha) << "chi2 " << chi.statistic << " dof " << chi.dof;
    EXPECT_EQ(chi.zeroCellSamples, 0.0) << "samples landed where the pdf integrates to 0";
}

TEST(EnvironmentSampling, ChiSquareRealMap) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    EnvironmentMap map = loadOrDie("blender_studiolights_world/city.exr");
    map.rotationRad = 0.0f;
    expectGoodFit(EnvironmentSampler(std::move(map)), 1234u);
}

TEST(EnvironmentSampling, ChiSquareSunMapRotated) {
    EnvironmentMap map = sunMap();
    map.rotationRad = 0.7f;
    expectGoodFit(EnvironmentSampler(std::move(map)), 4321u);
}

TEST(EnvironmentSampling, SamplePdfMatchesPdfFunction) {
    EnvironmentMap map = sunMap();
    map.rotationRad = -1.3f;
    EnvironmentSampler sampler(std::move(map));
    std::mt19937 rng(99);
    std::uniform_real_distribution<float> uni(0.0f, 1.0f);
    int mismatches = 0;
    const int n = 100000;
    for (int i = 0; i < n; ++i) {
        const EnvironmentSampler::Sample s = sampler.sample({uni(rng), uni(rng)});
        ASSERT_TRUE(std::isfinite(s.pdfSolidAngle));
        ASSERT_GT(s.pdfSolidAngle, 0.0f);
        EXPECT_NEAR(glm::length(s.direction), 1.0f, 1e-5f);
        const float p = sampler.pdf(s.direction);
        // A sample within rounding of a texel edge may be looked up in the neighbour.
        if (std::abs(p - s.pdfSolidAngle) > 1e-3f * s.pdfSolidAngle) ++mismatches;
        ASSERT_GT(luminance(sampler.radiance(s.direction)) + (p == s.pdfSolidAngle ? 1.0f : 0.0f),
                  0.0f)
            << "sampled a black texel";
    }
    EXPECT_LT(mismatches, n / 1000);
}

TEST(EnvironmentSampling, RotationConsistency) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    EnvironmentMap map = loadOrDie("polyhaven_1k_hdr/rooitou_park_1k.hdr");
    EnvironmentMap rotatedMap = map;
    const float r = 1.1f;
    rotatedMap.rotationRad = r;
    EnvironmentSampler plain(std::move(map));
    EnvironmentSampler rotated(std::move(rotatedMap));
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> uni(-1.0f, 1.0f);
    int differ = 0;
    for (int i = 0; i < 20000; ++i) {
        glm::vec3 d(uni(rng), uni(rng), uni(rng));
        if (glm::length(d) < 1e-3f) continue;
        d = glm::normalize(d);
        // R^-1 d: rotate by -r about +Y (counter-clockwise from above is positive).
        const glm::vec3 back(std::cos(-r) * d.x + std::sin(-r) * d.z, d.y,
                             -std::sin(-r) * d.x + std::cos(-r) * d.z);
        if (rotated.radiance(d) != plain.radiance(back)) ++differ;
        EXPECT_NEAR(rotated.pdf(d), plain.pdf(back), 1e-3f * plain.pdf(back) + 1e-6f);
    }
    // Texel-edge rounding only.
    EXPECT_LT(differ, 40);
    // Positive rotation turns the map counter-clockwise seen from above: what the unrotated
    // map shows at +X (φ = 0) appears at φ = -r, i.e. towards -Z.
    const glm::vec3 seen(std::cos(r), 0.0f, -std::sin(r));
    EXPECT_EQ(rotated.radiance(seen), plain.radiance({1, 0, 0}));
}

TEST(EnvironmentSampling, NoNaNAtThePoles) {
    EnvironmentMap map = sunMap(64, 32);
    for (uint32_t x = 0; x < 64; ++x) {
        map.radiance[x] = glm::vec3(50.0f);            // bright zenith row
        map.radiance[31 * 64 + x] = glm::vec3(20.0f);  // bright nadir row
    }
    EnvironmentSampler sampler(std::move(map));
    for (const glm::vec3& d : {glm::vec3(0, 1, 0), glm::vec3(0, -1, 0), glm::vec3(1e-8f, 1, 0),
                               glm::vec3(0, -1, -1e-8f)}) {
        const float p = sampler.pdf(d);
        EXPECT_TRUE(std::isfinite(p) && p >= 0.0f) << p;
        const glm::vec3 l = sampler.radiance(d);
        EXPECT_TRUE(std::isfinite(l.r + l.g + l.b));
    }
    EXPECT_EQ(sampler.pdf({0, 1, 0}), 0.0f);
    for (float u0 : {0.0f, 0.5f, 0.99999994f, 1.0f}) {
        for (float u1 : {0.0f, 1e-9f, 0.5f, 0.99999994f, 1.0f}) {
            const EnvironmentSampler::Sample s = sampler.sample({u0, u1});
            EXPECT_TRUE(std::isfinite(s.pdfSolidAngle) && s.pdfSolidAngle >= 0.0f);
            EXPECT_TRUE(std::isfinite(s.direction.x + s.direction.y + s.direction.z));
            EXPECT_NEAR(glm::length(s.direction), 1.0f, 1e-5f);
        }
    }
    // u wrap: φ = ±π is the seam between the last and the first column.
    EXPECT_TRUE(std::isfinite(sampler.pdf({-1, 0, 0})));
    EXPECT_TRUE(std::isfinite(sampler.pdf({-1, 0, -1e-9f})));
    EXPECT_TRUE(std::isfinite(sampler.pdf({-1, 0, 1e-9f})));
}

TEST(EnvironmentSampling, NonFiniteTexelsBecomeZero) {
    EnvironmentMap map;
    map.width = 4;
    map.height = 2;
    map.radiance.assign(8, glm::vec3(1.0f));
    map.radiance[3] = glm::vec3(std::nanf(""), 1.0f, 1.0f);
    map.radiance[5] = glm::vec3(INFINITY);
    // buildEnvironmentDistribution ignores non-finite weights even without the loader's cleanup.
    const EnvironmentDistribution dist = buildEnvironmentDistribution(map);
    for (float c : dist.conditionalCdf) EXPECT_TRUE(std::isfinite(c));
    for (float c : dist.marginalCdf) EXPECT_TRUE(std::isfinite(c));
    EXPECT_EQ(dist.marginalCdf.back(), 1.0f);
    EXPECT_TRUE(std::isfinite(dist.integral));

    // Through the loader: NaN, Inf and negative channels are replaced by 0.
    ImageF image{4, 2, 3, std::vector<float>(24, 1.0f), false};
    image.pixels[0] = std::nanf("");
    image.pixels[4] = INFINITY;
    image.pixels[8] = -2.0f;
    const std::string path = ::testing::TempDir() + "nonfinite_env.exr";
    ASSERT_TRUE(writeExr(path, image).ok());
    Result<EnvironmentMap> loaded = loadEnvironmentMap(path);
    ASSERT_TRUE(loaded.ok()) << loaded.message();
    EXPECT_EQ(loaded->radiance[0], glm::vec3(0, 1, 1));
    EXPECT_EQ(loaded->radiance[1], glm::vec3(1, 0, 1));
    EXPECT_EQ(loaded->radiance[2], glm::vec3(1, 1, 0));
    EXPECT_EQ(loaded->radiance[3], glm::vec3(1, 1, 1));
}

}  // namespace
}  // namespace previs
