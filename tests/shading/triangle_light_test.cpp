// Emissive-triangle sampling of trace_paths.comp (shared/triangle_light.h) on the CPU: directions
// uniform in the triangle's solid angle (chi-square on cells of exactly known solid angle), the
// density integrating to 1 over the triangle for both strategies, and finite samples and
// densities at the extremes (tiny, far, grazing, huge and near).
#include "gpu/shaders/shared/triangle_light.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <random>
#include <vector>

#include "tests/support/chi2.h"

namespace previs::testing {
namespace {

using namespace previs::shader;
using glm::dvec3;

struct Case {
    const char* name;
    glm::vec3 p;
    glm::vec3 p0, p1, p2;
};

// Shapes and sizes for the chi-square test: solid angles from nearly 2π sr to the
// spherical-sampling threshold, both windings.
const std::array<Case, 8> kUniformCases = {{
    {"equilateral", {0, 0, 0}, {-0.5f, -0.3f, 1}, {0.5f, -0.3f, 1}, {0, 0.6f, 1}},
    {"equilateral reversed", {0, 0, 0}, {0, 0.6f, 1}, {0.5f, -0.3f, 1}, {-0.5f, -0.3f, 1}},
    {"sliver", {0.1f, 0.2f, 0}, {-1, 0, 1}, {1, 0, 1.2f}, {0.9f, 0.05f, 1.1f}},
    {"obtuse off-axis", {0, 0, 0}, {2, 0, 0.5f}, {0.3f, 0.1f, 0.6f}, {-0.4f, 1.5f, 0.4f}},
    {"large and near", {0, 0, 0}, {-3, -3, 0.2f}, {4, -2, 0.25f}, {0, 4, 0.15f}},
    // Ω ≈ 2π − 0.01: the point almost in the plane of a triangle around it.
    {"nearly a hemisphere", {0.5f, 0.3f, 0.01f}, {-10, -10, 0}, {10, -10, 0}, {0, 10, 0}},
    {"small quad half", {0.3f, 0.1f, 0}, {0.6f, 1.5f, 0}, {0.8f, 1.5f, 0}, {0.8f, 1.5f, 0.2f}},
    // Ω ≈ 1.1e-6 sr, off axis, just above PV_SPHERICAL_MIN_SOLID_ANGLE: the float sampler must
    // still be uniform where it is first used.
    {"at the threshold", {0.3f, 0.2f, 0}, {0, 0, 1}, {0.0015f, 0, 1}, {0.0003f, 0.0018f, 1}},
}};
constexpr int kChi2Tests = int(kUniformCases.size());
const double kLevel = sidakLevel(0.01, kChi2Tests);

double solidAngle(dvec3 a, dvec3 b, dvec3 c) {  // unit vectors, Van Oosterom & Strackee
    double num = std::abs(glm::dot(a, glm::cross(b, c)));
    double den = 1.0 + glm::dot(a, b) + glm::dot(b, c) + glm::dot(c, a);
    return 2.0 * std::atan2(num, den);
}

// A spherical triangle cut into 4^depth cells by great-circle arcs through its edges'
// midpoints: the cells tile it exactly and each one's solid angle is known in closed form.
class SphericalCells {
public:
    SphericalCells(dvec3 a, dvec3 b, dvec3 c, int depth) : depth_(depth) {
        root_ = {a, b, c};
        collect(root_, depth);
    }
    size_t size() const { return solidAngles_.size(); }
    double solidAngle(size_t i) const { return solidAngles_[i]; }
    // The cell containing w; -1 if w lies outside the triangle by more than `slack` (radians).
    int cellOf(dvec3 w, double slack) const {
        std::array<dvec3, 3> t = root_;
        if (margin(t, w) < -slack) return -1;
        int index = 0;
        for (int level = 0; level < depth_; ++level) {
            auto kids = children(t);
            int best = 0;
            double bestMargin = -1e300;
            for (int k = 0; k < 4; ++k) {
                double m = margin(kids[k], w);
                if (m > bestMargin) {
                    bestMargin = m;
                    best = k;
                }
            }
            index = index * 4 + best;
            t = kids[best];
        }
        return index;
    }

private:
    static std::array<std::array<dvec3, 3>, 4> children(const std::array<dvec3, 3>& t) {
        dvec3 ab = glm::normalize(t[0] + t[1]);
        dvec3 bc = glm::normalize(t[1] + t[2]);
        dvec3 ca = glm::normalize(t[2] + t[0]);
        return {{{t[0], ab, ca}, {ab, t[1], bc}, {ca, bc, t[2]}, {ab, bc, ca}}};
    }
    // Smallest signed angular distance of w inside the three edges' great circles.
    static double margin(const std::array<dvec3, 3>& t, dvec3 w) {
        double orient = glm::dot(t[0], glm::cross(t[1], t[2])) >= 0.0 ? 1.0 : -1.0;
        double m = 1e300;
        for (int e = 0; e < 3; ++e) {
            dvec3 n = glm::normalize(glm::cross(t[e], t[(e + 1) % 3])) * orient;
            m = std::min(m, std::asin(std::clamp(glm::dot(n, w), -1.0, 1.0)));
        }
        return m;
    }
    void collect(const std::array<dvec3, 3>& t, int depth) {
        if (depth == 0) {
            solidAngles_.push_back(previs::testing::solidAngle(t[0], t[1], t[2]));
            return;
        }
        for (const auto& k : children(t)) collect(k, depth - 1);
    }
    int depth_;
    std::array<dvec3, 3> root_;
    std::vector<double> solidAngles_;
};

dvec3 unitFrom(glm::vec3 p, glm::vec3 q) { return glm::normalize(dvec3(q) - dvec3(p)); }

glm::vec3 pointAt(const Case& c, glm::vec2 b) {
    return (1.0f - b.x - b.y) * c.p0 + b.x * c.p1 + b.y * c.p2;
}

// Chi-square of the spherical sampler's directions (area sampling's with `spherical` off)
// against uniform solid angle over 64 cells.
Chi2Result sphericalChi2(const Case& c, int samples, uint32_t seed, bool spherical = true) {
    SphericalCells cells(unitFrom(c.p, c.p0), unitFrom(c.p, c.p1), unitFrom(c.p, c.p2), 3);
    double total = 0.0;
    for (size_t i = 0; i < cells.size(); ++i) total += cells.solidAngle(i);
    std::vector<double> observed(cells.size(), 0.0);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> uni(0.0f, std::nextafter(1.0f, 0.0f));
    const float omega = triangleSolidAngle(c.p, c.p0, c.p1, c.p2);
    Chi2Result r;
    for (int i = 0; i < samples; ++i) {
        glm::vec2 u(uni(rng), uni(rng));
        glm::vec2 b = spherical ? sampleSphericalTriangleLight(c.p, c.p0, c.p1, c.p2, omega, u)
                                : sampleUniformTriangle(u);
        dvec3 w = unitFrom(c.p, pointAt(c, b));
        int cell = cells.cellOf(w, 1e-5);
        if (cell < 0) {
            r.statistic = INFINITY;
            r.pValue = 0.0;
            return r;
        }
        observed[size_t(cell)] += 1.0;
    }
    for (size_t i = 0; i < cells.size(); ++i) {
        double expected = samples * cells.solidAngle(i) / total;
        r.expectedTotal += expected;
        r.observedTotal += observed[i];
        r.statistic += (observed[i] - expected) * (observed[i] - expected) / expected;
    }
    r.degreesOfFreedom = int(cells.size()) - 1;
    r.pValue = incompleteGammaQ(0.5 * r.degreesOfFreedom, 0.5 * r.statistic);
    return r;
}

TEST(TriangleLightTest, SphericalSamplesAreUniformInSolidAngle) {
    uint32_t seed = 10;
    for (const Case& c : kUniformCases) {
        float omega = triangleSolidAngle(c.p, c.p0, c.p1, c.p2);
        ASSERT_GE(omega, PV_SPHERICAL_MIN_SOLID_ANGLE) << c.name << ": below the threshold";
        Chi2Result r = sphericalChi2(c, 400'000, seed++);
        EXPECT_GT(r.pValue, kLevel) << c.name << " (" << omega << " sr): " << r.describe();
        RecordProperty(std::string("p ") + c.name, std::to_string(r.pValue));
    }
}

// The test has the power to tell: area sampling of a moderately small triangle (0.02 m² at
// 1.4 m, the area-light scene's emitters) is rejected at the same level.
TEST(TriangleLightTest, ChiSquareRejectsAreaSampling) {
    Chi2Result r = sphericalChi2(kUniformCases[6], 400'000, 30, false);
    EXPECT_LT(r.pValue, kLevel) << r.describe();
}

// Which strategy runs: spherical where the triangle is large against its plane's distance,
// area where it is small and far, below the precision threshold, or p is in its plane.
TEST(TriangleLightTest, ChoosesSphericalSamplingWhereItPays) {
    const glm::vec3 p0(0, 0, 1), p1(0.2f, 0, 1), p2(0, 0.2f, 1);
    EXPECT_GT(sphericalSamplingSolidAngle({0.05f, 0.05f, 0.9f}, p0, p1, p2), 0.0f);  // 10 cm
    EXPECT_GT(sphericalSamplingSolidAngle({5, 0, 0.9f}, p0, p1, p2), 0.0f);  // far but grazing
    EXPECT_EQ(sphericalSamplingSolidAngle({0.05f, 0.05f, 0.5f}, p0, p1, p2), 0.0f);  // 50 cm
    EXPECT_EQ(sphericalSamplingSolidAngle({3000, 0, 0.9f}, p0, p1, p2), 0.0f);       // < 1e-6 sr
    EXPECT_EQ(sphericalSamplingSolidAngle({0.5f, 0.5f, 1}, p0, p1, p2), 0.0f);       // in the plane
}

// The solid angle the sampler uses is the triangle's (double-precision reference), to float
// precision, from a few steradians down to far below the threshold.
TEST(TriangleLightTest, SolidAngleIsAccurate) {
    for (const Case& c : kUniformCases) {
        double ref = solidAngle(unitFrom(c.p, c.p0), unitFrom(c.p, c.p1), unitFrom(c.p, c.p2));
        EXPECT_NEAR(triangleSolidAngle(c.p, c.p0, c.p1, c.p2) / ref, 1.0, 1e-5) << c.name;
    }
    // 1 mm triangle 10 m away: ~5e-9 sr, where the angle-sum formula has no digits left.
    glm::vec3 p(0.0f), p0(1e-3f, 0, 10), p1(0, 1e-3f, 10), p2(0, 0, 10);
    double ref = 0.5e-6 / 100.0;  // area / distance² (the triangle is perpendicular, tiny)
    EXPECT_NEAR(triangleSolidAngle(p, p0, p1, p2) / ref, 1.0, 1e-4);
}

// ∫ pdf dω over the triangle's solid angle = 1, for the spherical and the area strategy: the
// mean of pdf(ω)·4π over uniform directions on the sphere (0 where the ray misses the triangle)
// is 1, within 4.0 standard errors (two-sided 1% over 2×4 estimates after Šidák is 3.7).
TEST(TriangleLightTest, DensityIntegratesToOne) {
    const std::array<Case, 4> cases = {kUniformCases[0], kUniformCases[2], kUniformCases[3],
                                       kUniformCases[4]};  // the solid angles it can resolve
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> uni(0.0f, 1.0f);
    for (const Case& c : cases) {
        for (bool spherical : {true, false}) {
            const int n = 2'000'000;
            double sum = 0.0, sum2 = 0.0;
            for (int i = 0; i < n; ++i) {
                glm::vec3 w = sampleUniformSphere({uni(rng), uni(rng)});
                // Does the ray from p along w hit the triangle? (barycentrics before clamping)
                glm::vec3 e1 = c.p1 - c.p0, e2 = c.p2 - c.p0, s1 = glm::cross(w, e2);
                float div = glm::dot(s1, e1);
                glm::vec3 sv = c.p - c.p0;
                float b1 = glm::dot(sv, s1) / div, b2 = glm::dot(w, glm::cross(sv, e1)) / div;
                float t = glm::dot(e2, glm::cross(sv, e1)) / div;
                double x = 0.0;
                if (b1 >= 0 && b2 >= 0 && b1 + b2 <= 1 && t > 0)
                    x = 4.0 * M_PI *
                        triangleLightDirectionPdf(c.p, c.p0, c.p1, c.p2, c.p + t * w, spherical);
                sum += x;
                sum2 += x * x;
            }
            double mean = sum / n;
            double se = std::sqrt((sum2 / n - mean * mean) / (n - 1));
            EXPECT_NEAR(mean, 1.0, 4.0 * se) << c.name << (spherical ? " spherical" : " area");
        }
    }
}

// The density the sampler reports is the one triangleLightDirectionPdf gives for its point —
// the pdf MIS evaluates for a BSDF-sampled hit there (exact for the spherical strategy, whose
// density does not depend on the point).
TEST(TriangleLightTest, SampledDensityIsTheEvaluatedDensity) {
    std::mt19937 rng(8);
    std::uniform_real_distribution<float> uni(0.0f, 1.0f);
    for (const Case& c : kUniformCases) {
        for (int i = 0; i < 1000; ++i) {
            float pdf = 0.0f;
            glm::vec2 b =
                sampleTriangleLight(c.p, c.p0, c.p1, c.p2, {uni(rng), uni(rng)}, true, pdf);
            EXPECT_EQ(pdf, triangleLightDirectionPdf(c.p, c.p0, c.p1, c.p2, pointAt(c, b), true))
                << c.name;
        }
    }
}

// Extremes: every sample has finite barycentrics on the triangle and a finite, non-negative
// density, for corner values of u too; the density is positive wherever the triangle has a
// solid angle.
TEST(TriangleLightTest, ExtremeTrianglesGiveFiniteSamples) {
    const std::array<Case, 8> extremes = {{
        {"tiny", {0, 0, 0}, {0, 0, 1}, {1e-6f, 0, 1}, {0, 1e-6f, 1}},
        {"far", {0, 0, 0}, {0, 0, 1e5f}, {1, 0, 1e5f}, {0, 1, 1e5f}},
        {"grazing", {0, 0, 1e-6f}, {1, 0, 0}, {2, 0, 0}, {1, 1, 0}},
        {"huge and near", {0.1f, 0.1f, 1e-3f}, {-1e4f, -1e4f, 0}, {1e4f, -1e4f, 0}, {0, 1e4f, 0}},
        {"near a vertex", {1e-5f, 1e-5f, 1e-5f}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}},
        {"near an edge", {0.5f, -1e-6f, 1e-6f}, {0, 0, 0}, {1, 0, 0}, {0, 1, 0}},
        {"sliver", {0, 0, 0}, {-1, 0, 1}, {1, 0, 1}, {0, 1e-7f, 1}},
        {"near hemisphere", {0, 0, 0.03f}, {-10, -10, 0}, {10, -10, 0}, {0, 10, 0}},
    }};
    std::mt19937 rng(9);
    std::uniform_real_distribution<float> uni(0.0f, 1.0f);
    const float one = PV_ONE_MINUS_EPSILON;
    for (const Case& c : extremes) {
        for (bool spherical : {true, false}) {
            for (int i = 0; i < 20000; ++i) {
                glm::vec2 u(uni(rng), uni(rng));
                if (i < 9)
                    u = glm::vec2(std::array{0.0f, 0.5f, one}[i % 3],
                                  std::array{0.0f, 0.5f, one}[i / 3]);
                float pdf = -1.0f;
                glm::vec2 b = sampleTriangleLight(c.p, c.p0, c.p1, c.p2, u, spherical, pdf);
                ASSERT_TRUE(std::isfinite(b.x) && std::isfinite(b.y)) << c.name;
                ASSERT_TRUE(b.x >= 0 && b.y >= 0 && b.x + b.y <= 1.0f + 1e-6f) << c.name;
                ASSERT_TRUE(std::isfinite(pdf) && pdf >= 0.0f) << c.name << " pdf " << pdf;
                float eval =
                    triangleLightDirectionPdf(c.p, c.p0, c.p1, c.p2, pointAt(c, b), spherical);
                ASSERT_TRUE(std::isfinite(eval) && eval >= 0.0f) << c.name;
            }
        }
        float omega = triangleSolidAngle(c.p, c.p0, c.p1, c.p2);
        EXPECT_TRUE(std::isfinite(omega) && omega >= 0.0f && omega <= 2.0f * PV_PI) << c.name;
    }
}

}  // namespace
}  // namespace previs::testing
