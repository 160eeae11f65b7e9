// Photon mapping for caustics (render/photon_map.h, gpu/shaders/shared/photon_records.h): the flux
// photons deposit, the split of light paths between the photon map and the path tracer (their
// sum equals a pure path trace where that converges), progressive convergence, the differential
// identities, and that a scene without a caustic pays nothing. Seeds are fixed; tolerances come
// from the measured noise.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstring>
#include <map>

#include "gpu/shaders/shared/bsdf.h"
#include "gpu/shaders/shared/photon_records.h"
#include "render/quality_dial.h"
#include "scene/material.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

constexpr float kPi = 3.14159265358979f;

RenderSettings photonSettings(uint32_t width, uint32_t height, PhotonMode mode) {
    RenderSettings rs = renderSettings(width, height, RenderSettings{}.maxDepth);
    rs.photons.mode = mode;
    // These tests were written at 32768 photons per iteration (the default until BENCHMARKS.md's
    // eighth caustics pass): their small images need no more, and their time stays.
    rs.photons.perIteration = 1u << 15;
    return rs;
}

// Sum of the power of the level-1 records (or the level-2 ones) in `solution` (PV_PHOTON_IN_*),
// green channel.
double depositedPower(const std::vector<shader::PhotonRecord>& records, uint32_t solution,
                      bool level2 = false) {
    double sum = 0.0;
    for (const auto& r : records)
        if ((r.flags & solution) && ((r.flags & PV_PHOTON_LEVEL_2) != 0) == level2)
            sum += r.power.g;
    return sum;
}

// Two sets of independent renders compared by their green image means: each set's mean, and
// |difference| over its standard error (printed, photon+path first).
struct MeanAgreement {
    double meanA = 0.0, meanB = 0.0, z = 0.0;
};
MeanAgreement agreementOfMeans(const std::vector<ImageF>& a, const std::vector<ImageF>& b) {
    auto means = [](const std::vector<ImageF>& images) {
        std::vector<double> out;
        for (const ImageF& img : images) {
            double sum = 0.0;
            for (size_t i = 1; i < img.pixels.size(); i += 3) sum += img.pixels[i];
            out.push_back(sum / double(img.pixels.size() / 3));
        }
        return meanAndVarianceOfMean(out);
    };
    const auto [meanA, varA] = means(a);
    const auto [meanB, varB] = means(b);
    MeanAgreement m{meanA, meanB, std::abs(meanA - meanB) / std::sqrt(varA + varB)};
    std::printf("photon+path image mean %.5f (sd of mean %.5f), path tracing %.5f (%.5f), z %.2f\n",
                meanA, std::sqrt(varA), meanB, std::sqrt(varB), m.z);
    return m;
}

// A closed white room (real) lit by a small real lamp in its ceiling, a smooth glass ball on its
// floor (real or virtual), seen from above.
Scene glassBallInAWhiteRoom(bool ballIsReal) {
    Scene scene;
    uint32_t white = addMaterial(scene, lambert(glm::vec3(0.7f)));
    uint32_t glassMat = addMaterial(scene, glass(1.5f));
    uint32_t lamp = addMaterial(scene, emitter(glm::vec3(200.0f)));
    addBox(scene, glm::vec3(-1.0f, 0.0f, -1.0f), glm::vec3(1.0f, 1.5f, 1.0f), white, true, true);
    addSphere(scene, glm::vec3(0.1f, 0.25f, 0.0f), 0.2f, glassMat, ballIsReal);
    addQuad(scene, glm::vec3(-0.2f, 1.2f, -0.1f), glm::vec3(0.05f, 0, 0), glm::vec3(0, 0, 0.05f),
            lamp, true);
    scene.cameras.push_back(
        lookAt(glm::vec3(0, 0.9f, 0.9f), glm::vec3(0, 0.1f, 0), glm::vec3(0, 1, 0), 1.2f));
    return scene;
}

class PhotonTest : public GpuTest {
protected:
    // A differential 32×24 renderer of `scene` (16384 photons per iteration) after `iterations`
    // samples; null, with the test failed, if it cannot render or runs no photons.
    std::unique_ptr<Renderer> differentialPhotonRenderer(const Scene& scene, uint32_t iterations) {
        RenderSettings rs = photonSettings(32, 24, PhotonMode::Auto);
        rs.differential = true;
        rs.photons.perIteration = 1u << 14;
        std::unique_ptr<Renderer> r = photonRenderer(scene, rs);
        if (r && !r->render(iterations).ok()) {
            ADD_FAILURE() << "the render failed";
            return nullptr;
        }
        return r;
    }

    // A renderer of `scene` whose photon pass runs; null, with the test failed, if it cannot be
    // made or runs no photons.
    std::unique_ptr<Renderer> photonRenderer(const Scene& scene, const RenderSettings& rs,
                                             const RendererTestOptions& testOptions = {}) {
        auto renderer = Renderer::create(ctx(), scene, rs, {}, testOptions);
        if (!renderer) {
            ADD_FAILURE() << renderer.message();
            return nullptr;
        }
        if (!(*renderer)->photonsActive()) {
            ADD_FAILURE() << "no photon pass";
            return nullptr;
        }
        return std::move(renderer.value());
    }
};

// A point light above a smooth glass ball in a closed white room: Fresnel splits every photon
// between reflection and refraction without loss, and the room catches all of it, so the flux
// the photons deposit is the flux the ball intercepts, I·Ω (Ω its solid angle from the light).
// Photons are aimed at the ball's bounding sphere, larger than the ball: the hit fraction is
// binomial, which sets the tolerance. (Refracted flux keeps no 1/η² factor: with it the deposit
// would fall to 1/η⁴ ≈ 0.2 of this.)
TEST_F(PhotonTest, GlassBallDepositsTheFluxItIntercepts) {
    Scene scene;
    uint32_t white = addMaterial(scene, lambert(glm::vec3(0.8f)));
    uint32_t glassMat = addMaterial(scene, glass(1.5f));
    addBox(scene, glm::vec3(-2.0f), glm::vec3(2.0f), white, true, true);
    const float radius = 0.3f;
    const glm::vec3 light(0.0f, 1.2f, 0.0f);
    addSphere(scene, glm::vec3(0.0f), radius, glassMat, true, 96, 192);
    const float candela = 10.0f;
    scene.lights.push_back(pointLight(light, candela, true));
    scene.cameras.push_back(lookAt(glm::vec3(0, 0, 1.9f), glm::vec3(0), glm::vec3(0, 1, 0), 1.0f));

    RenderSettings rs = photonSettings(16, 16, PhotonMode::Auto);
    rs.photons.perIteration = 1u << 16;
    std::unique_ptr<Renderer> renderer = photonRenderer(scene, rs);
    ASSERT_TRUE(renderer);
    Renderer& r = *renderer;
    const int iterations = 16;
    std::vector<double> perIteration, level2Ratio;
    size_t stored = 0;
    for (int i = 0; i < iterations; ++i) {
        ASSERT_TRUE(r.render(1).ok());
        auto records = r.diagnostics().photonRecords();
        ASSERT_TRUE(records.ok()) << records.message();
        perIteration.push_back(depositedPower(*records, PV_PHOTON_IN_MIXED));
        level2Ratio.push_back(depositedPower(*records, PV_PHOTON_IN_MIXED, true) /
                              perIteration.back());
        for (const auto& rec : *records) stored += rec.flags != 0;
    }
    auto [mean, varianceOfMean] = meanAndVarianceOfMean(perIteration);
    const double d = glm::length(light);
    const double solidAngle = 2.0 * kPi * (1.0 - std::sqrt(1.0 - radius * radius / (d * d)));
    const double expected = candela * solidAngle;
    // Statistical: 4.5σ of the measured iteration-to-iteration noise. Geometric: the tessellated
    // ball's outline is a 192-gon inscribed in the circle, whose area is cos²(π/192) ≥ 0.9997 of
    // it.
    const double tolerance = 4.5 * std::sqrt(varianceOfMean) + 3e-4 * expected;
    EXPECT_NEAR(mean, expected, tolerance)
        << "deposited " << mean << " W (σ " << std::sqrt(varianceOfMean) << "), intercepted "
        << expected;
    EXPECT_GT(stored, size_t(iterations) * 10000u);
    // Level 2: what the walls (albedo 0.8) scatter on lands again in the closed box, so its power
    // is 0.8 of level 1's (Russian roulette keeps each photon's power), less the photons whose
    // chain through the ball outlasts the bounce budget (max depth − 1): 0.01 % measured, 0.1 %
    // allowed.
    auto [ratio, ratioVariance] = meanAndVarianceOfMean(level2Ratio);
    std::printf("level 2 / level 1 power: %.5f (sigma %.5f)\n", ratio, std::sqrt(ratioVariance));
    EXPECT_NEAR(ratio, 0.8, 4.5 * std::sqrt(ratioVariance) + 0.8 * 1e-3);
}

// Flux is not rescaled by 1/η² when it refracts (radiance is). A diffuse square across the
// equator of a glass ball, lit by a point light on the axis above: every photon that refracts into
// the upper half lands on the square with no other bounce, and a reflected one lands on it where
// its ray meets the square outside the ball. The expected deposit is ∫ I·(1 − F(θ) + F(θ)·[the
// reflection reaches the square]) dω over the ball as seen from the light — numerically, over the
// angle ψ off the axis and the azimuth, on the exact sphere. With the radiance factor the refracted
// part would be 1/η² = 0.44 of itself.
TEST_F(PhotonTest, RefractedFluxIsNotScaledByEtaSquared) {
    Scene scene;
    uint32_t white = addMaterial(scene, lambert(glm::vec3(0.8f)));
    uint32_t glassMat = addMaterial(scene, glass(1.5f));
    const float radius = 0.3f;
    const float d = 1.2f;
    addSphere(scene, glm::vec3(0.0f), radius, glassMat, true, 96, 192);
    addQuad(scene, glm::vec3(0.0f), glm::vec3(0.5f, 0, 0), glm::vec3(0, 0, -0.5f), white, true);
    const float candela = 10.0f;
    scene.lights.push_back(pointLight(glm::vec3(0.0f, d, 0.0f), candela, true));
    scene.cameras.push_back(lookAt(glm::vec3(0, 1, 1.5f), glm::vec3(0), glm::vec3(0, 1, 0), 1.0f));
    RenderSettings rs = photonSettings(16, 16, PhotonMode::Auto);
    std::unique_ptr<Renderer> renderer = photonRenderer(scene, rs);
    ASSERT_TRUE(renderer);
    std::vector<double> perIteration;
    for (int i = 0; i < 16; ++i) {
        ASSERT_TRUE(renderer->render(1).ok());
        auto records = renderer->diagnostics().photonRecords();
        ASSERT_TRUE(records.ok());
        perIteration.push_back(depositedPower(*records, PV_PHOTON_IN_MIXED));
    }
    auto [mean, varianceOfMean] = meanAndVarianceOfMean(perIteration);
    // Midpoint rule in ψ and azimuth, fine enough that its error is far below the noise.
    const double psiMax = std::asin(radius / d);
    const int steps = 4000;
    const int azimuths = 256;
    const double half = 0.5;  // the square's half size
    double expected = 0.0;
    for (int k = 0; k < steps; ++k) {
        const double psi = (k + 0.5) * psiMax / steps;
        const double dOmega = 2.0 * kPi * std::sin(psi) * psiMax / steps / azimuths;
        for (int a = 0; a < azimuths; ++a) {
            const double phi = (a + 0.5) * 2.0 * kPi / azimuths;
            const glm::dvec3 dir(std::sin(psi) * std::cos(phi), -std::cos(psi),
                                 std::sin(psi) * std::sin(phi));
            const double t =
                d * std::cos(psi) -
                std::sqrt(std::max(0.0, radius * radius - d * d * std::sin(psi) * std::sin(psi)));
            const glm::dvec3 p = glm::dvec3(0.0, d, 0.0) + t * dir;
            const glm::dvec3 n = p / double(radius);
            const double cosTheta = -glm::dot(dir, n);
            const double fresnel = shader::fresnelDielectric(float(cosTheta), 1.5f);
            double landed = 1.0 - fresnel;
            const glm::dvec3 r = dir + 2.0 * cosTheta * n;
            if (r.y < 0.0) {
                const glm::dvec3 q = p - p.y / r.y * r;
                if (std::abs(q.x) < half && std::abs(q.z) < half) landed += fresnel;
            }
            expected += candela * landed * dOmega;
        }
    }
    // Geometry: a 192-gon outline and interpolated normals on 96 rings; 0.3 % covers both (the
    // η² error this test guards against is 56 %).
    const double tolerance = 4.5 * std::sqrt(varianceOfMean) + 3e-3 * expected;
    EXPECT_NEAR(mean, expected, tolerance) << "deposited " << mean << " W, expected " << expected;
    std::printf("deposited %.5f W (sigma %.5f), expected %.5f\n", mean, std::sqrt(varianceOfMean),
                expected);
}

// A scene whose light reaches the floor only through a glass ball is a caustic; the photon map
// carries it (levels 1 and 2) and the path tracer leaves those paths out. With a light large enough
// for the path tracer to converge, the two must agree: the image mean (where blur by the gather
// radius cannot move energy, as the density estimate conserves it on a plane) within the noise of
// both, and per pixel the error must shrink as iterations shrink the radius.
class CausticAgreementTest : public PhotonTest {
protected:
    static Scene scene() {
        Scene s;
        uint32_t floorMat = addMaterial(s, lambert(glm::vec3(0.7f)));
        uint32_t glassMat = addMaterial(s, glass(1.5f));
        uint32_t lamp = addMaterial(s, emitter(glm::vec3(30.0f)));
        addQuad(s, glm::vec3(0.0f), glm::vec3(1.5f, 0, 0), glm::vec3(0, 0, -1.5f), floorMat, true);
        addSphere(s, glm::vec3(0.0f, 0.35f, 0.0f), 0.25f, glassMat, false);
        // A varnished wall behind the ball: diffuse under a smooth coat, so a camera path meets
        // a gather vertex that scatters through a delta lobe (level 1 is then gathered at the
        // next one, shared/photon_records.h), and photons land on it twice (level 2).
        Material varnish = lambert(glm::vec3(0.6f));
        varnish.roughness = 0.0f;
        varnish.specular = 1.0f;
        uint32_t wallMat = addMaterial(s, varnish);
        addQuad(s, glm::vec3(0.0f, 0.6f, -0.7f), glm::vec3(1.5f, 0, 0), glm::vec3(0, 0.6f, 0),
                wallMat, true);
        // A 0.3 m square facing down, 1.1 m above the floor.
        addQuad(s, glm::vec3(0.0f, 1.1f, 0.0f), glm::vec3(0.15f, 0, 0), glm::vec3(0, 0, 0.15f),
                lamp, true);
        s.cameras.push_back(
            lookAt(glm::vec3(0, 1.6f, 1.2f), glm::vec3(0, 0, 0), glm::vec3(0, 1, 0), 0.9f));
        return s;
    }

    // 48×36 preview frames with a 4096-photon budget (refinement: 32768).
    static RenderSettings previewSettings() {
        RenderSettings rs = photonSettings(48, 36, PhotonMode::Auto);
        rs.photons.perIteration = 1u << 15;
        rs.photons.previewPerIteration = 4096;
        return rs;
    }
    // A 2-sample preview frame's pixels; empty, with the test failed, on an error.
    static std::vector<float> previewFrame(Renderer& r) {
        EXPECT_TRUE(r.renderPreviewFrame(2).ok());
        auto image = r.image();
        EXPECT_TRUE(image.ok());
        return image.ok() ? image->pixels : std::vector<float>{};
    }
};

TEST_F(CausticAgreementTest, PhotonsPlusPathsEqualPathTracing) {
    const Scene s = scene();
    RenderSettings pathOnly = photonSettings(48, 36, PhotonMode::Off);
    RenderSettings withPhotons = photonSettings(48, 36, PhotonMode::Auto);
    withPhotons.photons.perIteration = 1u << 15;
    constexpr uint32_t kRuns = 8;
    // A photon iteration costs 60-100 path samples here, and the photon runs' means scatter less:
    // 1024 samples against 32 iterations a run gives the difference of the means about the noise
    // of 512 against 64 (sd 0.00048 against 0.00043 of a mean of 0.212) in 42 % of the time.
    std::vector<ImageF> reference = renders(s, pathOnly, 1024, kRuns, 100);
    std::vector<ImageF> photon = renders(s, withPhotons, 32, kRuns, 200);
    ASSERT_EQ(reference.size(), kRuns);
    ASSERT_EQ(photon.size(), kRuns);
    const MeanAgreement m = agreementOfMeans(photon, reference);
    // Student's t, 14 dof, two-sided 0.1 %.
    EXPECT_LT(m.z, 4.1) << "photon+path mean " << m.meanA << ", path tracing " << m.meanB;
    // Not vacuous: the photons carry a real share of the light on the floor.
    std::unique_ptr<Renderer> r = photonRenderer(s, withPhotons);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->render(1).ok());
    auto records = r->diagnostics().photonRecords();
    ASSERT_TRUE(records.ok());
    EXPECT_GT(depositedPower(*records, PV_PHOTON_IN_MIXED), 0.1);
}

TEST_F(CausticAgreementTest, ErrorFallsAsTheRadiusShrinks) {
    const Scene s = scene();
    RenderSettings pathOnly = photonSettings(48, 36, PhotonMode::Off);
    ImageF reference = render(s, pathOnly, 4096);
    RenderSettings withPhotons = photonSettings(48, 36, PhotonMode::Auto);
    // 8192 photons an iteration: the errors at 4..256 iterations are those of 32768 within 0.5 %
    // (rate -0.71 both; the camera paths' noise and the radius dominate them) at half the CPU.
    withPhotons.photons.perIteration = 1u << 13;
    auto renderer = Renderer::create(ctx(), s, withPhotons);
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    Renderer& r = **renderer;
    std::vector<std::pair<uint32_t, double>> errors;
    for (uint32_t iterations : {4u, 16u, 64u, 256u}) {
        ASSERT_TRUE(r.render(iterations - uint32_t(r.samplesPerPixel())).ok());
        auto image = r.image();
        ASSERT_TRUE(image.ok());
        errors.emplace_back(iterations, std::sqrt(meanSquaredErrors({*image}, reference)[0]));
    }
    for (auto [n, e] : errors) std::printf("iterations %u: RMSE %.5f\n", n, e);
    const double rate = std::log(errors.back().second / errors.front().second) /
                        std::log(double(errors.back().first) / errors.front().first);
    std::printf("measured rate: RMSE ~ iterations^%.2f (the reference's own noise included)\n",
                rate);
    // Progressive photon mapping with α = 2/3 converges as N^(−1/3) (variance and bias² both
    // N^(−2/3)); the reference's noise flattens the curve at the end. The error must fall at
    // every step and by at least half of the asymptotic rate overall.
    for (size_t i = 1; i < errors.size(); ++i) EXPECT_LT(errors[i].second, errors[i - 1].second);
    EXPECT_LT(rate, -1.0 / 6.0);
}

// A spot light 0.2 m above a square mirror, pointing down: the only light on the diffuse ceiling
// 1 m up is the mirror's caustic, a square patch lit as by the light's mirror image 0.2 m below
// the mirror, with sharp edges and nothing outside. At max depth 2 the camera (looking up at the
// ceiling) sees exactly that level-1 estimate, whose expectation is known in closed form:
// L = (ρ/π)·I·cos θ/D² inside the patch, 0 outside (the mirror reflects all of it).
struct MirrorCausticOnACeiling {
    static constexpr float kMirrorHalf = 0.06f, kLightHeight = 0.2f, kCeiling = 1.0f;
    static constexpr float kAlbedo = 0.5f, kIntensity = 10.0f, kEyeHeight = 0.3f;
    static constexpr float kHalfView = 0.5f;
    static constexpr uint32_t kSize = 48;
    // The gather radius the tests hold fixed: 4 cm, about two pixels.
    static constexpr float kRadius = 0.04f;

    Scene scene;
    std::vector<double> expected;  // per pixel, the closed form averaged over 8×8 points of it
    std::vector<bool> inner;       // more than a radius and a pixel inside the patch

    MirrorCausticOnACeiling() : expected(kSize * kSize), inner(kSize * kSize) {
        addQuad(scene, glm::vec3(0.0f), glm::vec3(kMirrorHalf, 0, 0), glm::vec3(0, 0, -kMirrorHalf),
                addMaterial(scene, mirror()), true);
        addQuad(scene, glm::vec3(0.0f, kCeiling, 0.0f), glm::vec3(2.0f, 0, 0),
                glm::vec3(0, 0, 2.0f), addMaterial(scene, lambert(glm::vec3(kAlbedo))), true);
        PunctualLight spot = pointLight(glm::vec3(0.0f, kLightHeight, 0.0f), kIntensity, true);
        spot.type = LightType::Spot;
        spot.direction = glm::vec3(0.0f, -1.0f, 0.0f);
        spot.innerConeAngleRad = 0.7f;  // the mirror's corners are 0.40 rad off the axis
        spot.outerConeAngleRad = 0.75f;
        scene.lights.push_back(spot);
        const float tanHalf = kHalfView / (kCeiling - kEyeHeight);
        scene.cameras.push_back(lookAt(glm::vec3(0.0f, kEyeHeight, 0.0f),
                                       glm::vec3(0.0f, 1.0f, 0.0f), glm::vec3(0.0f, 0.0f, -1.0f),
                                       2.0f * std::atan(tanHalf)));
        // The scene is symmetric in x and z, so the camera's axis conventions do not matter.
        auto radianceAt = [&](float x, float z) {
            const float h = kLightHeight, H = kCeiling;
            if (std::abs(x) * h / (H + h) > kMirrorHalf || std::abs(z) * h / (H + h) > kMirrorHalf)
                return 0.0;
            const double d2 = double(x) * x + double(z) * z + double(H + h) * (H + h);
            return kAlbedo / kPi * kIntensity * (H + h) / (d2 * std::sqrt(d2));
        };
        const float edge = kMirrorHalf * (kCeiling + kLightHeight) / kLightHeight;
        const float pixel = 2.0f * kHalfView / kSize;
        for (uint32_t py = 0; py < kSize; ++py)
            for (uint32_t px = 0; px < kSize; ++px) {
                double sum = 0.0;
                for (int j = 0; j < 64; ++j) {
                    float a = ((px + (j % 8 + 0.5f) / 8.0f) / kSize * 2.0f - 1.0f) * kHalfView;
                    float b = ((py + (j / 8 + 0.5f) / 8.0f) / kSize * 2.0f - 1.0f) * kHalfView;
                    sum += radianceAt(a, b);
                }
                expected[py * kSize + px] = sum / 64.0;
                float cx = std::abs((px + 0.5f) / kSize * 2.0f - 1.0f) * kHalfView;
                float cy = std::abs((py + 0.5f) / kSize * 2.0f - 1.0f) * kHalfView;
                inner[py * kSize + px] = std::max(cx, cy) < edge - kRadius - pixel;
            }
    }

    // The camera's first hit takes the caustic (nothing else lights the ceiling), at a fixed
    // radius and no neighbour rule.
    static RenderSettings settings(bool splat) {
        RenderSettings rs = photonSettings(kSize, kSize, PhotonMode::Auto);
        rs.maxDepth = 2;
        rs.photons.perIteration = 1u << 14;
        rs.photons.initialRadius = kRadius;
        rs.photons.alpha = 1.0f;
        rs.photons.gatherNeighbours = 0;
        rs.photons.splatToCamera = splat;
        return rs;
    }

    struct Scores {
        std::vector<double> innerBias;  // per run: the inner pixels' mean error over their mean
        std::vector<double> innerSpread, mse;  // per run: inner RMS deviation, whole-image MSE
    };
    Scores score(const std::vector<ImageF>& images) const {
        Scores sc;
        double innerExpected = 0.0;
        size_t innerCount = 0;
        for (size_t i = 0; i < expected.size(); ++i)
            if (inner[i]) innerExpected += expected[i], ++innerCount;
        for (const ImageF& img : images) {
            double innerError = 0.0, innerSquares = 0.0, squares = 0.0;
            for (size_t i = 0; i < expected.size(); ++i) {
                const double e = double(img.pixels[3 * i + 1]) - expected[i];  // green
                squares += e * e;
                if (inner[i]) innerError += e, innerSquares += e * e;
            }
            sc.innerBias.push_back(innerError / innerExpected);
            sc.innerSpread.push_back(std::sqrt(innerSquares / double(innerCount)));
            sc.mse.push_back(squares / double(expected.size()));
        }
        return sc;
    }
};

// The gather (the camera sees the ceiling, but photons are not splatted): with the first radius
// large and fixed, the blur of the edges is most of the error. Where photons are dense a gather
// takes its estimate again at the radius that holds about photonGatherNeighbours of them
// (trace_paths.comp's gatherPhotons): inside the patch, where the density is nearly even, the
// estimate must keep its expectation; over the whole image, edges included, the error must fall.
TEST_F(PhotonTest, DenseGathersKeepTheDensityAndSharpenItsEdges) {
    const MirrorCausticOnACeiling c;
    const RenderSettings fixedRadius = MirrorCausticOnACeiling::settings(false);
    RenderSettings shrinking = fixedRadius;
    shrinking.photons.gatherNeighbours = 16;  // the patch holds about 90 photons per gather
    constexpr uint32_t kRuns = 4, kIterations = 16;
    using Scores = MirrorCausticOnACeiling::Scores;
    const Scores fixedScores = c.score(renders(c.scene, fixedRadius, kIterations, kRuns, 500));
    const Scores shrinkingScores = c.score(renders(c.scene, shrinking, kIterations, kRuns, 500));
    ASSERT_EQ(fixedScores.mse.size(), kRuns);
    ASSERT_EQ(shrinkingScores.mse.size(), kRuns);

    // Inside the patch both keep the closed form's mean: Student's t, 3 dof, two-sided 0.1 %
    // (12.9), plus the kernel's blur of the patch's curvature, r²/12·∇²E/E = −6·r²/(12·1.2²) =
    // −5.6e-4 at the centre for the fixed radius (less off the centre, and where it shrinks).
    // The shrinking estimate is noisier there: it did shrink.
    for (const Scores* sc : {&fixedScores, &shrinkingScores}) {
        auto [bias, biasVar] = meanAndVarianceOfMean(sc->innerBias);
        std::printf("inner patch: mean relative error %+.4f ± %.4f, per-pixel RMS %.4f\n", bias,
                    std::sqrt(biasVar), meanAndVarianceOfMean(sc->innerSpread).first);
        EXPECT_LT(std::abs(bias), 12.9 * std::sqrt(biasVar) + 6e-4);
    }
    EXPECT_GT(meanAndVarianceOfMean(shrinkingScores.innerSpread).first,
              1.2 * meanAndVarianceOfMean(fixedScores.innerSpread).first);
    // Over the whole image the sharper edges win; paired by seed (the same photons' positions
    // feed both), one-sided 0.1 % with 3 dof: 10.2.
    std::vector<double> gains;
    for (uint32_t i = 0; i < kRuns; ++i)
        gains.push_back(fixedScores.mse[i] - shrinkingScores.mse[i]);
    auto [gain, gainVar] = meanAndVarianceOfMean(gains);
    const double fixedMse = meanAndVarianceOfMean(fixedScores.mse).first;
    std::printf(
        "image RMSE against the closed form: fixed radius %.4f, shrinking where dense %.4f\n",
        std::sqrt(fixedMse), std::sqrt(fixedMse - gain));
    EXPECT_GT(gain, 10.2 * std::sqrt(gainVar));
}

// The same caustic splatted onto the pixels by the photon pass (trace_photons.comp's
// splatToCamera, the default): each photon goes to the pixel it lands in, weighted by the
// camera's change of variables, so the image is the closed form's box-filtered pixels with no
// kernel at all. Inside the patch the mean is the closed form's with no curvature term (the
// tolerance is the noise alone), and over the whole image, edges included, the error is below
// the gather's at the same photons (paired by seed: the photon pass draws the same photons).
TEST_F(PhotonTest, SplattedCausticsKeepTheClosedFormWithoutBlur) {
    const MirrorCausticOnACeiling c;
    constexpr uint32_t kRuns = 4, kIterations = 16;
    using Scores = MirrorCausticOnACeiling::Scores;
    const Scores gathered = c.score(
        renders(c.scene, MirrorCausticOnACeiling::settings(false), kIterations, kRuns, 500));
    const Scores splatted =
        c.score(renders(c.scene, MirrorCausticOnACeiling::settings(true), kIterations, kRuns, 500));
    ASSERT_EQ(gathered.mse.size(), kRuns);
    ASSERT_EQ(splatted.mse.size(), kRuns);
    auto [bias, biasVar] = meanAndVarianceOfMean(splatted.innerBias);
    std::printf("splatted inner patch: mean relative error %+.5f ± %.5f, per-pixel RMS %.4f\n",
                bias, std::sqrt(biasVar), meanAndVarianceOfMean(splatted.innerSpread).first);
    // Student's t, 3 dof, two-sided 0.1 %; the spread is not zero (photons are random).
    EXPECT_GT(biasVar, 0.0);
    EXPECT_LT(std::abs(bias), 12.9 * std::sqrt(biasVar));
    std::vector<double> gains;
    for (uint32_t i = 0; i < kRuns; ++i) gains.push_back(gathered.mse[i] - splatted.mse[i]);
    auto [gain, gainVar] = meanAndVarianceOfMean(gains);
    const double gatheredMse = meanAndVarianceOfMean(gathered.mse).first;
    std::printf("image RMSE against the closed form: gathered %.4f, splatted %.4f\n",
                std::sqrt(gatheredMse), std::sqrt(gatheredMse - gain));
    // One-sided 0.1 % with 3 dof.
    EXPECT_GT(gain, 10.2 * std::sqrt(gainVar));
}

// The differential identity with photons: when no photon path meets virtual geometry (the only
// virtual object is outside the closed real room), both maps hold the same photons and
// L_om − L_or is exactly 0 in every pixel — caustic included.
TEST_F(PhotonTest, NoVirtualObjectOnTheirPathGivesZeroDifferenceBitForBit) {
    Scene scene = glassBallInAWhiteRoom(true);
    uint32_t white = addMaterial(scene, lambert(glm::vec3(0.7f)));
    addBox(scene, glm::vec3(3.0f), glm::vec3(3.5f), white, false);  // virtual, outside the room
    std::unique_ptr<Renderer> renderer = differentialPhotonRenderer(scene, 8);
    ASSERT_TRUE(renderer);
    Renderer& r = *renderer;
    auto records = r.diagnostics().photonRecords();
    ASSERT_TRUE(records.ok());
    size_t both = 0, one = 0;
    for (const auto& rec : *records) {
        uint32_t s = rec.flags & (PV_PHOTON_IN_MIXED | PV_PHOTON_IN_REAL);
        both += s == (PV_PHOTON_IN_MIXED | PV_PHOTON_IN_REAL);
        one += s == PV_PHOTON_IN_MIXED || s == PV_PHOTON_IN_REAL;
    }
    EXPECT_GT(both, 1000u);
    EXPECT_EQ(one, 0u);
    auto mixed = r.image(Aov::Mixed);
    auto real = r.image(Aov::Real);
    ASSERT_TRUE(mixed.ok() && real.ok());
    ASSERT_EQ(mixed->pixels.size(), real->pixels.size());
    EXPECT_EQ(0, std::memcmp(mixed->pixels.data(), real->pixels.data(),
                             mixed->pixels.size() * sizeof(float)));
}

// The shaders specialised on the host (gpu/spirv_specialise.h) compute what the driver's own
// specialisation does: a differential render with photons (trace_paths, trace_photons and the
// photon grid's passes) gives the same mixed and real images and the same photon records, with
// constants other than the shader's defaults. LLVM
// may contract or reorder float operations differently in the two compiled forms, so the images
// agree to float rounding (measured: RMSE 1e-8 of a mean 0.29 on bench/scenes/caustics_glass),
// not always to the bit.
TEST_F(PhotonTest, HostSpecialisationMatchesTheDrivers) {
    const Scene scene = glassBallInAWhiteRoom(false);
    std::vector<float> images[2][2];
    size_t records[2] = {0, 0};
    const Specialise modes[2] = {Specialise::OnHost, Specialise::InDriver};
    for (int m = 0; m < 2; ++m) {
        RenderSettings rs = photonSettings(32, 24, PhotonMode::Auto);
        rs.differential = true;
        rs.photons.perIteration = 1u << 12;
        // Not the shader's default values: a constant the host failed to apply would show.
        rs.sampler = Sampler::Independent;
        rs.lightSampling = LightSampling::Area;
        std::unique_ptr<Renderer> renderer = photonRenderer(scene, rs, {.specialise = modes[m]});
        ASSERT_TRUE(renderer);
        ASSERT_TRUE(renderer->render(4).ok());
        auto stored = renderer->diagnostics().photonRecords();
        ASSERT_TRUE(stored.ok());
        for (const auto& rec : *stored) records[m] += rec.flags != 0;
        int a = 0;
        for (Aov aov : {Aov::Mixed, Aov::Real}) {
            auto image = renderer->image(aov);
            ASSERT_TRUE(image.ok());
            images[m][a++] = image->pixels;
        }
    }
    EXPECT_GT(records[0], 1000u);
    EXPECT_EQ(records[0], records[1]);
    for (int a = 0; a < 2; ++a) {
        ASSERT_EQ(images[0][a].size(), images[1][a].size());
        for (size_t i = 0; i < images[0][a].size(); ++i)
            ASSERT_NEAR(images[0][a][i], images[1][a][i],
                        1e-5f * std::max(1.0f, std::abs(images[1][a][i])))
                << (a ? "real" : "mixed") << " value " << i;
    }
}

// The grid the gather reads: every stored record of the iteration (and nothing else) lies in the
// range of its own bucket, exactly once; the ranges do not overlap; within a bucket the records
// keep photon order (the sort is stable, the compaction before it keeps record order), so the
// gather's subsampling window is the same on every run.
TEST_F(PhotonTest, GridHoldsEachStoredRecordOnceInItsBucketInPhotonOrder) {
    auto r = differentialPhotonRenderer(glassBallInAWhiteRoom(false), 2);
    ASSERT_TRUE(r);
    auto records = r->diagnostics().photonRecords();
    ASSERT_TRUE(records.ok()) << records.message();
    auto grid = r->diagnostics().photonGrid();
    ASSERT_TRUE(grid.ok()) << grid.message();
    // Trace order of each stored record, by its bits (position, power and direction make it
    // unique among one iteration's records).
    auto bitsOf = [](const shader::PhotonRecord& rec) {
        std::array<uint32_t, 8> b{};
        std::memcpy(b.data(), &rec, sizeof(rec));
        return b;
    };
    std::map<std::array<uint32_t, 8>, size_t> traceIndex;
    for (size_t i = 0; i < records->size(); ++i)
        if ((*records)[i].flags != 0) traceIndex.emplace(bitsOf((*records)[i]), i);
    ASSERT_GT(traceIndex.size(), 1000u);
    std::vector<bool> seen(records->size(), false);
    std::vector<glm::uvec2> ranges;
    size_t inRanges = 0;
    for (uint32_t bucket = 0; bucket < grid->buckets.size(); ++bucket) {
        const glm::uvec2 range = grid->buckets[bucket];
        if (range.y == range.x) continue;
        ASSERT_LT(range.x, range.y);
        ASSERT_LE(range.y, grid->sorted.size());
        ranges.push_back(range);
        size_t previous = 0;
        for (uint32_t k = range.x; k < range.y; ++k) {
            const shader::PhotonRecord& rec = grid->sorted[k];
            EXPECT_EQ(shader::photonBucket(
                          shader::photonCell(rec.position, shader::photonCellSize(grid->radius))),
                      bucket);
            auto it = traceIndex.find(bitsOf(rec));
            ASSERT_NE(it, traceIndex.end()) << "record " << k << " was not traced";
            EXPECT_FALSE(seen[it->second]) << "record " << it->second << " twice";
            seen[it->second] = true;
            if (k > range.x) {
                EXPECT_GT(it->second, previous) << "bucket " << bucket;
            }
            previous = it->second;
            ++inRanges;
        }
    }
    EXPECT_EQ(inRanges, traceIndex.size());
    std::sort(ranges.begin(), ranges.end(), [](glm::uvec2 a, glm::uvec2 b) { return a.x < b.x; });
    for (size_t i = 1; i < ranges.size(); ++i) EXPECT_LE(ranges[i - 1].y, ranges[i].x);
}

// A virtual glass ball on the real floor: its caustic and its shadow exist in the mixed solution
// only. The real solution has no specular object, so it holds no photon at all, and every mixed
// photon landed after passing the virtual ball.
TEST_F(PhotonTest, VirtualGlassBallCausticIsMixedOnly) {
    Scene scene;
    uint32_t white = addMaterial(scene, lambert(glm::vec3(0.7f)));
    uint32_t glassMat = addMaterial(scene, glass(1.5f));
    addQuad(scene, glm::vec3(0.0f), glm::vec3(2, 0, 0), glm::vec3(0, 0, -2), white, true);
    addSphere(scene, glm::vec3(0.0f, 0.3f, 0.0f), 0.2f, glassMat, false);
    scene.lights.push_back(pointLight(glm::vec3(0.0f, 1.5f, 0.0f), 20.0f, true));
    scene.cameras.push_back(
        lookAt(glm::vec3(0, 1.0f, 1.5f), glm::vec3(0, 0.1f, 0), glm::vec3(0, 1, 0), 1.0f));
    std::unique_ptr<Renderer> renderer = differentialPhotonRenderer(scene, 2);
    ASSERT_TRUE(renderer);
    auto records = renderer->diagnostics().photonRecords();
    ASSERT_TRUE(records.ok());
    size_t mixedOnly = 0, withReal = 0;
    for (const auto& rec : *records) {
        mixedOnly += rec.flags != 0 && (rec.flags & PV_PHOTON_IN_REAL) == 0;
        withReal += (rec.flags & PV_PHOTON_IN_REAL) != 0;
    }
    EXPECT_GT(mixedOnly, 1000u);
    EXPECT_EQ(withReal, 0u);
    // The point light's flux through the ball, focused below it: the floor under the ball is
    // brighter in the mixed solution than in the real one.
    EXPECT_GT(depositedPower(*records, PV_PHOTON_IN_MIXED),
              0.5 * 20.0 * 2.0 * kPi * (1.0 - std::sqrt(1.0 - 0.04 / 1.44)));
}

// A caustic seen from the other side of the surface it lands on: the mirror's patch on a rough,
// thin-walled glass pane in place of the ceiling, the camera above the pane looking down. The
// light reaches the camera through the pane's rough transmission, which the splat must evaluate
// from the camera's side of the surface, as the gather does (the photon's own side sees no
// transmission toward the eye). Image means over independent seeds, Welch's t against Student's
// t with 6 degrees of freedom, two-sided 0.1 % (5.96); and the light is there: the mean is many
// of its standard errors above zero.
TEST_F(PhotonTest, SplatsSeeATransmittedCausticFromBehind) {
    MirrorCausticOnACeiling c;
    Material pane = glass(1.5f);
    pane.roughness = 0.3f;
    pane.thinWalled = true;
    for (Material& m : c.scene.materials)
        if (m.metallic == 0.0f) m = pane;  // the ceiling (the mirror is the metal)
    c.scene.cameras[0] = lookAt(glm::vec3(0.0f, 1.7f, 0.0f), glm::vec3(0.0f, 0.0f, 0.0f),
                                glm::vec3(0.0f, 0.0f, -1.0f), 1.2f);
    constexpr uint32_t kRuns = 4, kIterations = 8;
    std::array<std::vector<double>, 2> means;  // gathered, splatted: per run
    for (bool splat : {false, true}) {
        for (const ImageF& img : renders(c.scene, MirrorCausticOnACeiling::settings(splat),
                                         kIterations, kRuns, splat ? 900 : 800)) {
            double sum = 0.0;
            for (size_t i = 1; i < img.pixels.size(); i += 3) sum += img.pixels[i];
            means[splat].push_back(sum / double(img.pixels.size() / 3));
        }
        ASSERT_EQ(means[splat].size(), kRuns);
    }
    auto [gathered, gatheredVar] = meanAndVarianceOfMean(means[0]);
    auto [splatted, splattedVar] = meanAndVarianceOfMean(means[1]);
    const double t = std::abs(splatted - gathered) / std::sqrt(gatheredVar + splattedVar);
    std::printf("seen through the pane: gathered %.5f ± %.5f, splatted %.5f ± %.5f, t %.2f\n",
                gathered, std::sqrt(gatheredVar), splatted, std::sqrt(splattedVar), t);
    EXPECT_GT(splatted, 20.0 * std::sqrt(splattedVar));
    EXPECT_LT(t, 5.96);
}

// Splats and gathers estimate the same light seen directly, in every image of a differential
// render with a plate: a real glass ball's caustic (both solutions), a virtual glass ball's
// (mixed only), and a virtual box that hides part of the real floor from the camera — its real
// light is in L_or, but not subtracted in the composite, whose first hit there is the box.
// Image means per image over independent seeds, Welch's t against Student's t with 10 degrees
// of freedom, two-sided 0.1 % (4.59).
TEST_F(PhotonTest, SplatsAndGathersAgreeInEverySolution) {
    Scene scene = glassBallInAWhiteRoom(true);
    addSphere(scene, glm::vec3(-0.45f, 0.15f, 0.3f), 0.15f, addMaterial(scene, glass(1.5f)), false);
    addBox(scene, glm::vec3(0.05f, 0.0f, 0.2f), glm::vec3(0.3f, 0.1f, 0.3f),
           addMaterial(scene, lambert(glm::vec3(0.5f))), false);
    constexpr uint32_t kWidth = 32, kHeight = 24, kRuns = 6, kIterations = 16;
    ImageF plate;
    plate.width = kWidth;
    plate.height = kHeight;
    plate.channels = 3;
    plate.pixels.assign(size_t(kWidth) * kHeight * 3, 0.25f);
    constexpr std::array<Aov, 3> kAovs = {Aov::Composite, Aov::Mixed, Aov::Real};
    constexpr std::array<const char*, 3> kNames = {"composite", "mixed", "real"};
    std::map<std::pair<bool, size_t>, std::vector<double>> means;  // (splat, image): per run
    for (bool splat : {false, true}) {
        RenderSettings rs = photonSettings(kWidth, kHeight, PhotonMode::Auto);
        rs.differential = true;
        rs.photons.perIteration = 1u << 14;
        rs.photons.splatToCamera = splat;
        std::unique_ptr<Renderer> renderer = photonRenderer(scene, rs);
        ASSERT_TRUE(renderer);
        Renderer& r = *renderer;
        ASSERT_TRUE(r.film().setPlate(plate, "test plate").ok());
        for (uint32_t run = 0; run < kRuns; ++run) {
            ASSERT_TRUE(r.reset().ok());
            r.setSeed(700 + run + (splat ? 100 : 0));
            ASSERT_TRUE(r.render(kIterations).ok());
            for (size_t k = 0; k < kAovs.size(); ++k) {
                auto image = r.image(kAovs[k]);
                ASSERT_TRUE(image.ok()) << image.message();
                double sum = 0.0;
                for (size_t i = 1; i < image->pixels.size(); i += 3) sum += image->pixels[i];
                means[{splat, k}].push_back(sum / double(image->pixels.size() / 3));
            }
        }
    }
    for (size_t k = 0; k < kAovs.size(); ++k) {
        auto [gathered, gatheredVar] = meanAndVarianceOfMean(means[{false, k}]);
        auto [splatted, splattedVar] = meanAndVarianceOfMean(means[{true, k}]);
        const double t = std::abs(splatted - gathered) / std::sqrt(gatheredVar + splattedVar);
        std::printf("%s: gathered %.5f ± %.5f, splatted %.5f ± %.5f, t %.2f\n", kNames[k], gathered,
                    std::sqrt(gatheredVar), splatted, std::sqrt(splattedVar), t);
        EXPECT_LT(t, 4.59) << kNames[k];
    }
}

// Preview's fixed random sequence holds with photons: every preview frame of an unchanged scene
// is the same to the bit, in one renderer and in a fresh one (the sort is stable and the gather's
// sums do not depend on the order of additions), and refining from it goes on converging.
TEST_F(CausticAgreementTest, PreviewFramesAreBitIdentical) {
    const Scene s = scene();
    const RenderSettings rs = previewSettings();
    auto frame = previewFrame;
    auto a = Renderer::create(ctx(), s, rs);
    auto b = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(a.ok() && b.ok());
    ASSERT_TRUE((*a)->photonsActive());
    std::vector<float> first = frame(**a);
    std::vector<float> again = frame(**a);
    std::vector<float> other = frame(**b);
    ASSERT_EQ(first.size(), size_t(48 * 36 * 3));
    EXPECT_EQ(0, std::memcmp(first.data(), again.data(), first.size() * sizeof(float)));
    EXPECT_EQ(0, std::memcmp(first.data(), other.data(), first.size() * sizeof(float)));
    // The preview budget was a budget: refinement traces its full count again.
    EXPECT_EQ((*a)->photonsPerIteration(), 1u << 15);
}

// A service's renderer runs each pass in parts, so that a stop waits for one part and not for a
// whole frame on a slow device (Renderer::setInterrupt). The parts must change nothing: the
// first frame (its first parts one workgroup row of paths and one group of photons, before any
// part was timed) and the next equal an uninterrupted renderer's bit for bit. Once the flag is
// set, a render ends with the interruption error and adds no samples.
TEST_F(CausticAgreementTest, PassesInPartsEqualWholePassesAndAStopEndsThem) {
    const Scene s = scene();
    const RenderSettings rs = previewSettings();
    auto whole = Renderer::create(ctx(), s, rs);
    auto parts = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(whole.ok() && parts.ok());
    ASSERT_TRUE((*parts)->photonsActive());
    std::atomic<bool> stop{false};
    (*parts)->setInterrupt(&stop);
    for (int f = 0; f < 2; ++f) {
        std::vector<float> a = previewFrame(**whole), b = previewFrame(**parts);
        ASSERT_EQ(a.size(), size_t(48 * 36 * 3));
        ASSERT_EQ(a.size(), b.size());
        EXPECT_EQ(0, std::memcmp(a.data(), b.data(), a.size() * sizeof(float))) << "frame " << f;
    }
    const uint64_t samples = (*parts)->samplesPerPixel();
    stop.store(true);
    Status stopped = (*parts)->render(4);
    ASSERT_FALSE(stopped.ok());
    EXPECT_EQ(stopped.message(), kDispatchInterrupted);
    EXPECT_EQ((*parts)->samplesPerPixel(), samples);
}

// The preview's photon budget is one of the dial's axes (render/quality_dial.h): setting it
// changes the frame (other photons are traced), measureDial sets it per point, and refinement
// keeps its own count.
TEST_F(CausticAgreementTest, PreviewPhotonBudgetIsADialAxis) {
    const Scene s = scene();
    RenderSettings rs = photonSettings(48, 36, PhotonMode::Auto);
    rs.photons.perIteration = 1u << 15;
    std::unique_ptr<Renderer> r = photonRenderer(s, rs);
    ASSERT_TRUE(r);
    Renderer& renderer = *r;
    ASSERT_TRUE(renderer.render(16).ok());
    auto reference = renderer.image();
    ASSERT_TRUE(reference.ok());
    DialAxes axes{{1.0f}, {1}, {4}, {}, {1024, 8192}};
    auto measured = measureDial(renderer, dialGrid(axes), *reference, 1);
    ASSERT_TRUE(measured.ok()) << measured.message();
    ASSERT_EQ(measured->size(), 2u);
    EXPECT_EQ((*measured)[0].point.photons, 1024u);
    EXPECT_EQ((*measured)[1].point.photons, 8192u);
    for (const DialMeasurement& m : *measured) {
        EXPECT_TRUE(std::isfinite(m.error) && m.error > 0.0);
        EXPECT_GT(m.frameSeconds, 0.0);
    }
    EXPECT_NE((*measured)[0].error, (*measured)[1].error);  // different photons, another frame
    EXPECT_EQ(renderer.photonsPerIteration(), 1u << 15);
    EXPECT_FALSE(renderer.setPreviewPhotons(0).ok());
}

// The default first radius keeps the expected photons in the first disc (∝ N·r²) whatever the
// photons per iteration N: 2.5 % of the aim radius at 32768, half that at four times as many,
// finite at the extremes. The renderer uses it for refinement's count and for a preview frame's
// budget; a radius the user gives is kept whatever the count.
TEST_F(CausticAgreementTest, TheDefaultFirstRadiusFollowsThePhotonsPerIteration) {
    EXPECT_FLOAT_EQ(defaultPhotonRadius(0.1f, 1u << 15), 0.1f * kDefaultRadiusFraction);
    EXPECT_FLOAT_EQ(defaultPhotonRadius(0.1f, 1u << 17), 0.5f * 0.1f * kDefaultRadiusFraction);
    for (uint32_t n : {1u, 128u, 5000u, 1u << 16, kMaxPhotonsPerIteration}) {
        const double r = defaultPhotonRadius(0.1f, n);
        EXPECT_TRUE(std::isfinite(r) && r > 0.0) << n;
        // To float rounding (the radius is a float).
        EXPECT_NEAR(double(n) * r * r / (double(1u << 15) * 0.0025 * 0.0025), 1.0, 1e-6) << n;
    }
    EXPECT_TRUE(std::isfinite(defaultPhotonRadius(0.1f, 0u)));

    const Scene s = scene();
    RenderSettings rs = previewSettings();  // refinement 32768 photons, preview 4096
    std::unique_ptr<Renderer> r = photonRenderer(s, rs);
    ASSERT_TRUE(r);
    const float aim = r->photonAim().radius;
    EXPECT_FLOAT_EQ(r->nextPhotonRadius(), defaultPhotonRadius(aim, 1u << 15));
    EXPECT_EQ(r->lastPhotonCount(), 0u);
    ASSERT_TRUE(r->renderPreviewFrame(1).ok());
    EXPECT_EQ(r->lastPhotonCount(), 4096u);
    EXPECT_FLOAT_EQ(r->lastPhotonRadius(), defaultPhotonRadius(aim, 4096));
    auto previewRecords =
        r->diagnostics().photonRecords();  // the preview iteration's, not refinement's
    ASSERT_TRUE(previewRecords.ok());
    EXPECT_EQ(previewRecords->size(), size_t(PV_PHOTON_RECORDS_PER_PHOTON) * 4096u);
    ASSERT_TRUE(r->reset().ok());
    ASSERT_TRUE(r->render(1).ok());
    EXPECT_EQ(r->lastPhotonCount(), 1u << 15);
    EXPECT_FLOAT_EQ(r->lastPhotonRadius(), defaultPhotonRadius(aim, 1u << 15));
    rs.photons.initialRadius = 0.004f;
    auto fixed = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(fixed.ok()) << fixed.message();
    EXPECT_FLOAT_EQ((*fixed)->nextPhotonRadius(), 0.004f);
}

// A polished chrome ball (roughness 0.05, below PV_CAUSTIC_ALPHA) on a white floor under an
// environment whose light is mostly one bright patch high up, as the demo's softbox: the ball
// throws the patch's caustic on the floor. Photons carry it (emitted from the environment map,
// reflected through the ball's narrow lobe: shared/photon_records.h), and the path tracer leaves
// out those paths, by its sampled directions and by light sampling at the ball alike; with the
// patch large enough for the path tracer to converge, the two must agree: the image means within
// the noise of both (Student's t, 10 degrees of freedom, two-sided 0.1 %: 4.59). The caustic is
// about 1 % of the image's mean: with the environment's photons carrying nothing the means
// differed by 14 standard errors (measured).
TEST_F(PhotonTest, AnEnvironmentsCausticThroughAPolishedBallEqualsPathTracing) {
    Scene s;
    const uint32_t floorMat = addMaterial(s, lambert(glm::vec3(0.7f)));
    Material chrome = mirror();
    chrome.roughness = 0.05f;
    const uint32_t chromeMat = addMaterial(s, chrome);
    addQuad(s, glm::vec3(0.0f), glm::vec3(1.0f, 0, 0), glm::vec3(0, 0, -1.0f), floorMat, true);
    addSphere(s, glm::vec3(0.0f, 0.3f, 0.0f), 0.2f, chromeMat, true);
    EnvironmentMap env = uniformEnvironment(glm::vec3(0.02f), 16, 8);
    for (uint32_t x : {3u, 4u}) env.radiance[1 * 16 + x] = glm::vec3(60.0f);  // 34–56° up
    s.environment = env;
    s.cameras.push_back(
        lookAt(glm::vec3(0, 1.4f, 1.3f), glm::vec3(0, 0.1f, 0), glm::vec3(0, 1, 0), 0.8f));
    RenderSettings pathOnly = photonSettings(32, 24, PhotonMode::Off);
    RenderSettings withPhotons = photonSettings(32, 24, PhotonMode::Auto);
    constexpr uint32_t kRuns = 6;
    const std::vector<ImageF> reference = renders(s, pathOnly, 1024, kRuns, 100);
    const std::vector<ImageF> photon = renders(s, withPhotons, 64, kRuns, 200);
    ASSERT_EQ(reference.size(), kRuns);
    ASSERT_EQ(photon.size(), kRuns);
    const MeanAgreement m = agreementOfMeans(photon, reference);
    EXPECT_LT(m.z, 4.59) << "photon+path mean " << m.meanA << ", path tracing " << m.meanB;
    // Not vacuous: the environment is the only light, and its photons land on the floor after
    // the ball, carrying a real share of the light there.
    std::unique_ptr<Renderer> r = photonRenderer(s, withPhotons);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->render(1).ok());
    auto records = r->diagnostics().photonRecords();
    ASSERT_TRUE(records.ok());
    EXPECT_GT(depositedPower(*records, PV_PHOTON_IN_MIXED), 0.01);
}

// Photons are aimed at a sphere around the specular triangles: for a glass ball it is the ball
// itself (every vertex on it), not the sphere around its bounding box (√3 times the radius, which
// would spend two thirds of the photons beside the ball); diffuse geometry does not widen it.
TEST(PhotonAimTest, TheAimSphereOfABallIsTheBall) {
    Scene scene;
    uint32_t white = addMaterial(scene, lambert(glm::vec3(0.7f)));
    addQuad(scene, glm::vec3(0.0f), glm::vec3(2, 0, 0), glm::vec3(0, 0, -2), white, true);
    uint32_t glassMat = addMaterial(scene, glass(1.5f));
    const glm::vec3 center(0.3f, 0.12f, -0.2f);
    addSphere(scene, center, 0.12f, glassMat, false, 24, 48);
    PhotonAim aim = photonAimFor(scene.geometry, scene.materials);
    ASSERT_TRUE(aim.any);
    EXPECT_NEAR(aim.radius, 0.12f, 0.12f * 2e-3f);
    EXPECT_LT(glm::length(aim.center - center), 1e-4f);
    EXPECT_GE(aim.sceneRadius, glm::length(glm::vec3(2.0f, 0.0f, 2.0f)));
    // Every specular vertex is inside (the bound holds every aimed triangle).
    for (size_t t = 0; t < scene.geometry.triangles.size(); ++t) {
        if (scene.geometry.triangleMaterials[t] != glassMat) continue;
        for (int k = 0; k < 3; ++k)
            EXPECT_LE(
                glm::length(scene.geometry.positions[scene.geometry.triangles[t][k]] - aim.center),
                aim.radius);
    }
}

// A polished mirror (roughness below 0.1) carries caustics and is aimed at; a rougher one, or
// one with a diffuse base, is not.
TEST(PhotonAimTest, PolishedMetalIsAimedAtRoughMetalIsNot) {
    auto aimOf = [](const Material& m) {
        Scene scene;
        addSphere(scene, glm::vec3(0.0f), 0.2f, addMaterial(scene, m), false);
        return photonAimFor(scene.geometry, scene.materials);
    };
    Material chrome = mirror();
    chrome.roughness = 0.03f;
    EXPECT_TRUE(aimOf(chrome).any);
    EXPECT_TRUE(mayCarryCaustics(chrome));
    chrome.roughness = 0.3f;
    EXPECT_FALSE(aimOf(chrome).any);
    Material varnish = lambert(glm::vec3(0.6f));
    varnish.roughness = 0.0f;
    varnish.specular = 1.0f;
    EXPECT_FALSE(mayCarryCaustics(varnish)) << "a diffuse base under the coat";
}

// The environment is a photon light when it has light: first in the table, real, picked in
// proportion to ∫ Le dω · π R² beside a punctual light's I · Ω.
TEST(PhotonLightsTest, TheEnvironmentIsAPhotonLight) {
    PhotonAim aim;
    aim.any = true;
    aim.center = glm::vec3(0.0f);
    aim.radius = 0.5f;
    aim.sceneRadius = 5.0f;
    shader::GpuLight point{};
    point.type = PV_LIGHT_POINT;
    point.position = glm::vec3(0.0f, 10.0f, 0.0f);
    point.intensity = glm::vec3(1.0f);
    const std::vector<shader::GpuLight> lights{point};
    const double environment = 2.0;  // ∫ Le dω in luminance
    const std::vector<glm::uvec4> table = buildPhotonLights(aim, {}, lights, environment);
    ASSERT_EQ(table.size(), 2u);
    EXPECT_EQ(table[0].x, PV_PHOTON_LIGHT_ENVIRONMENT | PV_PHOTON_LIGHT_REAL);
    EXPECT_EQ(table[1].x & 0xffu, PV_PHOTON_LIGHT_PUNCTUAL);
    const double envWeight = environment * kPi * 0.25;
    // The point light's Ω toward a sphere of radius 0.5 at distance 10.
    const double sin2 = 0.25 / 100.0;
    const double pointWeight = 2.0 * kPi * sin2 / (1.0 + std::sqrt(1.0 - sin2));
    float p0;
    std::memcpy(&p0, &table[0].w, sizeof(p0));
    EXPECT_NEAR(p0, envWeight / (envWeight + pointWeight), 1e-5);
    EXPECT_TRUE(buildPhotonLights(aim, {}, {}, 0.0).empty()) << "a black environment";
}

// The environment sends photons only where it has a lamp (a texel kEnvironmentLampRatio times
// its mean radiance): a uniform sky lights glass smoothly for the path tracer. Its power is
// ∫ Le dω over the texels' solid angles (a uniform map of radiance L: 4π L), times its scale.
TEST(PhotonLightsTest, OnlyAnEnvironmentWithALampSendsPhotons) {
    EnvironmentMap sky = uniformEnvironment(glm::vec3(0.5f), 64, 32);
    EXPECT_EQ(environmentPhotonLuminance(sky, buildEnvironmentDistribution(sky)), 0.0);
    EnvironmentMap lamp = sky;
    lamp.radiance[5 * 64 + 10] = glm::vec3(2000.0f);
    lamp.scale = 2.0f;
    const double texel = 2.0 * kPi * kPi / (64.0 * 32.0) * std::sin(kPi * 5.5 / 32.0);
    // The sum over rows of sin θ·(2π/W)(π/H) is 4π only to the rows' midpoint rule.
    double sphere = 0.0;
    for (int y = 0; y < 32; ++y)
        sphere += 64.0 * 2.0 * kPi * kPi / (64.0 * 32.0) * std::sin(kPi * (y + 0.5) / 32.0);
    EXPECT_NEAR(environmentPhotonLuminance(lamp, buildEnvironmentDistribution(lamp)),
                2.0 * (0.5 * sphere + (2000.0 - 0.5) * texel),
                1e-6 * environmentPhotonLuminance(lamp, buildEnvironmentDistribution(lamp)));
    EnvironmentMap dim = sky;
    dim.radiance[5 * 64 + 10] = glm::vec3(5.0f);  // 10× the mean: no lamp
    EXPECT_EQ(environmentPhotonLuminance(dim, buildEnvironmentDistribution(dim)), 0.0);
}

// The gather's BSDF is baseColor/π only where every surface photons may land on is Lambertian
// whatever its textures: smooth glass and untextured mirrors are passed through, anything
// glossy, or anything a texture could make glossy, keeps the BSDF per photon.
TEST(PhotonGatherTest, OnlyLambertianOrPurelySpecularMaterialsSkipTheBsdf) {
    EXPECT_FALSE(glossyMaterial(lambert(glm::vec3(0.7f))));
    EXPECT_FALSE(glossyMaterial(emitter(glm::vec3(5.0f))));
    EXPECT_FALSE(glossyMaterial(glass(1.5f)));
    EXPECT_FALSE(glossyMaterial(mirror()));
    Material textured = lambert(glm::vec3(0.7f));
    textured.baseColorTexture = 0;
    textured.metallicRoughnessTexture = 0;  // scales metalness 0: still Lambertian
    EXPECT_FALSE(glossyMaterial(textured));
    Material m = mirror();
    m.metallicRoughnessTexture = 0;  // may lower the metalness: a diffuse base shows
    EXPECT_TRUE(glossyMaterial(m));
    m = mirror();
    m.roughness = 0.3f;
    EXPECT_TRUE(glossyMaterial(m));
    m = glass(1.5f);
    m.roughness = 0.2f;
    EXPECT_TRUE(glossyMaterial(m));
    m = glass(1.5f);
    m.transmission = 0.5f;  // half the light meets a diffuse base
    EXPECT_TRUE(glossyMaterial(m));
    m = lambert(glm::vec3(0.7f));
    m.specular = 0.5f;  // a specular layer over the base
    EXPECT_TRUE(glossyMaterial(m));
}

// Where every gather vertex is Lambertian the gather applies baseColor/π once instead of the BSDF
// per photon: the same image as the general pipeline's (which evaluates it per photon), to float
// rounding, in both solutions; a glossy floor switches the per-photon BSDF back on.
TEST_F(PhotonTest, LambertianGathersMatchTheBsdfPerPhoton) {
    const Scene scene = glassBallInAWhiteRoom(false);
    std::vector<float> images[2][2];
    for (int general = 0; general < 2; ++general) {
        RenderSettings rs = photonSettings(32, 24, PhotonMode::Auto);
        rs.differential = true;
        rs.photons.perIteration = 1u << 12;
        auto renderer = Renderer::create(ctx(), scene, rs, {}, {.generalPipeline = general == 1});
        ASSERT_TRUE(renderer.ok()) << renderer.message();
        ASSERT_TRUE((*renderer)->photonsActive());
        EXPECT_FALSE((*renderer)->features().glossy);
        ASSERT_TRUE((*renderer)->render(4).ok());
        int a = 0;
        for (Aov aov : {Aov::Mixed, Aov::Real}) {
            auto image = (*renderer)->image(aov);
            ASSERT_TRUE(image.ok());
            images[general][a++] = image->pixels;
        }
    }
    double sum = 0.0;
    for (int a = 0; a < 2; ++a) {
        ASSERT_EQ(images[0][a].size(), images[1][a].size());
        for (size_t i = 0; i < images[0][a].size(); ++i) {
            ASSERT_NEAR(images[0][a][i], images[1][a][i],
                        1e-4f * std::max(1.0f, std::abs(images[1][a][i])))
                << (a ? "real" : "mixed") << " value " << i;
            sum += images[1][a][i];
        }
    }
    EXPECT_GT(sum, 0.0);
    Scene glossyFloor = scene;
    glossyFloor.materials[0].specular = 0.5f;
    RenderSettings rs = photonSettings(8, 8, PhotonMode::Auto);
    auto glossy = Renderer::create(ctx(), glossyFloor, rs);
    ASSERT_TRUE(glossy.ok()) << glossy.message();
    EXPECT_TRUE((*glossy)->features().glossy);
}

// A photon's direction numbers are stratified along a Z-order curve (shared/photon_records.h): over
// an iteration's N = 2^m photons every cell of the 2^k × 2^k grid (4^k ≥ N) is taken exactly
// once — by the cell-picking number's two halves where a photon's stretch is two cells — so the
// directions are uniform; the 8 photons of one SIMD batch lie within a 4 × 4-cell square; and
// a photon count that is not a power of two takes the sampler's own numbers.
TEST(PhotonDirectionTest, ZOrderStrataTakeEveryCellOnceAndKeepBatchesTogether) {
    for (uint32_t n : {128u, 256u, 32768u, 65536u}) {
        const uint32_t k = (uint32_t(std::log2(double(n))) + 1u) / 2u;
        const uint32_t side = 1u << k;
        const uint32_t perPhoton = side * side / n;
        std::vector<int> taken(size_t(side) * side, 0);
        for (uint32_t p = 0; p < n; ++p) {
            for (uint32_t half = 0; half < perPhoton; ++half) {
                const float pick = (float(half) + 0.5f) / float(perPhoton);
                const glm::vec2 u = shader::photonDirectionSample(p, n, glm::vec3(pick, 0.5f, 0.5f),
                                                                  glm::vec2(-1.0f));
                ASSERT_TRUE(u.x >= 0.0f && u.x < 1.0f && u.y >= 0.0f && u.y < 1.0f) << n;
                const auto x = uint32_t(u.x * float(side)), y = uint32_t(u.y * float(side));
                taken[size_t(y) * side + x] += 1;
            }
        }
        EXPECT_TRUE(std::all_of(taken.begin(), taken.end(), [](int t) { return t == 1; }))
            << n << " photons: a cell taken twice or never";
        // The last cell's far corner stays below 1 (a uniform number's range).
        const glm::vec2 corner =
            shader::photonDirectionSample(n - 1u, n, glm::vec3(0.9999f), glm::vec2(-1.0f));
        EXPECT_LT(std::max(corner.x, corner.y), 1.0f);
        for (uint32_t batch = 0; batch < n; batch += 8) {
            glm::vec2 lo(1.0f), hi(0.0f);
            for (uint32_t p = batch; p < batch + 8; ++p) {
                for (float pick : {0.0f, 0.9999f}) {
                    for (float c : {0.0f, 0.9999f}) {
                        const glm::vec2 u = shader::photonDirectionSample(
                            p, n, glm::vec3(pick, c, c), glm::vec2(-1.0f));
                        lo = glm::min(lo, u);
                        hi = glm::max(hi, u);
                    }
                }
            }
            ASSERT_LE(std::max(hi.x - lo.x, hi.y - lo.y), 4.0f / float(side))
                << n << " photons, batch " << batch;
        }
    }
    const glm::vec2 plain(0.25f, 0.75f);
    EXPECT_EQ(shader::photonDirectionSample(7u, 3u * 128u, glm::vec3(0.5f), plain), plain);
}

// Model only what the scene requires: no purely specular object (or no light) ⇒ no photon pass,
// no photon buffers; forcing it off turns it off; a bad photon setting is refused.
TEST_F(PhotonTest, OnlyScenesWithACausticRunPhotons) {
    Scene diffuse;
    uint32_t white = addMaterial(diffuse, lambert(glm::vec3(0.7f)));
    addQuad(diffuse, glm::vec3(0.0f), glm::vec3(1, 0, 0), glm::vec3(0, 0, -1), white, true);
    diffuse.lights.push_back(pointLight(glm::vec3(0, 1, 0), 5.0f, true));
    diffuse.cameras.push_back(lookAt(glm::vec3(0, 1, 1), glm::vec3(0), glm::vec3(0, 1, 0), 1.0f));
    auto plain = Renderer::create(ctx(), diffuse, photonSettings(8, 8, PhotonMode::Auto));
    ASSERT_TRUE(plain.ok());
    EXPECT_FALSE((*plain)->photonsActive());
    auto plainOff = Renderer::create(ctx(), diffuse, photonSettings(8, 8, PhotonMode::Off));
    ASSERT_TRUE(plainOff.ok());
    EXPECT_EQ((*plain)->deviceBytes(), (*plainOff)->deviceBytes());

    Scene caustic = diffuse;
    uint32_t glassMat = addMaterial(caustic, glass(1.5f));
    addSphere(caustic, glm::vec3(0, 0.3f, 0), 0.2f, glassMat, false, 8, 16);
    auto on = Renderer::create(ctx(), caustic, photonSettings(8, 8, PhotonMode::Auto));
    ASSERT_TRUE(on.ok());
    EXPECT_TRUE((*on)->photonsActive());
    EXPECT_GT((*on)->deviceBytes(), (*plain)->deviceBytes());
    auto off = Renderer::create(ctx(), caustic, photonSettings(8, 8, PhotonMode::Off));
    ASSERT_TRUE(off.ok());
    EXPECT_FALSE((*off)->photonsActive());

    Scene unlit = caustic;
    unlit.lights.clear();
    auto dark = Renderer::create(ctx(), unlit, photonSettings(8, 8, PhotonMode::Auto));
    ASSERT_TRUE(dark.ok());
    EXPECT_FALSE((*dark)->photonsActive());
    // An estimated light (the captured sun) makes the caustic possible: photons switch on.
    EstimatedLightSource sun;
    sun.direction = glm::vec3(0.2f, 1.0f, 0.1f);
    sun.solidAngleSr = 6.8e-5f;
    sun.radiance = glm::vec3(1e4f);
    // create() compiles the pipelines once, for the photon switch it predicts from the scene
    // before buildScene confirms it (renderer.cpp); the sun changes the switch: once more.
    for (const auto* r : {&plain, &plainOff, &on, &off, &dark})
        EXPECT_EQ((**r)->diagnostics().pipelineCompileCount(), 1u);
    ASSERT_TRUE((*dark)->setEstimatedLights(std::span(&sun, 1)).ok());
    EXPECT_TRUE((*dark)->photonsActive());
    // With the rest of a lighting snapshot, its environment: the features change twice, the
    // pipelines compile once, when the next render needs them.
    auto sky = std::make_shared<const EnvironmentMap>(uniformEnvironment(glm::vec3(0.5f)));
    ASSERT_TRUE((*dark)->setEnvironment(sky).ok());
    EXPECT_EQ((*dark)->diagnostics().pipelineCompileCount(), 1u);
    ASSERT_TRUE((*dark)->render(1).ok());
    EXPECT_EQ((*dark)->diagnostics().pipelineCompileCount(), 2u);
    // The next snapshot keeps the features: its buffers are bound, nothing compiles.
    sun.radiance = glm::vec3(2e4f);
    ASSERT_TRUE((*dark)->setEstimatedLights(std::span(&sun, 1)).ok());
    ASSERT_TRUE((*dark)->setEnvironment(sky).ok());
    ASSERT_TRUE((*dark)->render(1).ok());
    EXPECT_EQ((*dark)->diagnostics().pipelineCompileCount(), 2u);
    // An environment with a lamp in it (the set's softbox, radiance 2000 times the rest) sends
    // photons from the start: predicted, so create() compiles once.
    Scene lampLit = unlit;
    EnvironmentMap lamp = uniformEnvironment(glm::vec3(0.1f), 16, 8);
    lamp.radiance[2 * 16 + 5] = glm::vec3(200.0f);
    lampLit.environment = lamp;
    auto lampRenderer = Renderer::create(ctx(), lampLit, photonSettings(8, 8, PhotonMode::Auto));
    ASSERT_TRUE(lampRenderer.ok()) << lampRenderer.message();
    EXPECT_TRUE((*lampRenderer)->photonsActive());
    EXPECT_EQ((*lampRenderer)->diagnostics().pipelineCompileCount(), 1u);

    // A prediction buildScene refutes: the only light is an emitter of zero area, so no photon
    // leaves it. The pipelines are compiled again without photons and the render is the unlit
    // one (black), as from a scene without that emitter.
    Scene degenerate = unlit;
    const uint32_t glow = addMaterial(degenerate, emitter(glm::vec3(10.0f)));
    const glm::vec3 point(0, 1, 0);
    const glm::vec3 down(0, -1, 0);
    addMesh(degenerate, {point, point, point}, {down, down, down}, {glm::uvec3(0, 1, 2)}, glow,
            false);
    auto refuted = Renderer::create(ctx(), degenerate, photonSettings(8, 8, PhotonMode::Auto));
    ASSERT_TRUE(refuted.ok()) << refuted.message();
    EXPECT_FALSE((*refuted)->photonsActive());
    EXPECT_EQ((*refuted)->diagnostics().pipelineCompileCount(), 2u);
    ASSERT_TRUE((*refuted)->render(1).ok());
    auto black = (*refuted)->image(Aov::Mixed);
    ASSERT_TRUE(black.ok());
    for (float v : black->pixels) EXPECT_EQ(v, 0.0f);

    RenderSettings bad = photonSettings(8, 8, PhotonMode::On);
    bad.photons.alpha = 0.0f;
    EXPECT_FALSE(Renderer::create(ctx(), caustic, bad).ok());
    PhotonSettings parsed;
    EXPECT_TRUE(applyPhotonSpec("5000", parsed).ok());
    EXPECT_EQ(parsed.mode, PhotonMode::On);
    EXPECT_EQ(parsed.perIteration, 5000u);
    EXPECT_FALSE(applyPhotonSpec("many", parsed).ok());
    EXPECT_FALSE(applyPhotonSpec("0", parsed).ok());
}

}  // namespace
}  // namespace previs::testing
