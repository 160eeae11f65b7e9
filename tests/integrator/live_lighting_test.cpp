// Live lighting: a renderer whose environment, estimated lights or camera pose change between
// frames draws exactly what a renderer created with the new state draws (same seed, same
// samples: bit for bit), without rebuilding its scene; the cone lights that represent estimated
// light sources against closed-form answers; and the energy of a map split by the light
// estimator into lights and residual. Tolerances come from the noise each render measures.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"
#include "vision/lens_grid.h"
#include "vision/light_estimator.h"

namespace previs::testing {
namespace {

constexpr double kPi = 3.14159265358979323846;
// A mean over ~1000 nearly independent pixels is normal to good approximation; 5σ keeps a
// correct renderer green in all but one run in ~10⁶.
constexpr double kMeanZ = 5.0;

// NaN/Inf samples the renderer dropped (UINT32_MAX when it cannot tell).
uint32_t nonFinite(const Renderer& r) {
    auto n = r.nonFiniteSamples();
    return n.ok() ? *n : UINT32_MAX;
}

float radians(float deg) { return deg * float(kPi) / 180.0f; }

// An environment of `width`×`width/2` texels: a sky brightening toward the zenith, a darker
// ground, and a small bright lamp at (azimuthDeg, elevationDeg).
EnvironmentMap skyMap(uint32_t width, float azimuthDeg, float elevationDeg, glm::vec3 lamp) {
    EnvironmentMap map;
    map.path = "sky";
    map.width = width;
    map.height = width / 2;
    map.radiance.resize(size_t(map.width) * map.height);
    const float u0 = 0.5f + azimuthDeg / 360.0f;
    const float v0 = 0.5f - elevationDeg / 180.0f;
    for (uint32_t y = 0; y < map.height; ++y) {
        for (uint32_t x = 0; x < map.width; ++x) {
            float v = (y + 0.5f) / float(map.height);
            glm::vec3 c =
                v < 0.5f ? glm::vec3(0.4f, 0.6f, 1.0f) * (1.5f - v) : glm::vec3(0.3f, 0.25f, 0.2f);
            // Two by two texels around the lamp's direction.
            float du = std::abs((x + 0.5f) / float(map.width) - u0) * float(map.width);
            float dv = std::abs((y + 0.5f) / float(map.height) - v0) * float(map.height);
            if (du < 1.0f && dv < 1.0f) c = lamp;
            map.radiance[size_t(y) * map.width + x] = c;
        }
    }
    return map;
}

// A set: a real diffuse floor and a virtual sphere casting a shadow on it.
Scene liveSet() {
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 2}, {2, 0, 0}, addMaterial(s, lambert(glm::vec3(0.6f))), true);
    addSphere(s, {0, 0.3f, 0}, 0.3f, addMaterial(s, lambert(glm::vec3(0.2f, 0.5f, 0.8f))), false,
              16, 32);
    s.cameras.push_back(lookAt({0, 1.2f, 2}, {0, 0.2f, 0}, {0, 1, 0}, radians(45)));
    return s;
}

// The map most cases light the set with: 64 texels wide, a lamp of 300 at 30°, 40° up.
EnvironmentMap lampSky() { return skyMap(64, 30, 40, glm::vec3(300.0f)); }

// The set under lampSky().
Scene litSet() {
    Scene s = liveSet();
    s.environment = lampSky();
    return s;
}

RenderSettings smallSettings(bool differential = true) {
    RenderSettings rs = renderSettings(32, 32, 4);
    rs.seed = 7;
    rs.differential = differential;
    return rs;
}

std::vector<EstimatedLightSource> lightsA() {
    return {{{0.3f, 1.0f, 0.2f}, 0.01f, {200.0f, 180.0f, 150.0f}}};
}

std::vector<EstimatedLightSource> lightsB() {
    return {{{-0.5f, 0.8f, 0.1f}, 0.02f, {50.0f, 60.0f, 80.0f}},
            {{0.0f, 1.0f, 0.0f}, 0.3f, {2.0f, 2.0f, 2.0f}},
            {{0.7f, 0.3f, -0.6f}, 0.005f, {900.0f, 700.0f, 400.0f}}};
}

class LiveLightingTest : public GpuTest {
protected:
    std::unique_ptr<Renderer> make(const Scene& scene, const RenderSettings& rs) {
        auto r = Renderer::create(ctx(), scene, rs);
        EXPECT_TRUE(r.ok()) << r.message();
        return r ? std::move(r.value()) : nullptr;
    }

    // One preview frame (reset, the settings' seed) and all its AOVs, concatenated.
    std::vector<float> frame(Renderer& r, uint32_t spp) {
        Status s = r.renderPreviewFrame(spp);
        EXPECT_TRUE(s.ok()) << s.message();
        EXPECT_EQ(nonFinite(r), 0u);
        std::vector<float> all;
        for (Aov aov : {Aov::Composite, Aov::Mixed, Aov::Real, Aov::Mask}) {
            auto img = r.image(aov);
            EXPECT_TRUE(img.ok()) << img.message();
            if (img) all.insert(all.end(), img->pixels.begin(), img->pixels.end());
        }
        return all;
    }

    static bool identical(const std::vector<float>& a, const std::vector<float>& b) {
        return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * 4) == 0;
    }
};

constexpr uint32_t kSpp = 4;

// (1) Switching A → B (same size: an upload; another size: new buffers) draws what a renderer
// created with B draws, and never rebuilds the BVH or the geometry.
TEST_F(LiveLightingTest, EnvironmentSwitchMatchesFreshRenderer) {
    Scene s = litSet();
    auto live = make(s, smallSettings());
    ASSERT_TRUE(live);
    const auto* nodes = live->bvh().nodes.data();
    std::vector<float> first = frame(*live, kSpp);

    for (uint32_t width : {64u, 128u}) {
        auto b = std::make_shared<const EnvironmentMap>(skyMap(width, -100, 20, {50, 40, 30}));
        ASSERT_TRUE(live->setEnvironment(b).ok());
        std::vector<float> switched = frame(*live, kSpp);
        Scene withB = s;
        withB.environment = *b;
        auto fresh = make(withB, smallSettings());
        ASSERT_TRUE(fresh);
        EXPECT_TRUE(identical(switched, frame(*fresh, kSpp))) << "map width " << width;
        EXPECT_FALSE(identical(switched, first)) << "the new map changed nothing";
    }
    EXPECT_EQ(live->diagnostics().sceneBuildCount(), 1u);
    EXPECT_EQ(live->bvh().nodes.data(), nodes);
}

TEST_F(LiveLightingTest, EstimatedLightSwitchMatchesFreshRenderer) {
    Scene s = liveSet();
    // The scene's own light stays through every switch.
    s.lights.push_back(pointLight({1, 2, 1}, 3.0f, /*real=*/true));
    auto live = make(s, smallSettings());
    ASSERT_TRUE(live);
    ASSERT_TRUE(live->setEstimatedLights(lightsA()).ok());
    std::vector<float> withA = frame(*live, kSpp);

    // A count change (new buffer), then a same-count change (an upload).
    std::vector<EstimatedLightSource> b = lightsB();
    std::vector<EstimatedLightSource> b2 = lightsB();
    b2[1].radiance = glm::vec3(5.0f, 1.0f, 1.0f);
    for (const auto& next : {b, b2}) {
        ASSERT_TRUE(live->setEstimatedLights(next).ok());
        std::vector<float> switched = frame(*live, kSpp);
        auto fresh = make(s, smallSettings());
        ASSERT_TRUE(fresh);
        ASSERT_TRUE(fresh->setEstimatedLights(next).ok());
        EXPECT_TRUE(identical(switched, frame(*fresh, kSpp)));
        EXPECT_FALSE(identical(switched, withA));
    }
    EXPECT_EQ(live->diagnostics().sceneBuildCount(), 1u);
}

// (2) An environment or lights appearing re-specialise the pipeline: the result is the fresh
// renderer's.
TEST_F(LiveLightingTest, LightingAppearingMatchesFreshRenderer) {
    Scene dark = liveSet();
    auto live = make(dark, smallSettings());
    ASSERT_TRUE(live);
    EXPECT_FALSE(live->features().environment);
    EXPECT_FALSE(live->features().coneLights);
    frame(*live, kSpp);

    auto map = std::make_shared<const EnvironmentMap>(lampSky());
    ASSERT_TRUE(live->setEnvironment(map).ok());
    EXPECT_TRUE(live->features().environment);
    Scene lit = dark;
    lit.environment = *map;
    auto fresh = make(lit, smallSettings());
    ASSERT_TRUE(fresh);
    EXPECT_TRUE(identical(frame(*live, kSpp), frame(*fresh, kSpp)));

    ASSERT_TRUE(live->setEstimatedLights(lightsA()).ok());
    EXPECT_TRUE(live->features().coneLights);
    ASSERT_TRUE(fresh->setEstimatedLights(lightsA()).ok());
    auto fresher = make(lit, smallSettings());
    ASSERT_TRUE(fresher);
    ASSERT_TRUE(fresher->setEstimatedLights(lightsA()).ok());
    std::vector<float> liveFrame = frame(*live, kSpp);
    EXPECT_TRUE(identical(liveFrame, frame(*fresher, kSpp)));
    EXPECT_EQ(live->diagnostics().sceneBuildCount(), 1u);
}

// (3) Removing them gives the renderer that never had them (and its pipeline runs none of it).
TEST_F(LiveLightingTest, LightingRemovedMatchesFreshRenderer) {
    Scene lit = litSet();
    auto live = make(lit, smallSettings());
    ASSERT_TRUE(live);
    ASSERT_TRUE(live->setEstimatedLights(lightsB()).ok());
    frame(*live, kSpp);

    ASSERT_TRUE(live->setEnvironment(nullptr).ok());
    ASSERT_TRUE(live->setEstimatedLights({}).ok());
    EXPECT_FALSE(live->features().environment);
    EXPECT_FALSE(live->features().coneLights);
    Scene dark = liveSet();
    auto fresh = make(dark, smallSettings());
    ASSERT_TRUE(fresh);
    std::vector<float> removed = frame(*live, kSpp);
    EXPECT_TRUE(identical(removed, frame(*fresh, kSpp)));
    // An empty map removes it too.
    ASSERT_TRUE(live->setEnvironment(std::make_shared<const EnvironmentMap>()).ok());
    EXPECT_TRUE(identical(frame(*live, kSpp), removed));
    EXPECT_EQ(live->diagnostics().sceneBuildCount(), 1u);
}

TEST_F(LiveLightingTest, RejectsBadInputWithoutChangingTheRender) {
    Scene lit = litSet();
    auto live = make(lit, smallSettings());
    ASSERT_TRUE(live);
    std::vector<float> before = frame(*live, kSpp);
    EnvironmentMap broken = skyMap(64, 0, 0, glm::vec3(1.0f));
    broken.radiance.pop_back();
    EXPECT_FALSE(live->setEnvironment(std::make_shared<const EnvironmentMap>(broken)).ok());
    std::vector<EstimatedLightSource> bad = lightsA();
    bad[0].solidAngleSr = 0.0f;
    EXPECT_FALSE(live->setEstimatedLights(bad).ok());
    bad = lightsA();
    bad[0].radiance.g = std::nanf("");
    EXPECT_FALSE(live->setEstimatedLights(bad).ok());
    EXPECT_TRUE(identical(frame(*live, kSpp), before));
    // NaN texels (a bad camera frame) become black instead of poisoning the image.
    EnvironmentMap nanMap = lampSky();
    nanMap.radiance[100] = glm::vec3(std::nanf(""), -1.0f, INFINITY);
    ASSERT_TRUE(live->setEnvironment(std::make_shared<const EnvironmentMap>(nanMap)).ok());
    frame(*live, kSpp);  // checks that no sample is NaN
}

// The tracked pose moves the camera between preview frames, through a calibrated lens grid and
// in differential mode, exactly as a renderer created at the new pose; the scene stays built.
TEST_F(LiveLightingTest, CameraPoseChangeMatchesFreshRenderer) {
    Scene s = litSet();
    RenderSettings rs = smallSettings(true);
    double fy = 0.5 * rs.height / std::tan(0.5 * s.cameras[0].fovYRad);
    cv::Matx33d k(fy, 0, 0.5 * rs.width - 0.5, 0, fy, 0.5 * rs.height - 0.5, 0, 0, 1);
    auto calib = CameraCalibration::create(k, {-0.2, 0.05, 0.0, 0.0, 0.0},
                                           cv::Size(int(rs.width), int(rs.height)),
                                           DistortionModel::Pinhole, "test");
    ASSERT_TRUE(calib.ok()) << calib.message();
    auto grid = lensRayGrid(*calib, rs.width, rs.height);
    ASSERT_TRUE(grid.ok()) << grid.message();
    rs.lensGrid = *grid;

    auto live = make(s, rs);
    ASSERT_TRUE(live);
    std::vector<float> first = frame(*live, kSpp);
    Camera moved = lookAt({0.8f, 0.9f, 1.6f}, {0, 0.1f, 0}, {0, 1, 0}, s.cameras[0].fovYRad);
    live->setCameraPose(moved.worldFromCamera);
    std::vector<float> after = frame(*live, kSpp);
    Scene atB = s;
    atB.cameras[0].worldFromCamera = moved.worldFromCamera;
    auto fresh = make(atB, rs);
    ASSERT_TRUE(fresh);
    EXPECT_TRUE(identical(after, frame(*fresh, kSpp)));
    EXPECT_FALSE(identical(after, first));
    EXPECT_EQ(live->diagnostics().sceneBuildCount(), 1u);
}

// A large diffuse floor seen from straight above: every pixel shows the floor's centre region,
// lit by distant light only (max depth 1), so all pixels estimate the same radiance.
Scene floorFromAbove(float albedo) {
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 4}, {4, 0, 0}, addMaterial(s, lambert(glm::vec3(albedo))), true);
    s.cameras.push_back(lookAt({0, 1, 0}, {0, 0, 0}, {0, 0, -1}, radians(20)));
    return s;
}

// Mean of channel 0 over the pixels and its standard error from their spread.
struct PixelMean {
    double mean;
    double stdErr;
};

PixelMean pixelMean(const ImageF& img, int channel) {
    size_t n = size_t(img.width) * img.height;
    double sum = 0.0, sum2 = 0.0;
    for (size_t i = 0; i < n; ++i) {
        double v = img.pixels[i * img.channels + channel];
        sum += v;
        sum2 += v * v;
    }
    double mean = sum / n;
    double var = std::max(0.0, (sum2 - n * mean * mean) / double(n - 1));
    return {mean, std::sqrt(var / n)};
}

// (4) A Lambertian floor of albedo ρ under one cone light of radiance L and half-angle θ
// overhead: irradiance πL·sin²θ, outgoing radiance ρ·L·sin²θ exactly. For the wide cone this
// differs from the directional approximation ρ/π·L·Ω by 7%, which the test resolves.
TEST_F(LiveLightingTest, ConeLightOnLambertianFloorIsExact) {
    const float albedo = 0.5f;
    Scene s = floorFromAbove(albedo);
    RenderSettings rs = smallSettings(false);
    rs.maxDepth = 1;
    auto r = make(s, rs);
    ASSERT_TRUE(r);
    struct Case {
        double solidAngleSr;
        float radiance;
    };
    // A texel-sized cone (cos θmax rounds to 1 in float), a lamp, and a 30° half-angle cone.
    const double wideSr = 2.0 * kPi * (1.0 - std::cos(kPi / 6));
    for (Case c : {Case{1e-4, 1e4f}, Case{0.05, 20.0f}, Case{wideSr, 2.0f}}) {
        EstimatedLightSource light{
            {0.0f, 1.0f, 0.0f}, float(c.solidAngleSr), glm::vec3(c.radiance)};
        ASSERT_TRUE(r->setEstimatedLights(std::span(&light, 1)).ok());
        ASSERT_TRUE(r->renderPreviewFrame(64).ok());
        ASSERT_EQ(nonFinite(*r), 0u);
        auto img = r->image(Aov::Mixed);
        ASSERT_TRUE(img.ok());
        double oneMinusCos = c.solidAngleSr / (2.0 * kPi);
        double sin2 = oneMinusCos * (2.0 - oneMinusCos);
        double expected = albedo * c.radiance * sin2;
        double directional = albedo / kPi * c.radiance * c.solidAngleSr;
        PixelMean m = pixelMean(*img, 0);
        // Float accumulation of ~2000 samples per pixel mean: relative rounding well below 1e-5.
        double tolerance = kMeanZ * m.stdErr + 1e-5 * expected;
        std::printf("cone %.4g sr: measured %.6g ± %.2g, exact %.6g, directional %.6g\n",
                    c.solidAngleSr, m.mean, m.stdErr, expected, directional);
        EXPECT_NEAR(m.mean, expected, tolerance) << "solid angle " << c.solidAngleSr;
        if (c.solidAngleSr > 1.0) {
            EXPECT_GT(std::abs(directional - expected), 2.0 * tolerance)
                << "the test cannot tell a cone from a directional light";
        }
    }
}

// Estimated lights are real: with only the real set in view both solutions see them alike, so
// the differential composite L_om − L_or is exactly 0 where no virtual object is.
TEST_F(LiveLightingTest, EstimatedLightsLightBothSolutions) {
    Scene s = floorFromAbove(0.5f);
    RenderSettings rs = smallSettings(true);
    rs.maxDepth = 2;
    auto r = make(s, rs);
    ASSERT_TRUE(r);
    ASSERT_TRUE(r->setEstimatedLights(lightsB()).ok());
    ASSERT_TRUE(r->renderPreviewFrame(8).ok());
    ImageF mixed = r->image(Aov::Mixed).value();
    ImageF real = r->image(Aov::Real).value();
    EXPECT_EQ(std::memcmp(mixed.pixels.data(), real.pixels.data(), mixed.pixels.size() * 4), 0);
    EXPECT_GT(pixelMean(mixed, 0).mean, 0.0);
}

// Irradiance on an upward plane from a map: Σ L·∫cosθ dω over the texels of the upper
// hemisphere, with the exact integral per texel (θ from the zenith: ½Δφ·(sin²θ₁ − sin²θ₀)).
double upwardIrradiance(const EnvironmentMap& map, int channel) {
    double e = 0.0;
    double dPhi = 2.0 * kPi / map.width;
    for (uint32_t y = 0; y < map.height / 2; ++y) {
        double t0 = kPi * y / map.height;
        double t1 = kPi * (y + 1) / map.height;
        double w = 0.5 * dPhi * (std::pow(std::sin(t1), 2) - std::pow(std::sin(t0), 2));
        for (uint32_t x = 0; x < map.width; ++x)
            e += w * map.radiance[size_t(y) * map.width + x][channel];
    }
    return e;
}

// (5) The light estimator splits a map into lights and a residual conserving energy; rendered
// as cone lights plus the residual environment, a diffuse floor gets the same radiance as under
// the whole map, and both agree with the map's exact irradiance.
TEST_F(LiveLightingTest, LightsPlusResidualKeepTheMapsEnergy) {
    const float albedo = 0.7f;
    EnvironmentMap map = skyMap(128, 40, 55, glm::vec3(3000.0f, 2500.0f, 2000.0f));
    auto split = LightEstimator().estimate(environmentMapToMat(map));
    ASSERT_TRUE(split.ok()) << split.message();
    ASSERT_EQ(split->lights.size(), 1u);
    std::vector<EstimatedLightSource> lights;
    for (const EstimatedLight& l : split->lights)
        lights.push_back({glm::vec3(l.direction[0], l.direction[1], l.direction[2]),
                          float(l.solidAngleSr),
                          glm::vec3(l.radiance[0], l.radiance[1], l.radiance[2])});
    auto residual =
        std::make_shared<EnvironmentMap>(matToEnvironmentMap(split->residual, "residual"));

    Scene s = floorFromAbove(albedo);
    s.environment = map;
    RenderSettings rs = smallSettings(false);
    rs.maxDepth = 1;
    auto r = make(s, rs);
    ASSERT_TRUE(r);
    const uint32_t spp = 128;
    ASSERT_TRUE(r->renderPreviewFrame(spp).ok());
    ImageF whole = r->image(Aov::Mixed).value();
    ASSERT_TRUE(r->setEnvironment(residual).ok());
    ASSERT_TRUE(r->setEstimatedLights(lights).ok());
    // Another random sequence: the two estimates are independent.
    ASSERT_TRUE(r->reset().ok());
    r->setSeed(99);
    ASSERT_TRUE(r->render(spp).ok());
    ImageF parts = r->image(Aov::Mixed).value();
    ASSERT_EQ(nonFinite(*r), 0u);
    for (int c = 0; c < 3; ++c) {
        PixelMean a = pixelMean(whole, c);
        PixelMean b = pixelMean(parts, c);
        double exact = albedo / kPi * upwardIrradiance(map, c);
        std::printf(
            "channel %d: whole map %.6g ± %.2g, lights + residual %.6g ± %.2g, "
            "exact %.6g\n",
            c, a.mean, a.stdErr, b.mean, b.stdErr, exact);
        EXPECT_NEAR(a.mean, b.mean, kMeanZ * std::hypot(a.stdErr, b.stdErr)) << "channel " << c;
        EXPECT_NEAR(a.mean, exact, kMeanZ * a.stdErr + 1e-5 * exact) << "channel " << c;
    }
}

// What a fisheye snapshot costs the render thread, against building the renderer anew (printed
// for the report; the bound asserted is only that nothing is rebuilt).
TEST_F(LiveLightingTest, SetEnvironmentCostAgainstCreate) {
    Scene s = liveSet();
    s.environment = skyMap(512, 30, 40, glm::vec3(300.0f));
    using Clock = std::chrono::steady_clock;
    auto t0 = Clock::now();
    auto r = make(s, smallSettings());
    double createMs = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    ASSERT_TRUE(r);
    auto next = std::make_shared<const EnvironmentMap>(skyMap(512, -60, 25, glm::vec3(100.0f)));
    t0 = Clock::now();
    ASSERT_TRUE(r->setEnvironment(next).ok());
    double setMs = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    std::printf("512x256 map: setEnvironment %.2f ms, Renderer::create %.2f ms\n", setMs, createMs);
    RecordProperty("setEnvironmentMs", std::to_string(setMs));
    RecordProperty("createMs", std::to_string(createMs));
    EXPECT_EQ(r->diagnostics().sceneBuildCount(), 1u);
}

}  // namespace
}  // namespace previs::testing
