// FreeD input calibration (net/freed_calibration.h) on the demo take's real tracked motion: the
// tracker's packets are synthesised from the take's ground-truth camera path with a known mount
// offset, stage placement and delay, FreeD's quantisation (each packet goes through the
// encoder, a freed.csv and the decoder), receipt jitter and the tracker's own noise; the camera
// side is the tag tracker's own poses of the take's frames, with their real noise.
#include "net/freed_calibration.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "net/freed.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

constexpr double kDegPerRad = 180.0 / M_PI;

struct DemoTake {
    std::vector<TimedPose> tracked;  // the tag tracker's worldFromCamera of each frame
    std::vector<TimedPose> truth;    // the rendered camera path
};

// tests/net/data/demo_camera_poses.csv (tests/net/data/README.md says how it was made).
DemoTake loadDemoTake() {
    DemoTake take;
    std::ifstream in(testing::sourcePath("tests/net/data/demo_camera_poses.csv"));
    std::string line;
    std::getline(in, line);  // header
    while (std::getline(in, line)) {
        std::stringstream s(line);
        std::string field, kind;
        std::getline(s, field, ',');
        TimedPose p;
        p.timestampNs = std::stoll(field);
        std::getline(s, kind, ',');
        for (int i = 0; i < 16; ++i) {
            std::getline(s, field, ',');
            p.pose.val[i] = std::stod(field);
        }
        (kind == "truth" ? take.truth : take.tracked).push_back(p);
    }
    return take;
}

cv::Matx33d rotationOf(const cv::Matx44d& m) { return m.get_minor<3, 3>(0, 0); }
cv::Vec3d translationOf(const cv::Matx44d& m) { return {m(0, 3), m(1, 3), m(2, 3)}; }

cv::Matx44d rigid(const cv::Matx33d& r, const cv::Vec3d& t) {
    cv::Matx44d m = cv::Matx44d::eye();
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) m(i, j) = r(i, j);
        m(i, 3) = t[i];
    }
    return m;
}

// Rodrigues' formula: the rotation by |v| radians about v.
cv::Matx33d rotationOfVector(const cv::Vec3d& v) {
    const double angle = cv::norm(v);
    if (angle == 0) return cv::Matx33d::eye();
    const cv::Vec3d k = v / angle;
    const cv::Matx33d kx(0, -k[2], k[1], k[2], 0, -k[0], -k[1], k[0], 0);
    return cv::Matx33d::eye() + std::sin(angle) * kx + (1 - std::cos(angle)) * kx * kx;
}

double angleDeg(const cv::Matx33d& a, const cv::Matx33d& b) {
    const cv::Matx33d r = a.t() * b;
    const cv::Vec3d v(r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1));
    return std::atan2(0.5 * cv::norm(v), 0.5 * (cv::trace(r) - 1)) * kDegPerRad;
}

cv::Matx44d inverse(const cv::Matx44d& m) {
    const cv::Matx33d rt = rotationOf(m).t();
    return rigid(rt, -(rt * translationOf(m)));
}

// The rig the packets are made for: a tracker 12 cm above and 8 cm behind the optical centre
// (camera axes: y down, z forward), tilted 3° on its mount; the tracker's stage origin 2 m away
// on the floor, turned 35° from the board's axes and 0.8° off level; its packets 47 ms later
// than the frames. Noise: an optical tracker's 0.5 mm and 0.02° (σ per axis), network jitter
// of 0.5 ms (one-sided: a packet is only ever late), 60 packets a second.
struct Rig {
    cv::Matx44d worldFromStage =
        rigid(rotationOfVector({0.8 / kDegPerRad, 35 / kDegPerRad, 0}), {1.8, -0.9, 2.4});
    cv::Matx44d bodyFromCamera =
        rigid(rotationOfVector({3 / kDegPerRad, 0, 0.5 / kDegPerRad}), {0.01, 0.12, 0.08});
    double delayMs = 47;
    double positionNoiseMm = 0.5;
    double rotationNoiseDeg = 0.02;
    double jitterMs = 0.5;
    double rateHz = 60;
};

// The packets of the rig following `path`, written to a freed.csv as the daemon records them
// and read back: every pose goes through FreeD's quantisation.
std::vector<TimedPose> recordPackets(const std::vector<TimedPose>& path, const Rig& rig,
                                     uint32_t seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> normal(0.0, 1.0);
    std::vector<std::pair<int64_t, FreedBytes>> received;
    const int64_t periodNs = std::llround(1e9 / rig.rateHz);
    // A real tracker's clock is not locked to the camera's: start at an arbitrary phase.
    for (int64_t t = path.front().timestampNs + int64_t(rng() % periodNs);
         t <= path.back().timestampNs; t += periodNs) {
        const cv::Matx44d worldFromCamera = *interpolatePose(path, t, INT64_MAX);
        cv::Matx44d stageFromBody =
            inverse(rig.worldFromStage) * worldFromCamera * inverse(rig.bodyFromCamera);
        const cv::Vec3d dr =
            cv::Vec3d(normal(rng), normal(rng), normal(rng)) * (rig.rotationNoiseDeg / kDegPerRad);
        const cv::Vec3d dt =
            cv::Vec3d(normal(rng), normal(rng), normal(rng)) * (rig.positionNoiseMm / 1000.0);
        stageFromBody = rigid(rotationOf(stageFromBody) * rotationOfVector(dr),
                              translationOf(stageFromBody) + dt);
        const int64_t late = std::llround(std::abs(normal(rng)) * rig.jitterMs * 1e6);
        received.push_back({t + std::llround(rig.delayMs * 1e6) + late,
                            encodeFreed(stageFromBody, LensSample{}, 7).bytes});
    }
    std::sort(received.begin(), received.end());
    const std::string file =
        (testing::scratchDir("freed_calibration_test") / fmt::format("freed_{}.csv", seed))
            .string();
    {
        std::ofstream out(file);
        out << kFreedRecordingHeader << '\n';
        for (const auto& [ns, bytes] : received) out << freedRecordingLine(ns, bytes);
    }
    Result<FreedRecording> recording = loadFreedRecording(file, 7);
    EXPECT_TRUE(recording.ok()) << (recording.ok() ? "" : recording.message());
    return recording.ok() ? recording->stageFromBody : std::vector<TimedPose>{};
}

// The RMS rotation (degrees, per axis) and position (mm, per axis) error of the tag tracker on
// the take: the camera side's noise, measured rather than assumed.
struct TrackingNoise {
    double rotationDeg = 0, positionMm = 0;
};

TrackingNoise trackingNoise(const DemoTake& take) {
    double r2 = 0, p2 = 0;
    for (size_t i = 0; i < take.tracked.size(); ++i) {
        const double a = angleDeg(rotationOf(take.tracked[i].pose), rotationOf(take.truth[i].pose));
        const double d =
            cv::norm(translationOf(take.tracked[i].pose) - translationOf(take.truth[i].pose));
        r2 += a * a;
        p2 += d * d * 1e6;
    }
    const double n = 3.0 * double(take.tracked.size());
    return {std::sqrt(r2 / n), std::sqrt(p2 / n)};
}

std::vector<TimedPose> slice(const std::vector<TimedPose>& v, size_t first, size_t last) {
    return {v.begin() + long(first), v.begin() + long(last)};
}

}  // namespace

TEST(FreedCalibration, DemoTakeIsTheTrackedMotion) {
    const DemoTake take = loadDemoTake();
    ASSERT_EQ(take.tracked.size(), 60u);
    ASSERT_EQ(take.truth.size(), 60u);
    const TrackingNoise noise = trackingNoise(take);
    fmt::print("tag tracking noise on the demo take: {:.3f}° and {:.2f} mm RMS per axis\n",
               noise.rotationDeg, noise.positionMm);
    EXPECT_LT(noise.rotationDeg, 0.5);
    EXPECT_LT(noise.positionMm, 10.0);
}

namespace {

// How well the rotation speeds can time the two series: the speed noise of one camera interval
// (two independent rotation errors on each side, per axis) over the speeds' sensitivity to a
// shift of the path, sqrt(Σ (ds/dτ)²) (the Cramér–Rao bound of a time shift in white noise).
double delaySigmaMs(const std::vector<TimedPose>& path, double rotationNoiseDeg) {
    constexpr int64_t kShiftNs = 5'000'000;
    double sum = 0, dtS = 0;
    for (size_t i = 1; i < path.size(); ++i) {
        const int64_t t0 = path[i - 1].timestampNs, t1 = path[i].timestampNs;
        dtS = double(t1 - t0) * 1e-9;
        auto speedAt = [&](int64_t shift) {
            std::optional<cv::Matx44d> a = interpolatePose(path, t0 + shift, INT64_MAX);
            std::optional<cv::Matx44d> b = interpolatePose(path, t1 + shift, INT64_MAX);
            if (!a || !b) return std::nan("");
            return angleDeg(rotationOf(*a), rotationOf(*b)) / dtS;
        };
        const double slope = (speedAt(kShiftNs) - speedAt(-kShiftNs)) / (2 * kShiftNs * 1e-6);
        if (!std::isnan(slope)) sum += slope * slope;  // (deg/s per ms)²
    }
    const double speedNoise = std::sqrt(2.0) * rotationNoiseDeg / dtS;
    return speedNoise / std::sqrt(sum);
}

}  // namespace

// The whole take: an arc about the vertical, a hold, an arc about an axis 14° from it (demo
// README). Five draws of the tracker's noise and jitter.
TEST(FreedCalibration, RecoversDelayAndMountOffsetFromDemoTake) {
    const DemoTake take = loadDemoTake();
    const TrackingNoise tags = trackingNoise(take);
    const Rig rig;
    // Noise per axis of a frame/packet pair: the tags' (measured) and the tracker's (injected).
    const double pairRotationDeg = std::hypot(tags.rotationDeg, rig.rotationNoiseDeg);
    const double pairPositionMm = std::hypot(tags.positionMm, rig.positionNoiseMm);
    // The delay: the jitter's mean lateness (σ·√(2/π)) biases it; 4σ of the timing noise and
    // half a grid step of the search on top.
    const double sigmaMs = delaySigmaMs(take.truth, pairRotationDeg);
    const double delayToleranceMs = rig.jitterMs * std::sqrt(2 / M_PI) + 4 * sigmaMs + 0.5;
    fmt::print("delay: timing σ {:.2f} ms, tolerance {:.2f} ms\n", sigmaMs, delayToleranceMs);
    for (uint32_t seed = 1; seed <= 5; ++seed) {
        SCOPED_TRACE(fmt::format("seed {}", seed));
        const std::vector<TimedPose> packets = recordPackets(take.truth, rig, seed);
        Result<FreedDelay> delay = estimateFreedDelay(take.tracked, packets);
        ASSERT_TRUE(delay.ok()) << delay.message();
        Result<FreedCalibration> c = solveFreedCalibration(take.tracked, packets, *delay);
        ASSERT_TRUE(c.ok()) << c.message();
        const double offsetErrMm =
            cv::norm(translationOf(c->bodyFromCamera) - translationOf(rig.bodyFromCamera)) * 1e3;
        const double mountErrDeg =
            angleDeg(rotationOf(c->bodyFromCamera), rotationOf(rig.bodyFromCamera));
        const double stageErrMm =
            cv::norm(translationOf(c->worldFromStage) - translationOf(rig.worldFromStage)) * 1e3;
        const double stageErrDeg =
            angleDeg(rotationOf(c->worldFromStage), rotationOf(rig.worldFromStage));
        fmt::print(
            "seed {}: delay {:.2f} ms (corr {:.3f}), fitted {:.2f} ± {:.2f} ms; mount offset error "
            "{:.2f} mm {:.3f}° "
            "(σ {:.2f} mm {:.3f}°); stage error {:.1f} mm {:.3f}°; residual {:.2f} mm {:.3f}° "
            "over {} pairs (+{} rejected)\n",
            seed, delay->delayMs, delay->correlation, c->delayMs, c->delaySigmaMs, offsetErrMm,
            mountErrDeg, c->mountSigmaMm, c->mountSigmaDeg, stageErrMm, stageErrDeg,
            c->rmsPositionMm, c->rmsRotationDeg, c->samples, c->rejected);
        EXPECT_NEAR(delay->delayMs, rig.delayMs, delayToleranceMs);
        EXPECT_GT(delay->correlation, 0.95);
        // The delay the poses fit best: within 4 of its own σ (the solver's, from the curvature
        // of the fit) of the true one plus the jitter's bias, and far tighter than the speeds'.
        ASSERT_GT(c->delaySigmaMs, 0.0);
        EXPECT_LT(c->delaySigmaMs, sigmaMs);
        EXPECT_NEAR(c->delayMs, rig.delayMs + rig.jitterMs * std::sqrt(2 / M_PI),
                    4 * c->delaySigmaMs + 0.1);
        // The residuals are the pair noise (3 axes) less what the 12 fitted parameters absorb.
        EXPECT_NEAR(c->rmsPositionMm, std::sqrt(3.0) * pairPositionMm,
                    0.35 * std::sqrt(3.0) * pairPositionMm);
        EXPECT_NEAR(c->rmsRotationDeg, std::sqrt(3.0) * pairRotationDeg,
                    0.35 * std::sqrt(3.0) * pairRotationDeg);
        // The solver's own 1σ (worst direction) bounds the error: 3σ per axis, √3 for the three
        // axes of the error's length.
        EXPECT_LT(offsetErrMm, 3 * std::sqrt(3.0) * c->mountSigmaMm);
        EXPECT_LT(mountErrDeg, 3 * std::sqrt(3.0) * c->mountSigmaDeg);
        // And that σ is what this noise allows with this motion: a few mm, tenths of a degree.
        EXPECT_LT(c->mountSigmaMm, 5.0);
        EXPECT_LT(c->mountSigmaDeg, 0.25);
        // The stage lies ~3 m from the camera: its rotation error moves it by ~5 cm per degree.
        EXPECT_LT(stageErrDeg, 3 * std::sqrt(3.0) * c->mountSigmaDeg);
        // Every frame's FreeD pose lands where the tags put the camera, as the service will
        // compute it per frame.
        EXPECT_EQ(c->rejected, 0);
        size_t posed = 0;
        for (const TimedPose& frame : take.truth) {
            std::optional<cv::Matx44d> pose = freedWorldFromCamera(*c, packets, frame.timestampNs);
            if (!pose) continue;
            ++posed;
            EXPECT_LT(cv::norm(translationOf(*pose) - translationOf(frame.pose)) * 1e3,
                      3 * std::sqrt(3.0) * pairPositionMm + offsetErrMm);
        }
        EXPECT_GE(posed, take.truth.size() - 2);  // the first frame has no packet before it
    }
}

// Frames 21–44 of the take: the camera stands still; there is nothing to time.
TEST(FreedCalibration, HeldCameraDelayRefused) {
    const DemoTake take = loadDemoTake();
    const std::vector<TimedPose> held = slice(take.tracked, 21, 45);
    const std::vector<TimedPose> packets = recordPackets(slice(take.truth, 21, 45), Rig{}, 1);
    Result<FreedDelay> delay = estimateFreedDelay(held, packets);
    ASSERT_FALSE(delay.ok());
    EXPECT_NE(delay.message().find("hardly turned"), std::string::npos) << delay.message();
    EXPECT_NE(delay.message().find("pan and stop"), std::string::npos) << delay.message();
}

// Frames 0–44: one arc about the vertical, then still. The delay is found, but every turn is
// about one axis, so the mount offset along it is unknowable.
TEST(FreedCalibration, PanOnlyCalibrationRefused) {
    const DemoTake take = loadDemoTake();
    const std::vector<TimedPose> pan = slice(take.tracked, 0, 45);
    const std::vector<TimedPose> packets = recordPackets(slice(take.truth, 0, 45), Rig{}, 1);
    Result<FreedDelay> delay = estimateFreedDelay(pan, packets);
    ASSERT_TRUE(delay.ok()) << delay.message();
    Result<FreedCalibration> c = solveFreedCalibration(pan, packets, *delay);
    ASSERT_FALSE(c.ok());
    EXPECT_NE(c.message().find("one axis only (panning"), std::string::npos) << c.message();
    EXPECT_NE(c.message().find("adding tilts"), std::string::npos) << c.message();
}

// The whole take's second arc turns about an axis only 14° from the first: enough here for a
// 1σ of ~3 mm, so a crew asking for 2 mm is told which axis is weak and what to add.
TEST(FreedCalibration, UncertainMountOffsetRefusedNamingTheMotion) {
    const DemoTake take = loadDemoTake();
    const std::vector<TimedPose> packets = recordPackets(take.truth, Rig{}, 1);
    Result<FreedDelay> delay = estimateFreedDelay(take.tracked, packets);
    ASSERT_TRUE(delay.ok()) << delay.message();
    FreedSolveOptions strict;
    strict.maxMountSigmaMm = 2;
    Result<FreedCalibration> c = solveFreedCalibration(take.tracked, packets, *delay, strict);
    ASSERT_FALSE(c.ok());
    EXPECT_NE(c.message().find("the mount offset is uncertain by ±"), std::string::npos)
        << c.message();
    EXPECT_NE(c.message().find("vertical axis"), std::string::npos) << c.message();
    EXPECT_NE(c.message().find("adding tilts"), std::string::npos) << c.message();
}

TEST(FreedCalibration, ApplyComposesRightToLeft) {
    FreedCalibration c;
    c.worldFromStage = rigid(rotationOfVector({0, M_PI / 2, 0}), {1, 2, 3});
    c.bodyFromCamera = rigid(cv::Matx33d::eye(), {0, 0.1, 0});
    const cv::Matx44d stageFromBody = rigid(cv::Matx33d::eye(), {0, 0, 1});
    // The lens is 0.1 m below the body (camera y down), the body 1 m along stage z, and the stage
    // turned a quarter about y: stage z is world x.
    const cv::Vec3d lens = translationOf(applyFreedCalibration(c, stageFromBody));
    EXPECT_NEAR(lens[0], 2.0, 1e-12);
    EXPECT_NEAR(lens[1], 2.1, 1e-12);
    EXPECT_NEAR(lens[2], 3.0, 1e-12);
}

TEST(FreedCalibration, InterpolatePoseSlerpsAndRefusesGaps) {
    const std::vector<TimedPose> series = {
        {1000, rigid(cv::Matx33d::eye(), {0, 0, 0})},
        {2000, rigid(rotationOfVector({0, 0.4, 0}), {1, 0, 0})},
        {9000, rigid(cv::Matx33d::eye(), {0, 0, 0})},
    };
    std::optional<cv::Matx44d> mid = interpolatePose(series, 1250, 5000);
    ASSERT_TRUE(mid);
    EXPECT_NEAR(angleDeg(rotationOf(*mid), rotationOfVector({0, 0.1, 0})), 0.0, 1e-9);
    EXPECT_NEAR(translationOf(*mid)[0], 0.25, 1e-12);
    EXPECT_TRUE(interpolatePose(series, 2000, 5000));   // on a sample
    EXPECT_FALSE(interpolatePose(series, 999, 5000));   // before the series
    EXPECT_FALSE(interpolatePose(series, 9001, 5000));  // after it
    EXPECT_FALSE(interpolatePose(series, 5000, 5000));  // across a 7 µs gap: lost, not bridged
}

namespace {

std::string writeText(const std::string& name, const std::string& text) {
    const std::string path = (testing::scratchDir("freed_calibration_test") / name).string();
    std::ofstream(path) << text;
    return path;
}

std::string readText(const std::string& path) {
    std::ifstream in(path);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

FreedCalibration exampleCalibration() {
    const Rig rig;
    FreedCalibration c;
    c.worldFromStage = rig.worldFromStage;
    c.bodyFromCamera = rig.bodyFromCamera;
    c.delayMs = 47.25;
    c.delaySigmaMs = 0.21;
    c.delayCorrelation = 0.998;
    c.rmsPositionMm = 1.1;
    c.rmsRotationDeg = 0.06;
    c.mountSigmaMm = 3.4;
    c.mountSigmaDeg = 0.15;
    c.samples = 58;
    c.rejected = 2;
    c.created = "2026-12-05T09:00:00Z";
    return c;
}

}  // namespace

TEST(FreedCalibration, FileRoundTripsExactly) {
    const FreedCalibration c = exampleCalibration();
    const std::string path =
        (testing::scratchDir("freed_calibration_test") / "round_trip.toml").string();
    ASSERT_TRUE(writeFreedCalibration(path, c).ok());
    Result<FreedCalibration> back = loadFreedCalibration(path);
    ASSERT_TRUE(back.ok()) << back.message();
    // Shortest round-trip decimals: every double reads back bit for bit.
    for (int i = 0; i < 16; ++i) {
        EXPECT_EQ(back->worldFromStage.val[i], c.worldFromStage.val[i]);
        EXPECT_EQ(back->bodyFromCamera.val[i], c.bodyFromCamera.val[i]);
    }
    EXPECT_EQ(back->delayMs, c.delayMs);
    EXPECT_EQ(back->delaySigmaMs, c.delaySigmaMs);
    EXPECT_EQ(back->delayCorrelation, c.delayCorrelation);
    EXPECT_EQ(back->rmsPositionMm, c.rmsPositionMm);
    EXPECT_EQ(back->rmsRotationDeg, c.rmsRotationDeg);
    EXPECT_EQ(back->mountSigmaMm, c.mountSigmaMm);
    EXPECT_EQ(back->mountSigmaDeg, c.mountSigmaDeg);
    EXPECT_EQ(back->samples, c.samples);
    EXPECT_EQ(back->rejected, c.rejected);
    EXPECT_EQ(back->created, c.created);
    EXPECT_NE(readText(path).find("version = 1\n"), std::string::npos);
}

TEST(FreedCalibration, FileErrorsNameFileLineAndKey) {
    const FreedCalibration c = exampleCalibration();
    const std::string good = (testing::scratchDir("freed_calibration_test") / "good.toml").string();
    ASSERT_TRUE(writeFreedCalibration(good, c).ok());
    const std::string text = readText(good);
    auto replaced = [&](const std::string& from, const std::string& to) {
        std::string t = text;
        const size_t at = t.find(from);
        EXPECT_NE(at, std::string::npos) << from;
        return t.replace(at, from.size(), to);
    };
    struct Case {
        std::string name, text, expected;
    };
    const std::vector<Case> cases = {
        {"typo.toml", replaced("delay_ms =", "delay_mss ="), "delay_mss"},
        {"no_delay.toml", replaced("delay_ms = 47.25\n", ""), "'delay_ms' is missing"},
        {"far_delay.toml", replaced("delay_ms = 47.25", "delay_ms = 20000"),
         "line 6: 'delay_ms' is 20000"},
        {"short_matrix.toml", replaced("world_from_stage = [", "world_from_stage = [1, "),
         "world_from_stage"},
        {"not_rigid.toml", replaced("body_from_camera = [", "body_from_camera = [2"),
         "line 13: 'body_from_camera' is not a rigid transform"},
        {"future.toml", replaced("version = 1", "version = 2"), "update previs"},
        {"wrong_format.toml", replaced("previs-freed-calibration", "previs-session"),
         "'format' is 'previs-session'"},
        {"syntax.toml", replaced("samples = 58", "samples = "), "syntax.toml"},
    };
    for (const Case& k : cases) {
        const std::string path = writeText(k.name, k.text);
        Result<FreedCalibration> r = loadFreedCalibration(path);
        ASSERT_FALSE(r.ok()) << k.name;
        EXPECT_NE(r.message().find(path), std::string::npos) << r.message();
        EXPECT_NE(r.message().find(k.expected), std::string::npos) << r.message();
    }
    Result<FreedCalibration> missing = loadFreedCalibration("/nonexistent/freed_calibration.toml");
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.message().find("/nonexistent/freed_calibration.toml"), std::string::npos);
}

TEST(FreedCalibration, RecordingLinesReadBack) {
    const FreedBytes bytes =
        encodeFreed(rigid(rotationOfVector({0.1, 0.2, 0.3}), {1, 2, 3}), LensSample{}, 7).bytes;
    const std::string line = freedRecordingLine(123456789, bytes);
    EXPECT_EQ(line.size(), std::string("123456789,").size() + 58 + 1);
    EXPECT_EQ(line.substr(0, 12), "123456789,d1");
    FreedBytes other = bytes;
    other[1] = 3;
    other[28] = freedChecksum(other);
    FreedBytes broken = bytes;
    broken[28] ^= 1;
    const std::string path =
        writeText("freed.csv", std::string(kFreedRecordingHeader) + "\n" + line +
                                   freedRecordingLine(123456790, other) +
                                   freedRecordingLine(123456791, broken) + "123456792,d1");  // cut
    Result<FreedRecording> r = loadFreedRecording(path, 7);
    ASSERT_TRUE(r.ok()) << r.message();
    ASSERT_EQ(r->stageFromBody.size(), 1u);  // camera 3 skipped, the cut last line ignored
    EXPECT_EQ(r->stageFromBody[0].timestampNs, 123456789);
    EXPECT_EQ(r->rejected, 1u);  // the bad checksum
    EXPECT_EQ(r->cameraIds, (std::vector<uint8_t>{3, 7}));
    const FreedParse parse = decodeFreed(bytes, 7);
    EXPECT_EQ(r->stageFromBody[0].pose, worldFromFreed(parse.packet));

    const std::string bad =
        writeText("bad.csv", std::string(kFreedRecordingHeader) + "\n" + line + "12x,d1ff\n");
    Result<FreedRecording> e = loadFreedRecording(bad, 7);
    ASSERT_FALSE(e.ok());
    EXPECT_NE(e.message().find(bad + "' line 3"), std::string::npos) << e.message();
    const std::string noHeader = writeText("no_header.csv", line);
    Result<FreedRecording> h = loadFreedRecording(noHeader, 7);
    ASSERT_FALSE(h.ok());
    EXPECT_NE(h.message().find("line 1: expected the header 'receivedNs,packet'"),
              std::string::npos)
        << h.message();
}

}  // namespace previs
