// HDR light capture: a bracket of 8-bit frames merged to radiance (vision/hdr_bracket.h), the
// bracket's checks, and the fisheye → map step keeping a small sun's power
// (vision/fisheye_to_equirect.h).

#include "vision/hdr_bracket.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>
#include <random>

#include "base/luminance.h"
#include "render/tonemap.h"
#include "vision/camera_calibration.h"
#include "vision/equirect.h"
#include "vision/fisheye_to_equirect.h"

namespace previs {
namespace {

// The demo's camera curve: render/tonemap.h's extended Reinhard at L_max = L_white = 16, which
// the radiometry below inverts exactly.
InverseToneMapSettings radiometry() {
    InverseToneMapSettings r;
    r.op = InverseToneMapOperator::Banterle;
    r.maxRadiance = 16.0f;
    r.whiteLuminance = 16.0f;
    return r;
}

ToneMapSettings cameraCurve(float stops) {
    ToneMapSettings t;
    t.op = ToneMapOperator::ReinhardExtended;
    t.maxRadiance = 16.0f;
    t.whiteLuminance = 16.0f;
    t.exposureStops = stops;
    return t;
}

constexpr float kNoiseCodes = 1.5f;  // the demo's sensor noise, in 8-bit code values

// A set seen by a camera: a dim-to-bright wall (0.02 … 4), a saturated red patch, and a lamp
// (radiance 1500, a core of 1800) — 7 stops above what one 8-bit exposure holds.
cv::Mat sceneRadiance() {
    cv::Mat r(96, 128, CV_32FC3);
    for (int y = 0; y < r.rows; ++y)
        for (int x = 0; x < r.cols; ++x) {
            const float wall = 0.02f * std::pow(200.0f, float(x) / (r.cols - 1));
            cv::Vec3f v(wall, 0.9f * wall, 0.7f * wall);
            if (y >= 70 && y < 90 && x >= 10 && x < 40) v = cv::Vec3f(40.0f, 5.0f, 2.0f);
            const float d = std::hypot(x - 90.0f, y - 30.0f);
            if (d < 8.0f) v = cv::Vec3f(1500.0f, 1400.0f, 1200.0f);
            if (d < 3.0f) v = cv::Vec3f(1800.0f, 1700.0f, 1500.0f);
            r.at<cv::Vec3f>(y, x) = v;
        }
    return r;
}

cv::Mat exposeRgb8(const cv::Mat& radiance, float stops, std::mt19937& rng, float noise) {
    std::normal_distribution<float> gauss(0.0f, noise);
    cv::Mat out(radiance.size(), CV_8UC3);
    for (int y = 0; y < radiance.rows; ++y)
        for (int x = 0; x < radiance.cols; ++x) {
            const cv::Vec3f& v = radiance.at<cv::Vec3f>(y, x);
            const std::array<float, 3> enc = toneMapRgb({v[0], v[1], v[2]}, cameraCurve(stops));
            for (int c = 0; c < 3; ++c)
                out.at<cv::Vec3b>(y, x)[c] =
                    cv::saturate_cast<uint8_t>(255.0f * enc[c] + (noise > 0 ? gauss(rng) : 0.0f));
        }
    return out;
}

float lum(const cv::Vec3f& v) { return luminance(v[0], v[1], v[2]); }

TEST(HdrBracket, MergeRecoversRadianceSevenStopsAboveClipping) {
    const cv::Mat truth = sceneRadiance();
    const std::vector<float> stops{0.0f, -4.0f, -8.0f};
    std::mt19937 rng(7);
    std::vector<cv::Mat> frames;
    for (float s : stops) frames.push_back(exposeRgb8(truth, s, rng, kNoiseCodes));
    Result<MergedBracket> merged = mergeBracket(frames, stops, radiometry());
    ASSERT_TRUE(merged.ok()) << merged.message();
    // The lamp's core (1800) is at 7 at −8 stops: its red channel reads code 248.6 on the curve's
    // steep shoulder, so noise takes a few of its 28 pixels to kClippedCode (250), where they are
    // flagged and keep −8's value. Fewer than a tenth of the lamp's ~200 pixels.
    EXPECT_LT(merged->clippedFraction * truth.total(), 20.0);

    // The lamp's power (sum over its pixels) and the wall, the red patch per pixel. Noise of
    // 1.5 codes at the frame that exposes a pixel best (codes 60–200 for these) is 1–4 % per
    // pixel; sums over the lamp's ~200 pixels average it down, so 2 %.
    double lampTruth = 0.0, lampMerged = 0.0;
    std::vector<double> wallError;
    std::array<double, 3> redSum{}, redTruth{};
    for (int y = 0; y < truth.rows; ++y)
        for (int x = 0; x < truth.cols; ++x) {
            const cv::Vec3f t = truth.at<cv::Vec3f>(y, x);
            const cv::Vec3f m = merged->radiance.at<cv::Vec3f>(y, x);
            if (t[0] >= 1000.0f) {
                lampTruth += lum(t);
                lampMerged += lum(m);
            } else if (t[0] == 40.0f) {
                for (int c = 0; c < 3; ++c) {
                    redSum[size_t(c)] += m[c];
                    redTruth[size_t(c)] += t[c];
                }
            } else {
                wallError.push_back(std::abs(double(lum(m)) / lum(t) - 1.0));
            }
        }
    std::sort(wallError.begin(), wallError.end());
    const double wallMedian = wallError[wallError.size() / 2];
    std::printf(
        "lamp power merged/truth %.4f, wall median |error| %.4f, red patch %.4f %.4f %.4f\n",
        lampMerged / lampTruth, wallMedian, redSum[0] / redTruth[0], redSum[1] / redTruth[1],
        redSum[2] / redTruth[2]);
    EXPECT_NEAR(lampMerged / lampTruth, 1.0, 0.02);
    EXPECT_LT(wallMedian, 0.03);
    // The red patch's red channel clips at 0 and −4 stops (the curve keeps colour ratios, so red
    // reaches display white long before the luminance does): those frames get no weight, and its
    // hue comes from −8 alone, where blue sits at code ~19 (11 % noise a pixel). Over its 600
    // pixels each channel's mean is within 3 %: a clipped channel in a longer exposure would
    // have pulled red down by a factor of 2 or more.
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(redSum[size_t(c)] / redTruth[size_t(c)], 1.0, 0.03);

    // One exposure alone loses the lamp: what the box had before brackets.
    Result<MergedBracket> single = mergeBracket({frames[0]}, {0.0f}, radiometry());
    ASSERT_TRUE(single.ok());
    double lampSingle = 0.0;
    for (int y = 0; y < truth.rows; ++y)
        for (int x = 0; x < truth.cols; ++x)
            if (truth.at<cv::Vec3f>(y, x)[0] >= 1000.0f)
                lampSingle += lum(single->radiance.at<cv::Vec3f>(y, x));
    EXPECT_LT(lampSingle / lampTruth, 0.02);
    EXPECT_GT(single->clippedFraction, 0.0);
}

TEST(HdrBracket, TexelsClippedAtTheShortestExposureAreFlaggedAndKeepALowerBound) {
    const cv::Mat truth = sceneRadiance();
    const std::vector<float> stops{0.0f, -4.0f};  // too short a bracket for a 2400 lamp
    std::mt19937 rng(3);
    std::vector<cv::Mat> frames;
    for (float s : stops) frames.push_back(exposeRgb8(truth, s, rng, 0.0f));
    Result<MergedBracket> merged = mergeBracket(frames, stops, radiometry());
    ASSERT_TRUE(merged.ok()) << merged.message();
    int flaggedLamp = 0, flaggedRed = 0, flaggedElsewhere = 0;
    for (int y = 0; y < truth.rows; ++y)
        for (int x = 0; x < truth.cols; ++x) {
            const bool flagged = merged->clipped.at<uint8_t>(y, x) != 0;
            const cv::Vec3f t = truth.at<cv::Vec3f>(y, x);
            if (t[0] >= 1000.0f) {
                flaggedLamp += flagged;
                if (flagged) {
                    // 16 · 2⁴ = 256: the most the shortest exposure can say, below the truth.
                    const float m = lum(merged->radiance.at<cv::Vec3f>(y, x));
                    EXPECT_NEAR(m, 256.0f, 1.0f);
                    EXPECT_LT(m, lum(t));
                }
            } else if (t[0] == 40.0f) {
                flaggedRed += flagged;
            } else {
                flaggedElsewhere += flagged;
            }
        }
    EXPECT_GT(flaggedLamp, 150);  // the lamp's ~200 pixels
    // The red patch's red channel clips even at −4 (its colour ratios kept by the curve): it is
    // a lower bound too, and flagged.
    EXPECT_EQ(flaggedRed, 600);
    EXPECT_EQ(flaggedElsewhere, 0);
}

TEST(HdrBracket, MeasuredStopsMatchTheExposures) {
    const cv::Mat truth = sceneRadiance();
    std::mt19937 rng(11);
    const cv::Mat a = exposeRgb8(truth, 0.0f, rng, kNoiseCodes);
    const cv::Mat b = exposeRgb8(truth, -2.0f, rng, kNoiseCodes);
    std::optional<float> measured = measuredStopsBetween(a, b, radiometry(), 64);
    ASSERT_TRUE(measured.has_value());
    EXPECT_NEAR(*measured, -2.0f, 0.1f);
    // A black pair has nothing to compare.
    const cv::Mat black = cv::Mat::zeros(truth.size(), CV_8UC3);
    EXPECT_FALSE(measuredStopsBetween(black, black, radiometry(), 64).has_value());
}

class Assembler : public ::testing::Test {
protected:
    void SetUp() override {
        std::mt19937 rng(5);
        const cv::Mat truth = sceneRadiance();
        for (float s : {0.0f, -4.0f, -8.0f}) frames_[s] = exposeRgb8(truth, s, rng, kNoiseCodes);
        auto a = BracketAssembler::create({.stops = {0.0f, -4.0f, -8.0f}}, radiometry());
        ASSERT_TRUE(a.ok()) << a.message();
        assembler_.emplace(std::move(*a));
    }
    // Feeds the frame of exposure `shown` labelled `label`.
    std::optional<MergedBracket> feed(float shown, std::optional<float> label) {
        const uint64_t sequence = sequence_++;
        return assembler_->add(frames_.at(shown), sequence, 1000 * sequence, label);
    }
    std::map<float, cv::Mat> frames_;
    std::optional<BracketAssembler> assembler_;
    uint64_t sequence_ = 100;
};

TEST_F(Assembler, MergesEachCompleteBracketInOrder) {
    EXPECT_FALSE(feed(0, 0.0f));
    EXPECT_FALSE(feed(-4, -4.0f));
    std::optional<MergedBracket> m = feed(-8, -8.0f);
    ASSERT_TRUE(m.has_value());
    EXPECT_EQ(m->firstSequence, 100u);
    EXPECT_EQ(m->lastSequence, 102u);
    EXPECT_TRUE(feed(0, 0.0f) == std::nullopt && feed(-4, -4.0f) == std::nullopt);
    EXPECT_TRUE(feed(-8, -8.0f).has_value());
    EXPECT_EQ(assembler_->counts().merged, 2u);
    EXPECT_EQ(assembler_->counts().dropped(), 0u);
}

TEST_F(Assembler, AFrameWhosePictureBelongsToAnotherExposureDropsTheBracket) {
    // The control landed a frame late: the frame labelled −4 still shows 0.
    feed(0, 0.0f);
    feed(0, -4.0f);
    EXPECT_FALSE(feed(-8, -8.0f).has_value());
    EXPECT_EQ(assembler_->counts().droppedMismatch, 1u);
    EXPECT_EQ(assembler_->counts().merged, 0u);
    EXPECT_NE(assembler_->lastDrop().find("late"), std::string::npos) << assembler_->lastDrop();
    // The next bracket is whole again and merges.
    feed(0, 0.0f);
    feed(-4, -4.0f);
    EXPECT_TRUE(feed(-8, -8.0f).has_value());
}

TEST_F(Assembler, MissingOutOfOrderAndUnlabelledFramesAreDroppedAndCounted) {
    feed(0, 0.0f);
    ++sequence_;  // a frame lost before it reached us
    EXPECT_FALSE(feed(-4, -4.0f).has_value());
    EXPECT_EQ(assembler_->counts().droppedMissing, 1u);

    feed(0, 0.0f);
    EXPECT_FALSE(feed(-8, -8.0f).has_value());  // −8 before −4
    EXPECT_EQ(assembler_->counts().droppedWrongExposure, 1u);

    feed(0, 0.0f);
    EXPECT_FALSE(feed(-4, std::nullopt).has_value());
    EXPECT_EQ(assembler_->counts().droppedUnlabelled, 1u);

    feed(0, 0.0f);
    feed(-4, -4.0f);
    EXPECT_FALSE(feed(0, 0.0f).has_value());  // cut short by the next bracket, which goes on
    EXPECT_EQ(assembler_->counts().droppedMissing, 2u);
    feed(-4, -4.0f);
    EXPECT_TRUE(feed(-8, -8.0f).has_value());
    EXPECT_EQ(assembler_->counts().merged, 1u);
    EXPECT_EQ(assembler_->counts().dropped(), 4u);
}

TEST_F(Assembler, ARotatedCycleIsDroppedEvenWherePairsShareNoWellExposedPixel) {
    // Each control landed a whole step late: the frames labelled 0, −4, −8 show −8, 0, −4. The
    // first pair is 8 stops apart and shares no pixel well exposed in both, so no ratio measures
    // it; but the frame labelled darker is the brighter one wherever either exposes anything.
    EXPECT_FALSE(measuredStopsBetween(frames_.at(-8), frames_.at(0), radiometry(), 64));
    EXPECT_TRUE(exposureOrderContradicted(frames_.at(-8), frames_.at(0), -4.0f, 64));
    EXPECT_FALSE(exposureOrderContradicted(frames_.at(0), frames_.at(-8), -8.0f, 64));
    EXPECT_FALSE(exposureOrderContradicted(frames_.at(0), frames_.at(0), -4.0f, 64));
    feed(-8, 0.0f);
    feed(0, -4.0f);
    EXPECT_FALSE(feed(-4, -8.0f).has_value());
    EXPECT_EQ(assembler_->counts().droppedMismatch, 1u);
    EXPECT_EQ(assembler_->counts().merged, 0u);
    EXPECT_NE(assembler_->lastDrop().find("ordered against"), std::string::npos)
        << assembler_->lastDrop();
}

TEST(HdrBracket, StopsAreChecked) {
    EXPECT_TRUE(checkBracketStops({0, -4, -8}, "x"));
    EXPECT_FALSE(checkBracketStops({0}, "x"));
    EXPECT_FALSE(checkBracketStops({0, -0.5f}, "x"));
    EXPECT_FALSE(checkBracketStops({0, NAN}, "x"));
    EXPECT_FALSE(checkBracketStops({0, -40}, "x"));
    EXPECT_FALSE(BracketAssembler::create({.stops = {}}, radiometry()).ok());
}

// ---- the fisheye → map step keeps a small sun's power --------------------------------------

// An equidistant 190° lens on 640×480 (the demo's, examples/demo/fisheye.yaml): θ = r / f.
CameraCalibration equidistantLens() {
    const double f = 144.75;
    auto c = CameraCalibration::create(cv::Matx33d(f, 0, 319.5, 0, f, 239.5, 0, 0, 1), {0, 0, 0, 0},
                                       {640, 480}, DistortionModel::Fisheye, "equidistant");
    EXPECT_TRUE(c.ok());
    return *c;
}

// The lens's view of a black sky holding one sun: each pixel the mean over its area of the
// sun's radiance (64 sub-samples a side near the sun), so Σ pixel · pixel solid angle is the
// sun's power. A pixel's solid angle for θ = r/f is sin θ / (θ f²) per unit of image area.
struct SunFrame {
    cv::Mat image;
    double framePower = 0.0;  // Σ pixel value · its solid angle
    double truePower = 0.0;   // L · 2π(1 − cos α)
};

SunFrame sunFrame(const CameraCalibration& lens, const cv::Vec3d& fisheyeDir, double radiusDeg,
                  float radiance) {
    SunFrame s;
    s.image = cv::Mat::zeros(lens.imageSize(), CV_32FC3);
    const double f = lens.fx();
    const double cosAlpha = std::cos(radiusDeg * M_PI / 180.0);
    s.truePower = radiance * 2.0 * M_PI * (1.0 - cosAlpha);
    auto direction = [&](double px, double py) {
        const double u = (px - lens.cx()) / f, v = (py - lens.cy()) / f;
        const double theta = std::hypot(u, v);
        const double k = theta > 1e-12 ? std::sin(theta) / theta : 1.0;
        return cv::Vec3d(u * k, v * k, std::cos(theta));
    };
    const cv::Vec3d sun = fisheyeDir / cv::norm(fisheyeDir);
    constexpr int kSub = 64;
    for (int y = 0; y < s.image.rows; ++y)
        for (int x = 0; x < s.image.cols; ++x) {
            if (direction(x, y).dot(sun) < std::cos((radiusDeg + 2.0) * M_PI / 180.0)) continue;
            int inside = 0;
            for (int sy = 0; sy < kSub; ++sy)
                for (int sx = 0; sx < kSub; ++sx)
                    inside += direction(x - 0.5 + (sx + 0.5) / kSub, y - 0.5 + (sy + 0.5) / kSub)
                                  .dot(sun) >= cosAlpha;
            const float value = radiance * float(inside) / (kSub * kSub);
            s.image.at<cv::Vec3f>(y, x) = cv::Vec3f(value, value, value);
            const double theta = std::hypot((x - lens.cx()) / f, (y - lens.cy()) / f);
            s.framePower += value * (theta > 1e-9 ? std::sin(theta) / theta : 1.0) / (f * f);
        }
    return s;
}

double mapPower(const cv::Mat& map, cv::Vec3d* centroid = nullptr) {
    double power = 0.0;
    cv::Vec3d weighted(0, 0, 0);
    for (int y = 0; y < map.rows; ++y)
        for (int x = 0; x < map.cols; ++x) {
            const double p =
                map.at<cv::Vec3f>(y, x)[1] * equirectTexelSolidAngle(y, map.cols, map.rows);
            power += p;
            weighted += p * equirectTexelDirection(x, y, map.cols, map.rows);
        }
    if (centroid) *centroid = weighted / cv::norm(weighted);
    return power;
}

struct SunCase {
    int mapWidth;
    double radiusDeg;
    double offAxisDeg;
};

class SmallSun : public ::testing::TestWithParam<SunCase> {};

// The outdoor case: a sun a few fisheye pixels across. Point sampling kept about a third
// of it at 1.4° texels; the footprint mean keeps it within 2 % at every map size, and in the
// right direction (within half a texel).
TEST_P(SmallSun, KeepsItsPowerAndDirectionInTheMap) {
    const CameraCalibration lens = equidistantLens();
    const SunCase c = GetParam();
    const double off = c.offAxisDeg * M_PI / 180.0;
    const cv::Vec3d fisheyeDir(std::sin(off) * 0.6, std::sin(off) * 0.8, std::cos(off));
    const SunFrame frame = sunFrame(lens, fisheyeDir, c.radiusDeg, 50000.0f);
    // The frame itself holds the sun's power (the test's own check of its solid angles).
    ASSERT_NEAR(frame.framePower / frame.truePower, 1.0, 0.01);

    auto f = FisheyeToEquirect::create(lens, {.width = c.mapWidth});
    ASSERT_TRUE(f.ok()) << f.message();
    Result<cv::Mat> map = f->apply(frame.image);
    ASSERT_TRUE(map.ok()) << map.message();
    cv::Vec3d centroid;
    const double power = mapPower(*map, &centroid);
    const cv::Vec3d trueDir = f->worldFromFisheye() * (fisheyeDir / cv::norm(fisheyeDir));
    const double errorDeg = std::acos(std::clamp(centroid.dot(trueDir), -1.0, 1.0)) * 180.0 / M_PI;
    // What point sampling each texel's centre (the lookup before) keeps of the same sun.
    cv::Mat pointSampled;
    cv::remap(frame.image, pointSampled, f->mapX(), f->mapY(), cv::INTER_LINEAR,
              cv::BORDER_CONSTANT);
    const double pointPower = mapPower(pointSampled);
    std::printf(
        "map %d, sun %.2f° radius at %.0f° off axis: power map/truth %.4f (point "
        "sampled %.3f), direction %.3f°\n",
        c.mapWidth, c.radiusDeg, c.offAxisDeg, power / frame.truePower,
        pointPower / frame.truePower, errorDeg);
    EXPECT_NEAR(power / frame.truePower, 1.0, 0.02);
    EXPECT_LT(errorDeg, 0.5 * 360.0 / c.mapWidth);
}

INSTANTIATE_TEST_SUITE_P(Vision, SmallSun,
                         ::testing::Values(SunCase{256, 0.53, 40.0}, SunCase{256, 0.27, 75.0},
                                           SunCase{1024, 0.53, 40.0}, SunCase{64, 0.53, 10.0},
                                           SunCase{512, 2.0, 60.0}),
                         [](const auto& p) { return "case" + std::to_string(p.index); });

// Every texel's footprint weights sum to one: a uniform sky stays uniform, and a clipped flag
// reaches exactly the texels whose footprint holds it.
TEST(SmallSun, UniformSkyStaysUniformAndFlagsFollowTheFootprint) {
    const CameraCalibration lens = equidistantLens();
    auto f = FisheyeToEquirect::create(lens, {.width = 256});
    ASSERT_TRUE(f.ok());
    cv::Mat sky(lens.imageSize(), CV_32FC3, cv::Scalar(2.0, 3.0, 4.0));
    Result<cv::Mat> map = f->apply(sky);
    ASSERT_TRUE(map.ok());
    double worst = 0.0;
    for (int y = 0; y < map->rows; ++y)
        for (int x = 0; x < map->cols; ++x)
            worst = std::max(worst, std::abs(map->at<cv::Vec3f>(y, x)[2] - 4.0));
    EXPECT_LT(worst, 1e-4);

    cv::Mat flags = cv::Mat::zeros(lens.imageSize(), CV_8U);
    flags.at<uint8_t>(240, 320) = 1;  // the zenith's pixel
    Result<cv::Mat> texels = f->applyAny(flags);
    ASSERT_TRUE(texels.ok());
    const int set = cv::countNonZero(*texels);
    EXPECT_GT(set, 0);
    for (int y = 0; y < texels->rows; ++y)
        for (int x = 0; x < texels->cols; ++x)
            if (texels->at<uint8_t>(y, x)) {
                EXPECT_LT(y, 4) << "a flag at the zenith reached row " << y;
            }
}

}  // namespace
}  // namespace previs
