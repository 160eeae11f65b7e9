// Differential rendering (the paper's Eq. 1 and four ray types): identities that must hold
// exactly, agreement with independent renders within the measured noise, and the effects a
// virtual object has on the real set. Seeds are fixed; tolerances come from measured variances.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <glm/gtc/matrix_transform.hpp>
#include <random>

#include "render/tonemap.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/images.h"
#include "tests/support/scene_builders.h"
#include "vision/inverse_tone_map.h"
#include "vision/lens_grid.h"

namespace previs::testing {
namespace {

constexpr float kPi = 3.14159265358979f;
// As in integrator_test.cpp: Student's t with 15 dof, Šidák-corrected 1% over ~1000 pixels.
constexpr int kRuns = 16;
constexpr double kPixelT = 6.6;
// Photons an iteration where a mirror ball switches them on (PhotonMode::Auto) in the estimates
// below: at the default 65536 a 20x20 run of 8 samples traced 524288 photons for its 3200 camera
// paths. Each identity compares renders made with the same photon settings and each t-test's
// sigma is measured from its runs, so fewer photons only widen the measured noise.
constexpr uint32_t kPhotonsPerIteration = 8192;

// The image of a render result (failing the test on an error).
ImageF take(Result<ImageF> result) {
    if (!result.ok()) {
        ADD_FAILURE() << result.message();
        return {};
    }
    ImageF image = std::move(result).value();
    return image;
}

class DifferentialTest : public GpuTest {
protected:
    struct AovEstimate {
        std::vector<double> mean[4];  // indexed by Aov
        std::vector<double> var[4];   // variance of the mean
    };

    // Means and variances of every AOV over kRuns independent runs of one renderer.
    AovEstimate estimateAovs(const Scene& scene, RenderSettings rs, const ImageF* plate,
                             uint32_t spp, int runs = kRuns) {
        AovEstimate e;
        auto renderer = Renderer::create(ctx(), scene, rs);
        EXPECT_TRUE(renderer.ok()) << renderer.message();
        if (!renderer) return e;
        Renderer& r = **renderer;
        if (plate) {
            EXPECT_TRUE(r.film().setPlate(*plate).ok());
        }
        std::vector<double> sum[4], sum2[4];
        for (int run = 0; run < runs; ++run) {
            EXPECT_TRUE(r.reset().ok());
            r.setSeed(uint32_t(5000 + run));
            EXPECT_TRUE(r.render(spp).ok());
            EXPECT_EQ(r.nonFiniteSamples().value(), 0u);
            for (int a = 0; a < 4; ++a) {
                ImageF img = take(r.image(Aov(a)));
                sum[a].resize(img.pixels.size(), 0.0);
                sum2[a].resize(img.pixels.size(), 0.0);
                for (size_t i = 0; i < img.pixels.size(); ++i) {
                    sum[a][i] += img.pixels[i];
                    sum2[a][i] += double(img.pixels[i]) * img.pixels[i];
                }
            }
        }
        for (int a = 0; a < 4; ++a) {
            e.mean[a].resize(sum[a].size());
            e.var[a].resize(sum[a].size());
            for (size_t i = 0; i < sum[a].size(); ++i) {
                double m = sum[a][i] / runs;
                e.mean[a][i] = m;
                e.var[a][i] = std::max(0.0, (sum2[a][i] - runs * m * m) / (runs - 1)) / runs;
            }
        }
        return e;
    }
};

RenderSettings differentialSettings(uint32_t w, uint32_t h) {
    RenderSettings rs = renderSettings(w, h, 6);
    rs.differential = true;
    return rs;
}

// The set: a real table top and a real red box under a real sun and sky, seen from above.
Scene realSet() { return realTableUnderSun(/*withSky=*/true); }

ImageF hdrPlate(uint32_t w, uint32_t h) {
    ImageF p = filledImage(w, h, 3);
    std::mt19937 rng(42);
    std::uniform_real_distribution<float> logv(-4.0f, 5.0f);
    for (float& v : p.pixels) v = std::pow(10.0f, logv(rng));
    return p;
}

// Without virtual objects every path is shared: L_om − L_or is exactly zero, so the composite is
// the plate bit for bit, at any sample count.
TEST_F(DifferentialTest, NoVirtualObjectsGivesThePlateBitForBit) {
    Scene s = realSet();
    RenderSettings rs = differentialSettings(24, 24);
    ImageF plate = hdrPlate(rs.width, rs.height);
    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    ASSERT_TRUE((*renderer)->film().setPlate(plate).ok());
    for (uint32_t spp : {1u, 3u, 17u}) {
        ASSERT_TRUE((*renderer)->reset().ok());
        ASSERT_TRUE((*renderer)->render(spp).ok());
        ImageF composite = take((*renderer)->image(Aov::Composite));
        ASSERT_EQ(composite.pixels.size(), plate.pixels.size());
        EXPECT_EQ(std::memcmp(composite.pixels.data(), plate.pixels.data(),
                              plate.pixels.size() * sizeof(float)),
                  0)
            << "at " << spp << " spp";
        ImageF mask = take((*renderer)->image(Aov::Mask));
        for (float m : mask.pixels) ASSERT_EQ(m, 0.0f);
    }
}

// An 8-bit plate survives inverse tone mapping, compositing and tone mapping within one step.
TEST_F(DifferentialTest, LdrPlateRoundTripsWithinOneStep) {
    Scene s = realSet();
    RenderSettings rs = differentialSettings(16, 16);
    ImageF codes;
    codes.width = rs.width;
    codes.height = rs.height;
    codes.channels = 3;
    codes.ldrSrgb = true;
    for (size_t i = 0; i < size_t(rs.width) * rs.height * 3; ++i)
        codes.pixels.push_back(float(i % 256) / 255.0f);
    ImageF plate = inverseToneMap(codes, InverseToneMapSettings{});
    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok());
    ASSERT_TRUE((*renderer)->film().setPlate(plate).ok());
    ASSERT_TRUE((*renderer)->render(4).ok());
    ImageF composite = take((*renderer)->image());
    std::vector<uint8_t> out = toneMapToSrgb8(composite, ToneMapSettings{});
    for (size_t i = 0; i < out.size(); ++i)
        ASSERT_LE(std::abs(int(out[i]) - int(std::lround(codes.pixels[i] * 255.0f))), 1) << i;
}

// Scene `s` with only its real triangles and lights: what the real-only solution renders.
Scene realOnly(const Scene& s) {
    Scene r = s;
    r.geometry.triangles.clear();
    r.geometry.triangleMaterials.clear();
    r.geometry.triangleIsReal.clear();
    for (size_t i = 0; i < s.geometry.triangles.size(); ++i) {
        if (!s.geometry.triangleIsReal[i]) continue;
        r.geometry.triangles.push_back(s.geometry.triangles[i]);
        r.geometry.triangleMaterials.push_back(s.geometry.triangleMaterials[i]);
        r.geometry.triangleIsReal.push_back(1);
    }
    r.lights.clear();
    for (const auto& l : s.lights)
        if (l.isReal) r.lights.push_back(l);
    return r;
}

Scene setWithVirtualObjects() {
    Scene s = realSet();
    addSphere(s, {0.3f, 0.35f, 0.0f}, 0.25f, addMaterial(s, lambert(glm::vec3(0.1f, 0.8f, 0.2f))),
              false, 16, 32);
    addSphere(s, {-0.2f, 0.2f, 0.5f}, 0.2f, addMaterial(s, mirror()), false, 16, 32);
    // A virtual (artistic) light: it lights the mixed solution only.
    s.lights.push_back(pointLight({0.5f, 1.0f, 0.8f}, 0.5f));
    return s;
}

// One pass gives both solutions: its L_om equals a plain render of the mixed scene and its L_or
// a plain render of the real-only scene, in expectation (per-pixel t-test on the difference).
TEST_F(DifferentialTest, OnePassEqualsTwoIndependentRenders) {
    Scene s = setWithVirtualObjects();
    RenderSettings rs = differentialSettings(20, 20);
    rs.photons.perIteration = kPhotonsPerIteration;
    AovEstimate onePass = estimateAovs(s, rs, nullptr, 8);
    RenderSettings plain = rs;
    plain.differential = false;
    AovEstimate mixed = estimateAovs(s, plain, nullptr, 8);
    AovEstimate real = estimateAovs(realOnly(s), plain, nullptr, 8);
    auto compare = [&](const std::vector<double>& a, const std::vector<double>& va,
                       const std::vector<double>& b, const std::vector<double>& vb,
                       const char* what) {
        double worst = 0.0;
        for (size_t i = 0; i < a.size(); ++i) {
            double sigma = std::sqrt(va[i] + vb[i]);
            if (sigma == 0.0) {
                EXPECT_NEAR(a[i], b[i], 1e-6 * std::max(1.0, std::abs(a[i]))) << what << " " << i;
                continue;
            }
            worst = std::max(worst, std::abs(a[i] - b[i]) / sigma);
        }
        EXPECT_LT(worst, kPixelT) << what;
        RecordProperty(std::string(what) + "WorstT", std::to_string(worst));
    };
    compare(onePass.mean[int(Aov::Mixed)], onePass.var[int(Aov::Mixed)],
            mixed.mean[int(Aov::Mixed)], mixed.var[int(Aov::Mixed)], "mixed");
    compare(onePass.mean[int(Aov::Real)], onePass.var[int(Aov::Real)], real.mean[int(Aov::Mixed)],
            real.var[int(Aov::Mixed)], "real");
}

// A lane whose path ends starts its pixel's next sample in the same loop (trace_paths.comp's
// path regeneration), after the reflected branch of a split at glass and the real continuation
// behind a virtual object. Each sample must be the one a dispatch of that sample alone traces:
// every AOV of 16 samples in one dispatch equals 16 one-sample dispatches to rounding (only the
// order of the compensated sums differs). State leaking from one sample into the next (a branch
// left over, a solution's mode or mask not reset) would differ by far more.
TEST_F(DifferentialTest, PathsStartedInOneDispatchEqualOneSamplePerDispatch) {
    Scene s = setWithVirtualObjects();
    addSphere(s, {0.45f, 0.3f, 0.55f}, 0.2f, addMaterial(s, glass(1.5f)), false, 16, 32);
    auto renderWith = [&](uint32_t perDispatch) {
        RenderSettings rs = differentialSettings(24, 24);
        rs.samplesPerDispatch = perDispatch;
        // Photon iterations dispatch one sample each (the glass would switch them on).
        rs.photons.mode = PhotonMode::Off;
        auto r = Renderer::create(ctx(), s, rs);
        EXPECT_TRUE(r.ok()) << r.message();
        EXPECT_TRUE((*r)->render(16).ok());
        return std::move(*r);
    };
    auto alone = renderWith(1);
    auto together = renderWith(16);
    for (Aov aov : {Aov::Mixed, Aov::Real, Aov::Mask, Aov::SampleCount}) {
        Result<ImageF> a = alone->image(aov);
        Result<ImageF> b = together->image(aov);
        ASSERT_TRUE(a.ok() && b.ok());
        float worst = 0.0f;
        for (size_t i = 0; i < a->pixels.size(); ++i)
            worst = std::max(worst, std::abs(a->pixels[i] - b->pixels[i]) /
                                        std::max(1.0f, std::abs(a->pixels[i])));
        EXPECT_LT(worst, 1e-5f) << "AOV " << int(aov);
    }
}

// With this renderer's own converged real-only image as the plate, the composite equals its
// render of the mixed scene wherever the mask is all-or-nothing (at fractional-mask edges the
// pixel average of Eq. 1 legitimately differs).
TEST_F(DifferentialTest, CompositeOverOwnRealRenderEqualsMixedRender) {
    Scene s = setWithVirtualObjects();
    RenderSettings differential = differentialSettings(20, 20);
    differential.photons.perIteration = kPhotonsPerIteration;
    RenderSettings plain = differential;
    plain.differential = false;
    AovEstimate real = estimateAovs(realOnly(s), plain, nullptr, 32);
    ImageF plate;
    plate.width = plain.width;
    plate.height = plain.height;
    plate.channels = 3;
    for (double v : real.mean[int(Aov::Mixed)]) plate.pixels.push_back(float(v));
    AovEstimate mixed = estimateAovs(s, plain, nullptr, 8);
    AovEstimate composite = estimateAovs(s, differential, &plate, 8);
    double worst = 0.0;
    int tested = 0;
    for (size_t p = 0; p < size_t(plain.width) * plain.height; ++p) {
        double mask = composite.mean[int(Aov::Mask)][p];
        if (mask != 0.0 && mask != 1.0) continue;
        ++tested;
        for (int c = 0; c < 3; ++c) {
            size_t i = p * 3 + c;
            double sigma = std::sqrt(composite.var[0][i] + mixed.var[int(Aov::Mixed)][i] +
                                     real.var[int(Aov::Mixed)][i]);
            double d = std::abs(composite.mean[0][i] - mixed.mean[int(Aov::Mixed)][i]);
            if (sigma > 0.0)
                worst = std::max(worst, d / sigma);
            else
                EXPECT_NEAR(d, 0.0, 1e-6);
        }
    }
    EXPECT_GT(tested, 300);
    EXPECT_LT(worst, kPixelT);
    RecordProperty("worstT", std::to_string(worst));
}

// Pixel of world point p for the realSet camera (looking straight down, +X right, −Z up).
glm::ivec2 pixelOf(const Scene& s, const RenderSettings& rs, glm::vec3 p) {
    const Camera& c = s.cameras[0];
    glm::vec3 q = glm::vec3(glm::inverse(c.worldFromCamera) * glm::vec4(p, 1.0f));
    float t = std::tan(0.5f * c.fovYRad);
    float ndcX = q.x / -q.z / (t * float(rs.width) / float(rs.height));
    float ndcY = q.y / -q.z / t;
    return {int((ndcX + 1.0f) * 0.5f * float(rs.width)),
            int((1.0f - ndcY) * 0.5f * float(rs.height))};
}

// The effects a virtual object has on the real set, measured in the composite.
TEST_F(DifferentialTest, VirtualObjectsShadowReflectBleedAndAreOccluded) {
    Scene s = realSet();
    // A green diffuse ball floating above the table: its shadow falls 0.5 m toward −X (sun at 45°).
    addSphere(s, {0.6f, 0.5f, 0.0f}, 0.2f, addMaterial(s, lambert(glm::vec3(0.05f, 0.9f, 0.05f))),
              false, 16, 32);
    // A mirror ball next to the red box.
    addSphere(s, {-0.3f, 0.15f, -0.6f}, 0.15f, addMaterial(s, mirror()), false, 16, 32);
    // A virtual ball hidden under the (real) box: the phantom must occlude it.
    addSphere(s, {-0.7f, 0.1f, -0.1f}, 0.08f, addMaterial(s, lambert(glm::vec3(0.0f, 0.0f, 1.0f))),
              false, 8, 16);
    RenderSettings rs = differentialSettings(40, 40);
    rs.maxDepth = 4;
    rs.photons.perIteration = kPhotonsPerIteration;
    ImageF plate;
    plate.width = rs.width;
    plate.height = rs.height;
    plate.channels = 3;
    plate.pixels.assign(size_t(rs.width) * rs.height * 3, 0.5f);
    // 64 spp: at 16 the expected green bleed is only about 5σ of 8 runs, so its detection below
    // passed or failed with the draw of random numbers.
    AovEstimate e = estimateAovs(s, rs, &plate, 64, 8);
    auto at = [&](glm::ivec2 px, int c, int aov = 0) {
        return e.mean[aov][(size_t(px.y) * rs.width + px.x) * (aov == int(Aov::Mask) ? 1 : 3) +
                           (aov == int(Aov::Mask) ? 0 : c)];
    };
    auto sigma = [&](glm::ivec2 px, int c) {
        return std::sqrt(e.var[0][(size_t(px.y) * rs.width + px.x) * 3 + c]);
    };
    // Shadow: the sun's light (E = 3·cos45° lux on albedo 0.7: 0.47 radiance) is gone there.
    glm::ivec2 shadow = pixelOf(s, rs, {0.1f, 0.0f, 0.0f});
    double darkening = 0.5 - at(shadow, 0);
    RecordProperty("shadowDarkening", std::to_string(darkening));
    EXPECT_GT(darkening, 0.3) << "no virtual shadow on the real table";
    // Far from every virtual object the composite is the plate (up to the noise).
    glm::ivec2 far = pixelOf(s, rs, {0.8f, 0.0f, 0.8f});
    EXPECT_NEAR(at(far, 1), 0.5, kPixelT * sigma(far, 1) + 0.02);
    // Colour bleeding: the table next to the green ball receives green light, not red.
    glm::ivec2 beside = pixelOf(s, rs, {0.6f, 0.0f, 0.3f});
    double bleed = (at(beside, 1) - 0.5) - (at(beside, 0) - 0.5);
    EXPECT_GT(bleed, 5.0 * std::hypot(sigma(beside, 0), sigma(beside, 1)));
    RecordProperty("greenBleed", std::to_string(bleed));
    // The mirror shows the real red box and the grey environment: some mirror pixels are red.
    // Pixels at least 90% covered by the mirror (the box's reflection lies at the ball's rim, and
    // with stratified samples a rim pixel's mask is its coverage, never 1 by chance): the rest,
    // the grey plate and the table, cannot make a pixel 0.1 redder than green.
    double reddest = 0.0;
    for (int y = 0; y < int(rs.height); ++y)
        for (int x = 0; x < int(rs.width); ++x)
            if (at({x, y}, 0, int(Aov::Mask)) >= 0.9 &&
                glm::length(glm::vec2(x, y) - glm::vec2(pixelOf(s, rs, {-0.3f, 0.15f, -0.6f}))) <
                    3.0f)
                reddest = std::max(reddest, at({x, y}, 0) - at({x, y}, 1));
    EXPECT_GT(reddest, 0.1) << "the virtual mirror does not reflect the real box";
    // Occlusion: the ball under the box is hidden, the box's pixels keep the plate.
    glm::ivec2 box = pixelOf(s, rs, {-0.7f, 0.4f, -0.1f});
    EXPECT_EQ(at(box, 0, int(Aov::Mask)), 0.0);
    EXPECT_NEAR(at(box, 2), 0.5, kPixelT * sigma(box, 2) + 0.02) << "blue shows through the box";
}

// Where a virtual shadow takes more light than the plate holds (here a plate darker than the
// real scene renders; on set also noise), Eq. 1's mean L_oc + L_om − L_or is below zero. The
// composite is light: clamped at zero once accumulated. The differential L_om − L_or, which a
// compositor adds to its own plate, keeps its sign.
TEST_F(DifferentialTest, CompositeIsNeverNegativeAndTheDifferentialStaysSigned) {
    Scene s = realSet();
    addSphere(s, {0.6f, 0.5f, 0.0f}, 0.2f, addMaterial(s, lambert(glm::vec3(0.5f))), false, 8, 16);
    RenderSettings rs = differentialSettings(16, 16);
    rs.maxDepth = 2;
    ImageF plate;
    plate.width = rs.width;
    plate.height = rs.height;
    plate.channels = 3;
    plate.pixels.assign(size_t(rs.width) * rs.height * 3, 0.05f);
    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok()) << renderer.message();
    Renderer& r = **renderer;
    ASSERT_TRUE(r.film().setPlate(plate).ok());
    r.setSeed(7);
    ASSERT_TRUE(r.render(8).ok());
    const ImageF composite = take(r.image(Aov::Composite));
    const ImageF mixed = take(r.image(Aov::Mixed));
    const ImageF real = take(r.image(Aov::Real));
    ASSERT_EQ(composite.pixels.size(), mixed.pixels.size());
    for (size_t i = 0; i < composite.pixels.size(); ++i)
        ASSERT_GE(composite.pixels[i], 0.0f) << "pixel " << i / 3 << " channel " << i % 3;
    // The shadow's differential is about −0.47 (the sun's 3·cos45° on albedo 0.7).
    const glm::ivec2 shadow = pixelOf(s, rs, {0.1f, 0.0f, 0.0f});
    const size_t at = (size_t(shadow.y) * rs.width + shadow.x) * 3;
    EXPECT_LT(mixed.pixels[at] - real.pixels[at], -0.2f) << "the differential lost its sign";
    EXPECT_EQ(composite.pixels[at], 0.0f);
}

}  // namespace
}  // namespace previs::testing

namespace previs::testing {
namespace {

CameraCalibration pinholeFor(const Camera& camera, uint32_t w, uint32_t h,
                             std::vector<double> distortion) {
    double fy = 0.5 * h / std::tan(0.5 * camera.fovYRad);
    cv::Matx33d k(fy, 0, 0.5 * w - 0.5, 0, fy, 0.5 * h - 0.5, 0, 0, 1);
    return CameraCalibration::create(k, std::move(distortion), cv::Size(int(w), int(h)),
                                     DistortionModel::Pinhole, "test")
        .value();
}

// The lens grid inverts the calibrated distortion: projecting a grid ray with OpenCV lands on
// its pixel corner.
TEST(LensGridTest, RaysProjectBackToTheirPixels) {
    Camera cam;
    cam.fovYRad = glm::radians(60.0f);
    const uint32_t w = 64, h = 48;
    for (auto distortion :
         {std::vector<double>{}, std::vector<double>{-0.3, 0.1, 0.001, -0.002, 0.0}}) {
        CameraCalibration calib = pinholeFor(cam, w, h, distortion);
        auto grid = lensRayGrid(calib, w, h);
        ASSERT_TRUE(grid.ok()) << grid.message();
        std::vector<cv::Point3d> rays;
        for (const auto& n : *grid) rays.emplace_back(n.x, n.y, 1.0);
        std::vector<cv::Point2d> pixels = calib.projectPoints(rays);
        double worst = 0.0;
        for (uint32_t j = 0; j <= h; ++j)
            for (uint32_t i = 0; i <= w; ++i) {
                const auto& p = pixels[j * (w + 1) + i];
                worst = std::max(worst, std::hypot(p.x - (i - 0.5), p.y - (j - 0.5)));
            }
        EXPECT_LT(worst, 1e-3) << "pixels";
    }
    EXPECT_FALSE(lensRayGrid(pinholeFor(cam, w, h, {}), w + 1, h).ok());
}

class LensTest : public GpuTest {};

// An undistorted calibration with the camera's focal length renders what the pinhole renders.
TEST_F(LensTest, IdealLensMatchesPinhole) {
    Scene s = realSet();
    RenderSettings rs = differentialSettings(32, 24);
    rs.differential = false;
    ImageF pinhole = render(s, rs, 4);
    rs.lensGrid =
        lensRayGrid(pinholeFor(s.cameras[0], rs.width, rs.height, {}), rs.width, rs.height).value();
    ImageF lens = render(s, rs, 4);
    double sumDiff = 0.0, sum = 0.0;
    for (size_t i = 0; i < lens.pixels.size(); ++i) {
        sumDiff += std::abs(lens.pixels[i] - pinhole.pixels[i]);
        sum += pinhole.pixels[i];
    }
    // Same random numbers, rays equal to float rounding: only rays grazing an edge may differ.
    EXPECT_LT(sumDiff / sum, 1e-3);
}

}  // namespace
}  // namespace previs::testing

namespace previs::testing {
namespace {

class ModesTest : public GpuTest {};

// Preview frames repeat their noise exactly (same random sequence every frame); refinement keeps
// adding new samples, and its mean moves toward the converged image.
TEST_F(ModesTest, PreviewIsTemporallyCoherentRefinementAccumulates) {
    Scene s = setWithVirtualObjects();
    RenderSettings rs = differentialSettings(16, 16);
    auto renderer = Renderer::create(ctx(), s, rs);
    ASSERT_TRUE(renderer.ok());
    Renderer& r = **renderer;
    ASSERT_TRUE(r.renderPreviewFrame(2).ok());
    ImageF first = take(r.image(Aov::Mixed));
    // A camera move and back, as tracking jitters: the same pose gives the same pixels.
    glm::mat4 pose = r.camera().worldFromCamera;
    r.setCameraPose(glm::translate(pose, glm::vec3(0.05f, 0, 0)));
    ASSERT_TRUE(r.renderPreviewFrame(2).ok());
    ImageF moved = take(r.image(Aov::Mixed));
    r.setCameraPose(pose);
    ASSERT_TRUE(r.renderPreviewFrame(2).ok());
    ImageF again = take(r.image(Aov::Mixed));
    EXPECT_NE(first.pixels, moved.pixels);
    EXPECT_EQ(first.pixels, again.pixels);
    // Refinement: 2 + 30 samples; the 32-sample image differs from the 2-sample preview.
    ASSERT_TRUE(r.refine(30).ok());
    EXPECT_EQ(r.samplesPerPixel(), 32u);
    ImageF refined = take(r.image(Aov::Mixed));
    EXPECT_NE(refined.pixels, first.pixels);
}

}  // namespace
}  // namespace previs::testing
