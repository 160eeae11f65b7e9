// Fisheye → equirectangular resampling, inverse tone mapping and light-source estimation.

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>

#include "scene/environment_map.h"
#include "tests/support/test_data.h"
#include "vision/camera_calibration.h"
#include "vision/equirect.h"
#include "vision/fisheye_to_equirect.h"
#include "vision/inverse_tone_map.h"
#include "vision/light_estimator.h"
#include "vision/tag_board.h"

namespace previs {
namespace {

const std::string kData = testing::sharedDataDir();
const std::string kTestData = testing::sourcePath("tests/vision/data/");

double angleDeg(const cv::Vec3d& a, const cv::Vec3d& b) {
    return std::acos(std::clamp(a.dot(b) / (cv::norm(a) * cv::norm(b)), -1.0, 1.0)) * 180.0 / M_PI;
}

CameraCalibration loadCalib(const std::string& name) {
    auto c = CameraCalibration::load(kTestData + name);
    EXPECT_TRUE(c.ok()) << c.message();
    return *c;
}

// ---- fisheye lookup ------------------------------------------------------------------------

struct MountCase {
    std::string calib;
    cv::Vec3d mountDeg;
};

class FisheyeLookup : public ::testing::TestWithParam<MountCase> {};

// The lookup must agree with OpenCV's own fisheye projection of the same directions.
// cv::fisheye::projectPoints works through x/z, so only directions in front of the lens
// (θ < 89°) can be compared; beyond, our projection continues the same θd(θ) polynomial.
TEST_P(FisheyeLookup, AgreesWithOpenCvProjectPoints) {
    CameraCalibration calib = loadCalib(GetParam().calib);
    FisheyeToEquirectSettings s;
    s.mountRotationDeg = GetParam().mountDeg;
    s.width = 512;
    auto f = FisheyeToEquirect::create(calib, s);
    ASSERT_TRUE(f.ok()) << f.message();
    std::vector<cv::Point3d> points;
    std::vector<cv::Point2i> texels;
    const cv::Matx33d fisheyeFromWorld = f->worldFromFisheye().t();
    for (int y = 0; y < f->height(); y += 3)
        for (int x = 0; x < f->width(); x += 3) {
            if (f->seenMask().at<uint8_t>(y, x) == 0) continue;
            cv::Vec3d d = fisheyeFromWorld * equirectTexelDirection(x, y, f->width(), f->height());
            if (std::atan2(std::hypot(d[0], d[1]), d[2]) > 89.0 * M_PI / 180.0) continue;
            points.emplace_back(d[0], d[1], d[2]);
            texels.emplace_back(x, y);
        }
    ASSERT_GT(points.size(), 1000u);
    std::vector<cv::Point2d> projected;
    cv::fisheye::projectPoints(points, projected, cv::Vec3d(0, 0, 0), cv::Vec3d(0, 0, 0),
                               cv::Mat(calib.cameraMatrix()), calib.distortion());
    double worst = 0.0;
    for (size_t i = 0; i < points.size(); ++i) {
        cv::Point2d m(f->mapX().at<float>(texels[i]), f->mapY().at<float>(texels[i]));
        worst = std::max(worst, cv::norm(m - projected[i]));
    }
    std::printf("%zu directions, worst |lookup - cv::fisheye::projectPoints| = %.2e px\n",
                points.size(), worst);
    EXPECT_LT(worst, 1e-3);  // float32 storage of the map: ~3e-5 px at 640 px
}

INSTANTIATE_TEST_SUITE_P(Vision, FisheyeLookup,
                         ::testing::Values(MountCase{"boofcv_fisheye_kb.yaml", {-90, 0, 0}},
                                           MountCase{"boofcv_fisheye_kb.yaml", {180, 0, 0}},
                                           MountCase{"theta_front_kb.yaml", {30, -20, 70}}),
                         [](const auto& p) {
                             return p.param.calib.substr(0, 6) + "_mount" + std::to_string(p.index);
                         });

// DESIGN.md §3: the default mount looks at the zenith with the image's bottom edge toward −Z.
TEST(FisheyeToEquirect, DefaultMountOrientation) {
    CameraCalibration calib = loadCalib("boofcv_fisheye_kb.yaml");
    auto f = FisheyeToEquirect::create(calib);
    ASSERT_TRUE(f.ok());
    auto zenith = f->pixelForDirection({0, 1, 0});
    ASSERT_TRUE(zenith.has_value());
    EXPECT_NEAR(zenith->x, calib.cx(), 1e-9);
    EXPECT_NEAR(zenith->y, calib.cy(), 1e-9);
    auto towardMinusZ = f->pixelForDirection({0, 0.5, -1});  // up and toward −Z
    ASSERT_TRUE(towardMinusZ.has_value());
    EXPECT_NEAR(towardMinusZ->x, calib.cx(), 1e-6);
    EXPECT_GT(towardMinusZ->y, calib.cy() + 50.0);  // below the centre: toward the bottom edge
    auto towardPlusX = f->pixelForDirection({1, 0.5, 0});
    ASSERT_TRUE(towardPlusX.has_value());
    EXPECT_GT(towardPlusX->x, calib.cx() + 50.0);                // image x = world +X
    EXPECT_FALSE(f->pixelForDirection({0, -1, 0}).has_value());  // nadir: unseen
    EXPECT_NEAR(f->seenFraction(), (1.0 - std::cos(95.0 * M_PI / 180.0)) / 2.0, 0.01);
}

// Real data: the chessboard corners detected in the BoofCV fisheye views, with the poses of the
// derived OpenCV calibration, must land where our lookup sends their directions. The calibration
// reprojects at 0.198 px RMS; our own projection of the same model (the code that builds the
// lookup) must do as well, out to the ~88° off axis the views reach.
TEST(FisheyeToEquirect, ChessboardCornersOnRealFisheyeViews) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    std::ifstream in(kData +
                     "fisheye/boofcv_chessboard/kb_opencv_calibration_from_shared_images.json");
    nlohmann::json j = nlohmann::json::parse(in);
    CameraCalibration calib = loadCalib("boofcv_fisheye_kb.yaml");
    FisheyeToEquirectSettings s;
    s.width = 64;  // only pixelForDirection is used here
    s.maxFieldAngleDeg = 110.0;
    auto f = FisheyeToEquirect::create(calib, s);
    ASSERT_TRUE(f.ok());
    double sum = 0.0;
    int n = 0;
    double maxTheta = 0.0;
    for (auto& [view, corners] : j["corners_px"].items()) {
        if (view == "4.jpg") continue;  // set aside by the calibration (README)
        cv::Vec3d rvec(j["rvecs"][view][0].get<double>(), j["rvecs"][view][1].get<double>(),
                       j["rvecs"][view][2].get<double>());
        cv::Vec3d tvec(j["tvecs_square_units"][view][0].get<double>(),
                       j["tvecs_square_units"][view][1].get<double>(),
                       j["tvecs_square_units"][view][2].get<double>());
        cv::Matx33d r;
        cv::Rodrigues(rvec, r);
        for (size_t i = 0; i < corners.size(); ++i) {
            // OpenCV's object points for patternSize (4, 6): (col, row, 0) square units.
            cv::Vec3d obj(double(i % 4), double(i / 4), 0.0);
            cv::Vec3d cam = r * obj + tvec;
            maxTheta = std::max(maxTheta, std::atan2(std::hypot(cam[0], cam[1]), cam[2]));
            auto px = f->pixelForDirection(f->worldFromFisheye() * cam);
            ASSERT_TRUE(px.has_value()) << view << " corner " << i;
            cv::Point2d measured(corners[i][0].get<double>(), corners[i][1].get<double>());
            sum += std::pow(cv::norm(*px - measured), 2);
            ++n;
        }
    }
    const double rms = std::sqrt(sum / n);
    std::printf("%d corners on 16 views (up to %.1f° off axis): RMS %.3f px (calibration: 0.198)\n",
                n, maxTheta * 180.0 / M_PI, rms);
    EXPECT_LT(rms, 0.25);
}

cv::Mat loadLinear(const std::string& path) {
    cv::Mat bgr = cv::imread(path, cv::IMREAD_COLOR);
    EXPECT_FALSE(bgr.empty()) << path;
    cv::Mat rgb;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    return inverseToneMapRgb8(rgb, {});
}

TEST(FisheyeToEquirect, RealFrameAndFillRule) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    CameraCalibration calib = loadCalib("theta_front_kb.yaml");
    auto f = FisheyeToEquirect::create(calib, {.mountRotationDeg = {180, 0, 0}, .width = 512});
    ASSERT_TRUE(f.ok());
    cv::Mat frame = loadLinear(kData + "fisheye/theta_dual_fisheye/front_table.jpg");
    auto env = f->apply(frame);
    ASSERT_TRUE(env.ok()) << env.message();
    ASSERT_EQ(env->cols, 512);
    ASSERT_EQ(env->rows, 256);
    // The camera looks along world −Z (u = 0.25): that texel shows the image centre.
    cv::Vec3f centre = env->at<cv::Vec3f>(128, 128);
    cv::Mat patch;
    cv::getRectSubPix(frame, {1, 1}, cv::Point2f(float(calib.cx()), float(calib.cy())), patch);
    const cv::Vec3f expected = patch.at<cv::Vec3f>(0, 0);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(centre[c], expected[c], 0.02);
    // Unseen directions (behind the lens, +Z at u = 0.75) all hold one constant, finite value.
    cv::Vec3f fill = env->at<cv::Vec3f>(128, 384);
    EXPECT_EQ(f->seenMask().at<uint8_t>(128, 384), 0);
    EXPECT_EQ(env->at<cv::Vec3f>(10, 384), fill);
    for (int c = 0; c < 3; ++c) EXPECT_GT(fill[c], 0.0f);
}

TEST(FisheyeToEquirect, BlackWhiteAndBrokenFrames) {
    CameraCalibration calib = loadCalib("boofcv_fisheye_kb.yaml");
    auto f = FisheyeToEquirect::create(calib, {.width = 256});
    ASSERT_TRUE(f.ok());
    const cv::Size size = calib.imageSize();
    auto black = f->apply(cv::Mat(size, CV_32FC3, cv::Scalar(0, 0, 0)));
    ASSERT_TRUE(black.ok());
    EXPECT_EQ(cv::norm(*black, cv::NORM_INF), 0.0);
    cv::Mat white8(size, CV_8UC3, cv::Scalar(255, 255, 255));
    auto white = f->apply(inverseToneMapRgb8(white8, {}));
    ASSERT_TRUE(white.ok());
    // Constant radiance 1 in → 1 everywhere out (fill included): power 4π.
    EXPECT_NEAR(cv::norm(*white - cv::Scalar(1, 1, 1), cv::NORM_INF), 0.0, 1e-6);
    cv::Mat broken(size, CV_32FC3, cv::Scalar(1, 1, 1));
    broken.at<cv::Vec3f>(320, 320) = cv::Vec3f(NAN, INFINITY, -5.0f);
    auto cleaned = f->apply(broken);
    ASSERT_TRUE(cleaned.ok());
    EXPECT_TRUE(cv::checkRange(*cleaned, true, nullptr, 0.0, 1.0 + 1e-6));
    EXPECT_FALSE(f->apply(cv::Mat(10, 10, CV_32FC3)).ok());  // wrong size: an error, no crash
    EXPECT_FALSE(f->apply(cv::Mat(size, CV_8UC3)).ok());
    EXPECT_FALSE(FisheyeToEquirect::create(calib, {.width = 7}).ok());
}

// ---- inverse tone mapping ------------------------------------------------------------------

TEST(InverseToneMap, InvertsTheForwardOperators) {
    auto srgbEncode = [](float l) {
        return l <= 0.0031308f ? 12.92f * l : 1.055f * std::pow(l, 1.0f / 2.4f) - 0.055f;
    };
    for (float l : {0.0f, 0.001f, 0.02f, 0.2f, 0.5f, 0.9f, 1.0f})
        EXPECT_NEAR(srgbDecode(srgbEncode(l)), l, 1e-6f * std::max(1.0f, l));
    // Reinhard on luminance, with exposure: forward rgb·2^e / (1 + L), then sRGB.
    InverseToneMapSettings s{.op = InverseToneMapOperator::Reinhard, .exposureStops = 1.0f};
    std::array<float, 3> radiance{0.6f, 0.4f, 0.1f};  // display values stay below 1
    float e = std::exp2(s.exposureStops);
    float lum = 0.2126f * radiance[0] * e + 0.7152f * radiance[1] * e + 0.0722f * radiance[2] * e;
    std::array<float, 3> encoded;
    for (int c = 0; c < 3; ++c) encoded[c] = srgbEncode(radiance[c] * e / (1.0f + lum));
    auto back = inverseToneMapRgb(encoded, s);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(back[c], radiance[c], 1e-4f * radiance[c]);
    // White balance gains apply per channel; saturated white stays finite under Reinhard.
    s.whiteBalance = {2.0f, 1.0f, 0.5f};
    auto white = inverseToneMapRgb({1.0f, 1.0f, 1.0f}, s);
    for (float v : white) EXPECT_TRUE(std::isfinite(v));
    EXPECT_NEAR(white[0] / white[1], 2.0f, 1e-5f);
}

// ---- light estimation ----------------------------------------------------------------------

// Sky gradient plus a sun disc of the given angular radius and radiance.
cv::Mat syntheticSky(int width, const cv::Vec3d& sunDir, double radiusDeg, float sunRadiance) {
    const int h = width / 2;
    cv::Mat m(h, width, CV_32FC3);
    const cv::Vec3d s = sunDir / cv::norm(sunDir);
    const double cosR = std::cos(radiusDeg * M_PI / 180.0);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < width; ++x) {
            cv::Vec3d d = equirectTexelDirection(x, y, width, h);
            float sky = float(0.3 + 0.7 * std::max(0.0, d[1]));
            cv::Vec3f c(0.6f * sky, 0.8f * sky, 1.0f * sky);
            if (d.dot(s) >= cosR)
                c = cv::Vec3f(sunRadiance, 0.9f * sunRadiance, 0.8f * sunRadiance);
            m.at<cv::Vec3f>(y, x) = c;
        }
    return m;
}

void expectEnergyPreserved(const LightingSnapshot& snap) {
    for (int c = 0; c < 3; ++c) {
        double lights = 0.0;
        for (const EstimatedLight& l : snap.lights) lights += l.radiance[c] * l.solidAngleSr;
        EXPECT_NEAR(lights + snap.residualPower[c], snap.totalPower[c],
                    1e-12 * snap.totalPower[c] + 1e-300);
    }
}

struct SunCase {
    std::string name;
    cv::Vec3d direction;
};

class SyntheticSun : public ::testing::TestWithParam<SunCase> {};

TEST_P(SyntheticSun, FindsTheSunAndPreservesPower) {
    const cv::Vec3d dir = GetParam().direction / cv::norm(GetParam().direction);
    cv::Mat map = syntheticSky(512, dir, 2.0, 5000.0f);
    auto snap = LightEstimator().estimate(map);
    ASSERT_TRUE(snap.ok()) << snap.message();
    ASSERT_EQ(snap->lights.size(), 1u);  // one sun, even across the seam or around a pole
    const double err = angleDeg(snap->lights[0].direction, dir);
    std::printf("%s: sun direction error %.3f deg, solid angle %.5f sr (disc: %.5f sr)\n",
                GetParam().name.c_str(), err, snap->lights[0].solidAngleSr,
                2.0 * M_PI * (1.0 - std::cos(2.0 * M_PI / 180.0)));
    // The disc is sampled on 0.7° texels: its centroid lands within a fraction of a texel.
    EXPECT_LT(err, 0.25);
    EXPECT_NEAR(snap->lights[0].solidAngleSr, 2.0 * M_PI * (1.0 - std::cos(2.0 * M_PI / 180.0)),
                0.15 * 2.0 * M_PI * (1.0 - std::cos(2.0 * M_PI / 180.0)));
    EXPECT_NEAR(snap->lights[0].radiance[0], 5000.0, 1e-6 * 5000.0);  // uniform disc
    expectEnergyPreserved(*snap);
    // Residual = the map minus the sun: no texel of it above the threshold's sun level.
    double maxResidual;
    cv::minMaxLoc(snap->residual.reshape(1), nullptr, &maxResidual);
    EXPECT_LT(maxResidual, 1.01);
}

INSTANTIATE_TEST_SUITE_P(Vision, SyntheticSun,
                         ::testing::Values(SunCase{"afternoon", {0.5, 0.6, -0.3}},
                                           SunCase{"seam", {-1.0, 0.3, 0.0}},
                                           SunCase{"zenith", {0.01, 1.0, 0.0}},
                                           SunCase{"low", {0.2, 0.03, 0.9}}),
                         [](const auto& p) { return p.param.name; });

TEST(LightEstimator, BlackMapAndBadInput) {
    auto snap = LightEstimator().estimate(cv::Mat(64, 128, CV_32FC3, cv::Scalar(0, 0, 0)));
    ASSERT_TRUE(snap.ok());
    EXPECT_TRUE(snap->lights.empty());
    EXPECT_EQ(snap->totalPower[0], 0.0);
    cv::Mat broken(64, 128, CV_32FC3, cv::Scalar(1, 1, 1));
    broken.at<cv::Vec3f>(5, 5) = cv::Vec3f(NAN, INFINITY, -1.0f);
    auto cleaned = LightEstimator().estimate(broken);
    ASSERT_TRUE(cleaned.ok());
    EXPECT_NEAR(cleaned->totalPower[1], 4.0 * M_PI, 1e-3);  // constant 1 (one texel 0) ≈ 4π
    EXPECT_TRUE(std::isfinite(cleaned->totalPower[0]));
    expectEnergyPreserved(*cleaned);
    EXPECT_FALSE(LightEstimator().estimate(cv::Mat(64, 128, CV_8UC3)).ok());
}

// Real maps: total power matches the derived statistics (a loader/orientation check), energy is
// preserved, the brightest texel ends in a light, and on the four maps with the sun in view the
// dominant light points at the sun (the brightest pixel of envmap_stats.json) within 1°.
class RealMaps : public ::testing::TestWithParam<std::string> {};

TEST_P(RealMaps, DominantLightAndEnergy) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    std::ifstream in(kData + "envmaps/envmap_stats.json");
    nlohmann::json stats = nlohmann::json::parse(in)["maps"][GetParam()];
    auto map = loadEnvironmentMap(kData + "envmaps/" + GetParam());
    ASSERT_TRUE(map.ok()) << map.message();
    auto snap = LightEstimator().estimate(environmentMapToMat(*map));
    ASSERT_TRUE(snap.ok());
    expectEnergyPreserved(*snap);
    for (int c = 0; c < 3; ++c) {
        // The stats weight rows by sin θ at the row centre, we by the exact texel solid angle.
        const double mean = stats["solid_angle_weighted_mean_rgb"][c].get<double>();
        EXPECT_NEAR(snap->totalPower[c] / (4.0 * M_PI), mean, 2e-3 * mean + 1e-6);
    }
    const int bx = stats["brightest_pixel_xy"][0];
    const int by = stats["brightest_pixel_xy"][1];
    const cv::Vec3d brightest = equirectTexelDirection(bx, by, int(map->width), int(map->height));
    if (!snap->lights.empty()) {
        EXPECT_EQ(snap->residual.at<cv::Vec3f>(by, bx), cv::Vec3f(0, 0, 0))
            << "the brightest texel is not part of any light";
    }
    const bool sunInView = GetParam().find("city") != std::string::npos ||
                           GetParam().find("sunrise") != std::string::npos ||
                           GetParam().find("sunset") != std::string::npos ||
                           GetParam().find("rooitou") != std::string::npos;
    if (sunInView) {
        ASSERT_FALSE(snap->lights.empty());
        const double err = angleDeg(snap->lights[0].direction, brightest);
        std::printf("%s: dominant light %.2f deg from the sun pixel, %zu light(s)\n",
                    GetParam().c_str(), err, snap->lights.size());
        EXPECT_LT(err, 1.0);
    }
}

INSTANTIATE_TEST_SUITE_P(
    Vision, RealMaps,
    ::testing::Values(
        "blender_studiolights_world/city.exr", "blender_studiolights_world/courtyard.exr",
        "blender_studiolights_world/forest.exr", "blender_studiolights_world/interior.exr",
        "blender_studiolights_world/night.exr", "blender_studiolights_world/studio.exr",
        "blender_studiolights_world/sunrise.exr", "blender_studiolights_world/sunset.exr",
        "polyhaven_1k_hdr/empty_warehouse_01_1k.hdr", "polyhaven_1k_hdr/potsdamer_platz_1k.hdr",
        "polyhaven_1k_hdr/rooitou_park_1k.hdr", "polyhaven_1k_hdr/st_fagans_interior_1k.hdr",
        "polyhaven_1k_hdr/studio_small_03_1k.hdr"),
    [](const auto& p) {
        std::string n = p.param.substr(p.param.find('/') + 1);
        n = n.substr(0, n.find('.'));
        return n;
    });

// ---- the lighting thread -------------------------------------------------------------------

TEST(LightingEstimator, NeverBlocksAndPublishesTheLatest) {
    LightingEstimator estimator;
    EXPECT_EQ(estimator.latest(), nullptr);
    const cv::Mat sky = syntheticSky(256, {0.5, 0.6, -0.3}, 3.0, 5000.0f);
    const int n = 20;
    double worstSubmitMs = 0.0;
    for (int i = 1; i <= n; ++i) {
        auto env = std::make_shared<EnvironmentSnapshot>();
        env->radiance = sky;
        env->sequence = uint64_t(i);
        auto t0 = std::chrono::steady_clock::now();
        estimator.submit(std::move(env));
        worstSubmitMs = std::max(worstSubmitMs, std::chrono::duration<double, std::milli>(
                                                    std::chrono::steady_clock::now() - t0)
                                                    .count());
    }
    // The estimate takes milliseconds; submitting must not wait for it. Shown without timing
    // (a timed assertion flakes on a loaded machine): the producer outran the estimator, so
    // snapshots were dropped rather than queued behind it.
    RecordProperty("worstSubmitMs", std::to_string(worstSubmitMs));
    auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < deadline) {
        auto latest = estimator.latest();
        if (latest && latest->sequence == uint64_t(n)) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    auto latest = estimator.latest();
    ASSERT_NE(latest, nullptr);
    EXPECT_EQ(latest->sequence, uint64_t(n));
    EXPECT_EQ(latest->lights.size(), 1u);
    EXPECT_EQ(estimator.processed() + estimator.dropped(), uint64_t(n));
    EXPECT_GT(estimator.dropped(), 0u);
    std::printf("submitted %d, processed %llu, dropped %llu, slowest submit %.3f ms\n", n,
                (unsigned long long)estimator.processed(), (unsigned long long)estimator.dropped(),
                worstSubmitMs);
    // A bad snapshot keeps the previous lighting.
    auto bad = std::make_shared<EnvironmentSnapshot>();
    bad->radiance = cv::Mat(4, 8, CV_8UC3);
    bad->sequence = 99;
    estimator.submit(bad);
    while (estimator.failed() == 0 && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    EXPECT_EQ(estimator.failed(), 1u);
    EXPECT_EQ(estimator.latest()->sequence, uint64_t(n));
}

}  // namespace
}  // namespace previs
