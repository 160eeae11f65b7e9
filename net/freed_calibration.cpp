#include "net/freed_calibration.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <opencv2/calib3d.hpp>

#include "base/atomic_file.h"
#include "base/bounded_file.h"
#include "base/toml_reader.h"
#include "net/freed.h"

namespace previs {

namespace {

constexpr double kDegPerRad = 180.0 / M_PI;

cv::Matx33d rotationOf(const cv::Matx44d& m) {
    return cv::Matx33d(m(0, 0), m(0, 1), m(0, 2), m(1, 0), m(1, 1), m(1, 2), m(2, 0), m(2, 1),
                       m(2, 2));
}

cv::Vec3d translationOf(const cv::Matx44d& m) { return {m(0, 3), m(1, 3), m(2, 3)}; }

cv::Matx44d rigid(const cv::Matx33d& r, const cv::Vec3d& t) {
    return cv::Matx44d(r(0, 0), r(0, 1), r(0, 2), t[0], r(1, 0), r(1, 1), r(1, 2), t[1], r(2, 0),
                       r(2, 1), r(2, 2), t[2], 0, 0, 0, 1);
}

cv::Matx44d rigidInverse(const cv::Matx44d& m) {
    const cv::Matx33d rt = rotationOf(m).t();
    return rigid(rt, -(rt * translationOf(m)));
}

// The angle of the rotation aFromB: atan2 keeps small angles exact, where acos of the trace
// loses half the digits (a held camera turns by hundredths of a degree).
double rotationAngleRad(const cv::Matx33d& r) {
    const cv::Vec3d v(r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1));
    return std::atan2(0.5 * cv::norm(v), 0.5 * (cv::trace(r) - 1.0));
}

// Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method: the largest diagonal
// term picks the branch, so no division by a small number).
cv::Vec4d quaternionOf(const cv::Matx33d& r) {
    const double tr = cv::trace(r);
    cv::Vec4d q;
    if (tr > r(0, 0) && tr > r(1, 1) && tr > r(2, 2)) {
        const double s = 2.0 * std::sqrt(1.0 + tr);
        q = {0.25 * s, (r(2, 1) - r(1, 2)) / s, (r(0, 2) - r(2, 0)) / s, (r(1, 0) - r(0, 1)) / s};
    } else if (r(0, 0) > r(1, 1) && r(0, 0) > r(2, 2)) {
        const double s = 2.0 * std::sqrt(1.0 + r(0, 0) - r(1, 1) - r(2, 2));
        q = {(r(2, 1) - r(1, 2)) / s, 0.25 * s, (r(0, 1) + r(1, 0)) / s, (r(0, 2) + r(2, 0)) / s};
    } else if (r(1, 1) > r(2, 2)) {
        const double s = 2.0 * std::sqrt(1.0 + r(1, 1) - r(0, 0) - r(2, 2));
        q = {(r(0, 2) - r(2, 0)) / s, (r(0, 1) + r(1, 0)) / s, 0.25 * s, (r(1, 2) + r(2, 1)) / s};
    } else {
        const double s = 2.0 * std::sqrt(1.0 + r(2, 2) - r(0, 0) - r(1, 1));
        q = {(r(1, 0) - r(0, 1)) / s, (r(0, 2) + r(2, 0)) / s, (r(1, 2) + r(2, 1)) / s, 0.25 * s};
    }
    return q / cv::norm(q);
}

cv::Matx33d rotationOfQuaternion(const cv::Vec4d& q) {
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    return cv::Matx33d(1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                       2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                       2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y));
}

cv::Vec4d slerp(cv::Vec4d a, const cv::Vec4d& b, double u) {
    double c = a.dot(b);
    if (c < 0) {  // the shorter way round: q and −q are the same rotation
        a = -a;
        c = -c;
    }
    if (c > 0.9995) return (a * (1 - u) + b * u) / cv::norm(a * (1 - u) + b * u);
    const double theta = std::acos(c);
    return (a * std::sin((1 - u) * theta) + b * std::sin(u * theta)) / std::sin(theta);
}

// The first sample at or after `t`; series.size() when none.
size_t firstAtOrAfter(std::span<const TimedPose> series, int64_t t) {
    auto it = std::lower_bound(series.begin(), series.end(), t,
                               [](const TimedPose& p, int64_t v) { return p.timestampNs < v; });
    return size_t(it - series.begin());
}

int64_t medianIntervalNs(std::span<const TimedPose> series) {
    std::vector<int64_t> dt;
    for (size_t i = 1; i < series.size(); ++i)
        dt.push_back(series[i].timestampNs - series[i - 1].timestampNs);
    if (dt.empty()) return 0;
    std::nth_element(dt.begin(), dt.begin() + dt.size() / 2, dt.end());
    return dt[dt.size() / 2];
}

// A gap longer than a few packet intervals is a lost stretch, not something to interpolate over.
int64_t packetGapLimitNs(std::span<const TimedPose> series) {
    return std::max<int64_t>(4 * medianIntervalNs(series), 50'000'000);
}

double median(std::vector<double> v) {
    if (v.empty()) return 0;
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
}

// One step of the camera series: consecutive frames no further apart than a lost frame or two.
struct Interval {
    int64_t startNs = 0, endNs = 0;
    double speedDegPerS = 0;
};

std::vector<Interval> cameraIntervals(std::span<const TimedPose> camera) {
    const int64_t maxDt = 3 * medianIntervalNs(camera);
    std::vector<Interval> out;
    for (size_t i = 1; i < camera.size(); ++i) {
        const int64_t dt = camera[i].timestampNs - camera[i - 1].timestampNs;
        if (dt <= 0 || dt > maxDt) continue;
        const double angle =
            rotationAngleRad(rotationOf(camera[i - 1].pose).t() * rotationOf(camera[i].pose));
        out.push_back({camera[i - 1].timestampNs, camera[i].timestampNs,
                       angle * kDegPerRad / (double(dt) * 1e-9)});
    }
    return out;
}

// The fastest turn over ~100 ms windows: per-frame speeds of a held camera are mostly tracking
// noise, which a longer window averages away.
double peakSpeedDegPerS(std::span<const TimedPose> camera) {
    constexpr int64_t kWindowNs = 100'000'000;
    double peak = 0;
    size_t j = 0;
    for (size_t i = 0; i < camera.size(); ++i) {
        j = std::max(j, i + 1);
        while (j < camera.size() && camera[j].timestampNs - camera[i].timestampNs < kWindowNs) ++j;
        if (j >= camera.size()) break;
        const double dt = double(camera[j].timestampNs - camera[i].timestampNs) * 1e-9;
        if (dt > 3 * kWindowNs * 1e-9) continue;
        const double a =
            rotationAngleRad(rotationOf(camera[i].pose).t() * rotationOf(camera[j].pose));
        peak = std::max(peak, a * kDegPerRad / dt);
    }
    return peak;
}

// The packet series as quaternions, so the delay search does not convert per evaluation.
struct RotationSeries {
    std::vector<int64_t> timesNs;
    std::vector<cv::Vec4d> rotations;
    int64_t maxGapNs = 0;

    std::optional<cv::Vec4d> at(int64_t t) const {
        auto it = std::lower_bound(timesNs.begin(), timesNs.end(), t);
        if (it == timesNs.end()) return std::nullopt;
        const size_t hi = size_t(it - timesNs.begin());
        if (timesNs[hi] == t) return rotations[hi];
        if (hi == 0 || timesNs[hi] - timesNs[hi - 1] > maxGapNs) return std::nullopt;
        const double u = double(t - timesNs[hi - 1]) / double(timesNs[hi] - timesNs[hi - 1]);
        return slerp(rotations[hi - 1], rotations[hi], u);
    }
};

// θ = 4·atan2(|a − b|, |a + b|) with b on a's side: exact for small angles, where acos of the
// dot product loses half the digits.
double quaternionAngleRad(const cv::Vec4d& a, cv::Vec4d b) {
    if (a.dot(b) < 0) b = -b;
    return 4.0 * std::atan2(cv::norm(a - b), cv::norm(a + b));
}

// Pearson correlation of the camera's speeds with the packets' over the same intervals shifted
// by `delayNs`; NaN when the packets cover too few of them. Reading the packet series over the
// camera's own intervals makes both speeds averages over the same time, so a 15 fps camera and a
// 60 Hz tracker give the same curve and the peak is not biased by the rates.
double correlationAt(const std::vector<Interval>& intervals, const RotationSeries& packets,
                     int64_t delayNs) {
    double sa = 0, sb = 0, saa = 0, sbb = 0, sab = 0;
    size_t n = 0;
    for (const Interval& iv : intervals) {
        std::optional<cv::Vec4d> a = packets.at(iv.startNs + delayNs);
        std::optional<cv::Vec4d> b = packets.at(iv.endNs + delayNs);
        if (!a || !b) continue;
        const double speed =
            quaternionAngleRad(*a, *b) * kDegPerRad / (double(iv.endNs - iv.startNs) * 1e-9);
        const double c = iv.speedDegPerS;
        sa += c, sb += speed, saa += c * c, sbb += speed * speed, sab += c * speed;
        ++n;
    }
    if (n < 8 || n * 5 < intervals.size() * 4) return std::nan("");
    const double cov = sab - sa * sb / double(n);
    const double va = saa - sa * sa / double(n), vb = sbb - sb * sb / double(n);
    if (va <= 0 || vb <= 0) return std::nan("");
    return cov / std::sqrt(va * vb);
}

}  // namespace

cv::Matx44d applyFreedCalibration(const FreedCalibration& calibration,
                                  const cv::Matx44d& stageFromBody) {
    return calibration.worldFromStage * stageFromBody * calibration.bodyFromCamera;
}

std::optional<cv::Matx44d> freedWorldFromCamera(const FreedCalibration& calibration,
                                                std::span<const TimedPose> stageFromBody,
                                                int64_t frameNs, int64_t maxGapNs) {
    std::optional<cv::Matx44d> body =
        interpolatePose(stageFromBody, frameNs + std::llround(calibration.delayMs * 1e6), maxGapNs);
    if (!body) return std::nullopt;
    return applyFreedCalibration(calibration, *body);
}

std::optional<cv::Matx44d> interpolatePose(std::span<const TimedPose> series, int64_t timestampNs,
                                           int64_t maxGapNs) {
    const size_t hi = firstAtOrAfter(series, timestampNs);
    if (hi == series.size()) return std::nullopt;
    if (series[hi].timestampNs == timestampNs) return series[hi].pose;
    if (hi == 0) return std::nullopt;
    const TimedPose& a = series[hi - 1];
    const TimedPose& b = series[hi];
    if (b.timestampNs - a.timestampNs > maxGapNs) return std::nullopt;
    const double u = double(timestampNs - a.timestampNs) / double(b.timestampNs - a.timestampNs);
    const cv::Vec4d q =
        slerp(quaternionOf(rotationOf(a.pose)), quaternionOf(rotationOf(b.pose)), u);
    return rigid(rotationOfQuaternion(q),
                 translationOf(a.pose) * (1 - u) + translationOf(b.pose) * u);
}

namespace {

// The correlation at every delay of the search grid, k·stepMs for k in [−steps, steps].
std::vector<double> correlationCurve(std::span<const TimedPose> worldFromCamera,
                                     std::span<const TimedPose> stageFromBody, int steps,
                                     double stepMs) {
    const std::vector<Interval> intervals = cameraIntervals(worldFromCamera);
    RotationSeries packets;
    packets.maxGapNs = packetGapLimitNs(stageFromBody);
    for (const TimedPose& p : stageFromBody) {
        packets.timesNs.push_back(p.timestampNs);
        packets.rotations.push_back(quaternionOf(rotationOf(p.pose)));
    }
    std::vector<double> corr(size_t(2 * steps + 1));
    for (int k = -steps; k <= steps; ++k)
        corr[size_t(k + steps)] = correlationAt(intervals, packets, std::llround(k * stepMs * 1e6));
    return corr;
}

// Another local maximum nearly as high as the peak, with a real valley between them, means two
// delays fit (a motion repeated at a regular beat); bumps on the peak's own slope from tracking
// noise have no such valley. Returns the rival's index, or nothing.
std::optional<size_t> rivalPeak(const std::vector<double>& corr, size_t best, double margin) {
    for (size_t i = 1; i + 1 < corr.size(); ++i) {
        if (i == best || std::isnan(corr[i]) || corr[i] < corr[i - 1] || corr[i] < corr[i + 1] ||
            corr[i] <= corr[best] - margin)
            continue;
        double valley = corr[i];
        for (size_t k = std::min(i, best); k <= std::max(i, best); ++k)
            if (!std::isnan(corr[k])) valley = std::min(valley, corr[k]);
        if (corr[i] - valley >= margin) return i;
    }
    return std::nullopt;
}

// The checks a usable peak passes, each failure saying what to do; the peak's index if all pass.
Result<size_t> distinctPeak(const std::vector<double>& corr, const FreedDelayOptions& options) {
    const double steps = double(corr.size() / 2);
    size_t best = corr.size();
    for (size_t i = 0; i < corr.size(); ++i)
        if (!std::isnan(corr[i]) && (best == corr.size() || corr[i] > corr[best])) best = i;
    if (best == corr.size())
        return makeError(
            "the FreeD packets do not cover the tracked frames at any delay within ±{} ms: "
            "were they recorded during the same take?",
            options.searchMs);
    const double peak = corr[best];
    if (best == 0 || best + 1 == corr.size() || std::isnan(corr[best - 1]) ||
        std::isnan(corr[best + 1]))
        return makeError(
            "the best match ({:.2f}) lies at the edge of the ±{} ms search: the packets and the "
            "frames are further apart in time than that, or belong to different cameras",
            peak, options.searchMs);
    if (peak < options.minCorrelation)
        return makeError(
            "the tracker's motion and the camera's do not match (correlation {:.2f}, needs {}): "
            "check the FreeD camera id, and that the board stayed in view while the camera "
            "panned and stopped",
            peak, options.minCorrelation);
    if (std::optional<size_t> rival = rivalPeak(corr, best, options.minPeakMargin))
        return makeError(
            "two delays fit almost equally ({:.0f} ms: {:.3f}, {:.0f} ms: {:.3f}): pan and stop "
            "at irregular moments, not to a beat",
            (double(best) - steps) * options.stepMs, peak,
            (double(*rival) - steps) * options.stepMs, corr[*rival]);
    return best;
}

}  // namespace

Result<FreedDelay> estimateFreedDelay(std::span<const TimedPose> worldFromCamera,
                                      std::span<const TimedPose> stageFromBody,
                                      const FreedDelayOptions& options) {
    if (worldFromCamera.size() < 10)
        return makeError(
            "only {} tracked camera frames: the delay needs a few seconds of the board in view "
            "while the camera pans and stops",
            worldFromCamera.size());
    if (stageFromBody.size() < 10)
        return makeError(
            "only {} FreeD packets: check that the tracker sends to this box and that the "
            "camera id is its",
            stageFromBody.size());
    FreedDelay delay;
    delay.peakSpeedDegPerS = peakSpeedDegPerS(worldFromCamera);
    if (delay.peakSpeedDegPerS < options.minPeakSpeedDegPerS)
        return makeError(
            "the camera hardly turned (fastest {:.1f}°/s, the delay needs {}°/s): pan and stop "
            "the camera a few times while the board is in view",
            delay.peakSpeedDegPerS, options.minPeakSpeedDegPerS);

    const int steps = int(std::lround(options.searchMs / options.stepMs));
    const std::vector<double> corr =
        correlationCurve(worldFromCamera, stageFromBody, steps, options.stepMs);
    Result<size_t> best = distinctPeak(corr, options);
    if (!best) return best.error();
    // A parabola through the peak and its neighbours puts it between grid points.
    const double a = corr[*best - 1], b = corr[*best], c = corr[*best + 1];
    const double denom = a - 2 * b + c;
    const double offset = denom < 0 ? std::clamp(0.5 * (a - c) / denom, -0.5, 0.5) : 0.0;
    delay.delayMs = (double(*best) - steps + offset) * options.stepMs;
    delay.correlation = b;
    return delay;
}

namespace {

struct PosePair {
    int64_t timestampNs = 0;  // the camera frame's
    cv::Matx44d worldFromCamera;
    cv::Matx44d stageFromBody;
};

// Where the turns of the camera point: the rotation vectors of frame pairs (in the first frame's
// camera axes, where a pan keeps one axis whatever the heading) and how far they spread about
// their main direction. A spread of 0 is one axis: the hand-eye problem is then degenerate.
struct AxisSpread {
    double spreadDeg = 0;
    cv::Vec3d mainAxis;  // camera axes
    size_t turns = 0;
};

AxisSpread axisSpread(const std::vector<PosePair>& pairs) {
    constexpr double kMinTurnRad = 3.0 / kDegPerRad;  // smaller turns have noisy axes
    const size_t stride = std::max<size_t>(1, pairs.size() / 100);
    cv::Matx33d scatter = cv::Matx33d::zeros();
    AxisSpread out;
    for (size_t i = 0; i < pairs.size(); i += stride) {
        for (size_t j = i + stride; j < pairs.size(); j += stride) {
            const cv::Matx33d r =
                rotationOf(pairs[i].worldFromCamera).t() * rotationOf(pairs[j].worldFromCamera);
            const double angle = rotationAngleRad(r);
            if (angle < kMinTurnRad) continue;
            cv::Vec3d v(r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1));
            if (cv::norm(v) < 1e-9) continue;  // a half turn: rare, and its axis is ill-posed
            v *= angle / cv::norm(v);
            scatter += v * v.t();
            ++out.turns;
        }
    }
    if (out.turns == 0) return out;
    cv::Matx31d values;
    cv::Matx33d vectors;
    cv::eigen(scatter, values, vectors);  // descending
    out.mainAxis = cv::Vec3d(vectors(0, 0), vectors(0, 1), vectors(0, 2));
    out.spreadDeg =
        std::atan(std::sqrt(std::max(0.0, values(1)) / std::max(values(0), 1e-300))) * kDegPerRad;
    return out;
}

// "panning", "tilting" or "rolling" for a turn axis in the camera's axes (y down, x right).
const char* motionName(const cv::Vec3d& axis) {
    const double x = std::abs(axis[0]), y = std::abs(axis[1]), z = std::abs(axis[2]);
    if (y >= x && y >= z) return "panning";
    return x >= z ? "tilting" : "rolling";
}

struct Residual {
    double positionMm = 0, rotationDeg = 0;
};

Residual residualOf(const FreedCalibration& c, const PosePair& p) {
    const cv::Matx44d predicted = applyFreedCalibration(c, p.stageFromBody);
    return {
        cv::norm(translationOf(predicted) - translationOf(p.worldFromCamera)) * 1000.0,
        rotationAngleRad(rotationOf(predicted).t() * rotationOf(p.worldFromCamera)) * kDegPerRad};
}

// OpenCV's robot-world/hand-eye equation cTw·wTb = cTg·gTb, with its robot base = the tracker's
// stage and its gripper = the tracker's body: cTw = cameraFromWorld, gTb = bodyFromStage, and it
// returns wTb = worldFromStage and cTg = cameraFromBody.
Result<FreedCalibration> solveHandEye(const std::vector<PosePair>& pairs) {
    std::vector<cv::Mat> rCameraFromWorld, tCameraFromWorld, rBodyFromStage, tBodyFromStage;
    for (const PosePair& p : pairs) {
        const cv::Matx44d cameraFromWorld = rigidInverse(p.worldFromCamera);
        const cv::Matx44d bodyFromStage = rigidInverse(p.stageFromBody);
        rCameraFromWorld.push_back(cv::Mat(rotationOf(cameraFromWorld)));
        tCameraFromWorld.push_back(cv::Mat(translationOf(cameraFromWorld)));
        rBodyFromStage.push_back(cv::Mat(rotationOf(bodyFromStage)));
        tBodyFromStage.push_back(cv::Mat(translationOf(bodyFromStage)));
    }
    cv::Mat rWorldFromStage, tWorldFromStage, rCameraFromBody, tCameraFromBody;
    try {
        cv::calibrateRobotWorldHandEye(
            rCameraFromWorld, tCameraFromWorld, rBodyFromStage, tBodyFromStage, rWorldFromStage,
            tWorldFromStage, rCameraFromBody, tCameraFromBody, cv::CALIB_ROBOT_WORLD_HAND_EYE_SHAH);
    } catch (const cv::Exception& e) {
        return makeError("OpenCV's hand-eye solver failed: {}", e.what());
    }
    FreedCalibration c;
    c.worldFromStage = rigid(cv::Matx33d(rWorldFromStage), cv::Vec3d(tWorldFromStage));
    c.bodyFromCamera =
        rigidInverse(rigid(cv::Matx33d(rCameraFromBody), cv::Vec3d(tCameraFromBody)));
    return c;
}

// Rodrigues' formula: the rotation by |v| radians about v.
cv::Matx33d rotationOfVector(const cv::Vec3d& v) {
    const double angle = cv::norm(v);
    if (angle < 1e-300) return cv::Matx33d::eye();
    const cv::Vec3d k = v / angle;
    const cv::Matx33d kx(0, -k[2], k[1], k[2], 0, -k[0], -k[1], k[0], 0);
    return cv::Matx33d::eye() + std::sin(angle) * kx + (1 - std::cos(angle)) * kx * kx;
}

// The rotation vector of a rotation well below a half turn (a residual).
cv::Vec3d vectorOfRotation(const cv::Matx33d& r) {
    const cv::Vec3d v(r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1));
    const double s = 0.5 * cv::norm(v);
    if (s < 1e-300) return {0, 0, 0};
    return v * (rotationAngleRad(r) / (2 * s));
}

// The 12 parameters of the refinement: small turns and shifts of both transforms.
using Params = cv::Vec<double, 12>;

FreedCalibration perturbed(const FreedCalibration& c, const Params& d) {
    FreedCalibration out = c;
    out.worldFromStage = rigid(rotationOf(c.worldFromStage) * rotationOfVector({d[0], d[1], d[2]}),
                               translationOf(c.worldFromStage) + cv::Vec3d(d[3], d[4], d[5]));
    out.bodyFromCamera = rigid(rotationOf(c.bodyFromCamera) * rotationOfVector({d[6], d[7], d[8]}),
                               translationOf(c.bodyFromCamera) + cv::Vec3d(d[9], d[10], d[11]));
    return out;
}

// Each pair's position (m) and rotation (rad) error, divided by the noise of each, so that the
// sum of squares weighs both as the data do.
std::vector<double> whitenedResiduals(const FreedCalibration& c, const std::vector<PosePair>& pairs,
                                      double sigmaM, double sigmaRad) {
    std::vector<double> out;
    out.reserve(6 * pairs.size());
    for (const PosePair& p : pairs) {
        const cv::Matx44d predicted = applyFreedCalibration(c, p.stageFromBody);
        const cv::Vec3d dt = translationOf(predicted) - translationOf(p.worldFromCamera);
        const cv::Vec3d dr =
            vectorOfRotation(rotationOf(p.worldFromCamera).t() * rotationOf(predicted));
        for (int k = 0; k < 3; ++k) out.push_back(dt[k] / sigmaM);
        for (int k = 0; k < 3; ++k) out.push_back(dr[k] / sigmaRad);
    }
    return out;
}

// JᵀJ, Jᵀr and χ² = |r|² of the whitened residuals at `c` (J by central differences).
struct NormalEquations {
    cv::Matx<double, 12, 12> jtj;
    cv::Matx<double, 12, 1> jtr;
    double chi2 = 0;
};

NormalEquations normalEquations(const FreedCalibration& c, const std::vector<PosePair>& pairs,
                                double sigmaM, double sigmaRad) {
    constexpr double kStep = 1e-6;  // rad or m: far below the noise, far above rounding
    const std::vector<double> r0 = whitenedResiduals(c, pairs, sigmaM, sigmaRad);
    std::vector<std::vector<double>> columns(12, std::vector<double>(r0.size()));
    for (int k = 0; k < 12; ++k) {
        Params d;
        d[k] = kStep;
        const std::vector<double> plus =
            whitenedResiduals(perturbed(c, d), pairs, sigmaM, sigmaRad);
        d[k] = -kStep;
        const std::vector<double> minus =
            whitenedResiduals(perturbed(c, d), pairs, sigmaM, sigmaRad);
        for (size_t i = 0; i < r0.size(); ++i)
            columns[size_t(k)][i] = (plus[i] - minus[i]) / (2 * kStep);
    }
    NormalEquations out;
    for (size_t i = 0; i < r0.size(); ++i) {
        out.chi2 += r0[i] * r0[i];
        for (int a = 0; a < 12; ++a) {
            out.jtr(a) += columns[size_t(a)][i] * r0[i];
            for (int b = 0; b < 12; ++b)
                out.jtj(a, b) += columns[size_t(a)][i] * columns[size_t(b)][i];
        }
    }
    return out;
}

// The mount's 1σ in its worst direction from the covariance (JᵀJ)⁻¹·s², s² the residual variance
// per degree of freedom (it rescales the assumed noise to the one the fit leaves). Large along an
// axis the camera never turned about: an offset along the turn axis moves the lens the same in
// every frame. Returns that worst direction of the offset (camera axes).
cv::Vec3d setMountUncertainty(FreedCalibration& c, const NormalEquations& normal, size_t pairs) {
    const double s2 = normal.chi2 / std::max(1.0, 6.0 * double(pairs) - 12);
    cv::Matx<double, 12, 12> covariance;
    cv::invert(normal.jtj, covariance, cv::DECOMP_SVD);
    covariance *= s2;
    cv::Matx33d offset, turn;
    for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
            turn(a, b) = covariance(6 + a, 6 + b);
            offset(a, b) = covariance(9 + a, 9 + b);
        }
    }
    cv::Matx31d values;
    cv::Matx33d vectors;
    cv::eigen(turn, values, vectors);  // descending
    c.mountSigmaDeg = std::sqrt(std::max(0.0, values(0))) * kDegPerRad;
    cv::eigen(offset, values, vectors);
    c.mountSigmaMm = std::sqrt(std::max(0.0, values(0))) * 1000.0;
    return {vectors(0, 0), vectors(0, 1), vectors(0, 2)};
}

// The per-axis noise of positions (m) and rotations (rad) the residuals of `c` show, floored so
// exact data do not divide by zero.
struct Noise {
    double sigmaM = 1e-6, sigmaRad = 1e-6;
};

Noise noiseOf(const FreedCalibration& c, const std::vector<PosePair>& pairs) {
    double sumM2 = 0, sumRad2 = 0;
    for (const PosePair& p : pairs) {
        const Residual r = residualOf(c, p);
        sumM2 += r.positionMm * r.positionMm * 1e-6;
        sumRad2 += r.rotationDeg * r.rotationDeg / (kDegPerRad * kDegPerRad);
    }
    const double n = 3.0 * double(pairs.size());
    return {std::max(std::sqrt(sumM2 / n), 1e-6), std::max(std::sqrt(sumRad2 / n), 1e-6)};
}

struct Refined {
    FreedCalibration calibration;
    NormalEquations normal;  // at the solution
};

// Gauss–Newton on both transforms together from the closed-form start, which solves rotation
// and translation one after the other and so does not weigh the two against each other.
Refined refine(const FreedCalibration& start, const std::vector<PosePair>& pairs, Noise noise,
               int maxIterations = 6) {
    Refined r{start, normalEquations(start, pairs, noise.sigmaM, noise.sigmaRad)};
    for (int iteration = 0; iteration < maxIterations; ++iteration) {
        cv::Matx<double, 12, 1> step;
        if (!cv::solve(r.normal.jtj, -r.normal.jtr, step, cv::DECOMP_SVD)) break;
        const FreedCalibration next = perturbed(r.calibration, Params(step.val));
        const NormalEquations nextNormal =
            normalEquations(next, pairs, noise.sigmaM, noise.sigmaRad);
        if (nextNormal.chi2 >= r.normal.chi2) break;
        const bool converged = r.normal.chi2 - nextNormal.chi2 < 1e-9 * r.normal.chi2;
        r = {next, nextNormal};
        if (converged) break;
    }
    return r;
}

// The delay that fits the poses best, near the correlation's: χ² of the refined fit at delays
// 1 ms apart over ±8 ms (the profile likelihood of the delay), a parabola through the lowest
// and its neighbours. The full poses time the two series far better than the rotation speed
// alone: a 1 ms error shows as 0.05° at 50°/s in every moving frame. Nothing when the lowest
// lies at the edge (the correlation's delay is then kept). `sigmaMs` gets the curve's 1σ.
std::optional<double> bestFitDelay(const std::vector<PosePair>& kept,
                                   std::span<const TimedPose> stageFromBody, double delayMs,
                                   const FreedCalibration& start, Noise noise, size_t dof,
                                   double& sigmaMs) {
    constexpr int kSteps = 8;
    const int64_t maxGapNs = packetGapLimitNs(stageFromBody);
    std::vector<double> chi2;
    for (int k = -kSteps; k <= kSteps; ++k) {
        const int64_t shiftNs = std::llround((delayMs + k) * 1e6);
        std::vector<PosePair> pairs;
        for (const PosePair& p : kept) {
            std::optional<cv::Matx44d> body =
                interpolatePose(stageFromBody, p.timestampNs + shiftNs, maxGapNs);
            if (!body) return std::nullopt;  // the same frames at every delay, or no comparison
            pairs.push_back({p.timestampNs, p.worldFromCamera, *body});
        }
        // Two steps from the fit at the correlation's delay: a few ms move it little, and
        // Gauss–Newton converges in one step on a problem this close to linear.
        chi2.push_back(refine(start, pairs, noise, 2).normal.chi2);
    }
    const size_t best = size_t(std::min_element(chi2.begin(), chi2.end()) - chi2.begin());
    if (best == 0 || best + 1 == chi2.size()) return std::nullopt;
    const double a = chi2[best - 1], b = chi2[best], c = chi2[best + 1];
    const double curvature = a - 2 * b + c;  // per ms²
    if (curvature <= 0) return std::nullopt;
    // χ² rises by s² (the residual variance per degree of freedom) at 1σ: Δ = ½·curvature·σ².
    const double s2 = b / double(std::max<size_t>(1, dof));
    sigmaMs = std::sqrt(2 * s2 / curvature);
    return delayMs + double(best) - kSteps + std::clamp(0.5 * (a - c) / curvature, -0.5, 0.5);
}

}  // namespace

namespace {

constexpr size_t kMinPairs = 10;

// Each tracked frame with the packet series read at its time + delay, thinned to `maxSamples`.
std::vector<PosePair> pairsAtDelay(std::span<const TimedPose> worldFromCamera,
                                   std::span<const TimedPose> stageFromBody, double delayMs,
                                   size_t maxSamples) {
    const int64_t delayNs = std::llround(delayMs * 1e6);
    const int64_t maxGapNs = packetGapLimitNs(stageFromBody);
    std::vector<PosePair> all;
    for (const TimedPose& camera : worldFromCamera) {
        std::optional<cv::Matx44d> body =
            interpolatePose(stageFromBody, camera.timestampNs + delayNs, maxGapNs);
        if (body) all.push_back({camera.timestampNs, camera.pose, *body});
    }
    const size_t stride = std::max<size_t>(1, (all.size() + maxSamples - 1) / maxSamples);
    std::vector<PosePair> pairs;
    for (size_t i = 0; i < all.size(); i += stride) pairs.push_back(all[i]);
    return pairs;
}

Status checkTurnAxes(const std::vector<PosePair>& pairs, double minSpreadDeg) {
    const AxisSpread spread = axisSpread(pairs);
    if (spread.turns == 0)
        return makeError(
            "the camera never turned by more than 3° while the board was in view: pan and tilt "
            "it by 20° or more each way");
    if (spread.spreadDeg >= minSpreadDeg) return {};
    const std::string motion = motionName(spread.mainAxis);
    return makeError(
        "the camera turned about one axis only ({}; the turns spread {:.1f}° about it, {}° "
        "needed): the mount offset along that axis cannot be measured. Record again adding {} "
        "of 20° or more each way (and rolls on a remote head that can)",
        motion, spread.spreadDeg, minSpreadDeg, motion == "tilting" ? "pans" : "tilts");
}

// Solves, leaves out the pairs far from the solution (a mis-tracked frame, a dropped packet
// bridged by interpolation) and solves again until none is left out. `kept` gets the inliers.
Result<FreedCalibration> solveRobust(const std::vector<PosePair>& pairs,
                                     const FreedSolveOptions& options,
                                     std::vector<PosePair>& kept) {
    kept = pairs;
    Result<FreedCalibration> solution = solveHandEye(kept);
    for (int round = 0; round < 4 && solution; ++round) {
        std::vector<double> positions, rotations;
        for (const PosePair& p : pairs) {
            const Residual r = residualOf(*solution, p);
            positions.push_back(r.positionMm);
            rotations.push_back(r.rotationDeg);
        }
        // 3.5 robust sigmas (1.4826 × the median absolute residual), never below the floor.
        const double maxMm = std::max(options.outlierFloorMm, 3.5 * 1.4826 * median(positions));
        const double maxDeg = std::max(options.outlierFloorDeg, 3.5 * 1.4826 * median(rotations));
        std::vector<PosePair> inliers;
        for (size_t i = 0; i < pairs.size(); ++i)
            if (positions[i] <= maxMm && rotations[i] <= maxDeg) inliers.push_back(pairs[i]);
        if (inliers.size() == kept.size()) break;
        if (inliers.size() < kMinPairs)
            return makeError(
                "only {} of {} frames agree with one mount offset: the tracker and the tag "
                "tracking disagree; check the board file's tag size and that the tracker is "
                "fixed to the camera",
                inliers.size(), pairs.size());
        kept = std::move(inliers);
        solution = solveHandEye(kept);
    }
    return solution;
}

// The offset is unknown along the axis the camera kept turning about: name it and the motion
// that would pin it.
Error uncertainMountError(const FreedCalibration& c, const cv::Vec3d& worstAxis,
                          const FreedSolveOptions& options) {
    const std::string motion = motionName(worstAxis);
    const bool pan = motion == "panning", tilt = motion == "tilting";
    return makeError(
        "the mount offset is uncertain by ±{:.1f} mm and ±{:.2f}° (1σ; needs ≤ {} mm, {}°), most "
        "along the camera's {} axis: the camera turned mostly about that axis. Record again "
        "adding {} of 20° or more each way",
        c.mountSigmaMm, c.mountSigmaDeg, options.maxMountSigmaMm, options.maxMountSigmaDeg,
        pan    ? "vertical"
        : tilt ? "horizontal"
               : "viewing",
        pan    ? "tilts"
        : tilt ? "pans"
               : "pans and tilts");
}

void setResiduals(FreedCalibration& c, const std::vector<PosePair>& kept) {
    double sumMm2 = 0, sumDeg2 = 0;
    for (const PosePair& p : kept) {
        const Residual r = residualOf(c, p);
        sumMm2 += r.positionMm * r.positionMm;
        sumDeg2 += r.rotationDeg * r.rotationDeg;
    }
    c.rmsPositionMm = std::sqrt(sumMm2 / double(kept.size()));
    c.rmsRotationDeg = std::sqrt(sumDeg2 / double(kept.size()));
    c.samples = int(kept.size());
}

}  // namespace

Result<FreedCalibration> solveFreedCalibration(std::span<const TimedPose> worldFromCamera,
                                               std::span<const TimedPose> stageFromBody,
                                               const FreedDelay& delay,
                                               const FreedSolveOptions& options) {
    std::vector<PosePair> pairs =
        pairsAtDelay(worldFromCamera, stageFromBody, delay.delayMs, options.maxSamples);
    if (pairs.size() < kMinPairs)
        return makeError(
            "only {} tracked frames have FreeD packets around them (needs {}): record the board "
            "in view while the tracker sends",
            pairs.size(), kMinPairs);
    if (Status s = checkTurnAxes(pairs, options.minAxisSpreadDeg); !s) return s.error();
    std::vector<PosePair> kept;
    Result<FreedCalibration> solution = solveRobust(pairs, options, kept);
    if (!solution) return solution;
    // The delay refined on the full poses, then the pairs and the fit again at it.
    const Noise noise = noiseOf(*solution, kept);
    double delayMs = delay.delayMs, delaySigmaMs = 0;
    const FreedCalibration start = refine(*solution, kept, noise).calibration;
    if (std::optional<double> fit = bestFitDelay(kept, stageFromBody, delay.delayMs, start, noise,
                                                 6 * kept.size() - 12, delaySigmaMs)) {
        delayMs = *fit;
        pairs = pairsAtDelay(worldFromCamera, stageFromBody, delayMs, options.maxSamples);
        solution = solveRobust(pairs, options, kept);
        if (!solution) return solution;
    }
    const Refined refined = refine(*solution, kept, noiseOf(*solution, kept));
    FreedCalibration c = refined.calibration;
    const cv::Vec3d worstAxis = setMountUncertainty(c, refined.normal, kept.size());
    if (c.mountSigmaMm > options.maxMountSigmaMm || c.mountSigmaDeg > options.maxMountSigmaDeg)
        return uncertainMountError(c, worstAxis, options);
    c.delaySigmaMs = delaySigmaMs;
    setResiduals(c, kept);
    c.rejected = int(pairs.size() - kept.size());
    c.delayMs = delayMs;
    c.delayCorrelation = delay.correlation;
    return c;
}

namespace {

constexpr const char* kWhat = "FreeD calibration";
constexpr const char* kFormat = "previs-freed-calibration";
constexpr int64_t kVersion = 1;

std::string utcNow() {
    const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    std::tm tm{};
    gmtime_r(&now, &tm);
    char text[32];
    std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &tm);
    return text;
}

std::string matrixText(const cv::Matx44d& m) {
    std::string out = "[";
    for (int i = 0; i < 16; ++i) {
        out += fmt::format("{}{}", i == 0 ? "" : (i % 4 == 0 ? ",\n    " : ", "), m.val[i]);
    }
    return out + "]";
}

// 16 row-major numbers that form a rigid transform (a rotation and a translation).
Result<cv::Matx44d> readRigid(const TomlReader& r, const toml::table& root, std::string_view key) {
    Result<std::optional<std::vector<double>>> v = r.numbers(root, "", key, 16);
    if (!v) return v.error();
    if (!*v) return r.fail(&root, "'{}' is missing (16 numbers, row-major)", key);
    cv::Matx44d m;
    for (int i = 0; i < 16; ++i) m.val[i] = (**v)[size_t(i)];
    const cv::Matx33d rotation = rotationOf(m);
    if (cv::norm(m.row(3) - cv::Matx14d(0, 0, 0, 1)) > 1e-9 ||
        cv::norm(rotation.t() * rotation - cv::Matx33d::eye()) > 1e-6 ||
        cv::determinant(rotation) < 0)
        return r.fail(root.get(key),
                      "'{}' is not a rigid transform (a rotation, a translation, last row 0 0 0 "
                      "1): run previs freed-calibrate again rather than editing it",
                      key);
    return m;
}

}  // namespace

Status writeFreedCalibration(const std::string& path, const FreedCalibration& c) {
    const std::string text = fmt::format(
        "# FreeD input calibration, written by previs freed-calibrate (docs/freed.md).\n"
        "# worldFromCamera = world_from_stage · stageFromBody(packet at frame time + delay_ms)"
        " · body_from_camera\n"
        "format = \"{}\"\n"
        "version = {}\n"
        "created = \"{}\"\n"
        "delay_ms = {}\n"
        "delay_sigma_ms = {}\n"
        "delay_correlation = {}\n"
        "world_from_stage = {}\n"
        "body_from_camera = {}\n"
        "rms_position_mm = {}\n"
        "rms_rotation_deg = {}\n"
        "mount_sigma_mm = {}\n"
        "mount_sigma_deg = {}\n"
        "samples = {}\n"
        "rejected = {}\n",
        kFormat, kVersion, c.created.empty() ? utcNow() : c.created, c.delayMs, c.delaySigmaMs,
        c.delayCorrelation, matrixText(c.worldFromStage), matrixText(c.bodyFromCamera),
        c.rmsPositionMm, c.rmsRotationDeg, c.mountSigmaMm, c.mountSigmaDeg, c.samples, c.rejected);
    // Written beside and renamed over, so a reader never sees half a file; not synced, as before.
    if (Status s = writeFileAtomic(
            path, {reinterpret_cast<const uint8_t*>(text.data()), text.size()}, {.durable = false});
        !s)
        return makeError("{}; choose another --out", s.message());
    return {};
}

Result<FreedCalibration> loadFreedCalibration(const std::string& path) {
    Result<toml::table> parsed = parseTomlFile(path, kWhat);
    if (!parsed) return parsed.error();
    const toml::table& root = *parsed;
    const TomlReader r(path, kWhat);
    if (Status s = r.checkKeys(
            root, "",
            {"format", "version", "created", "delay_ms", "delay_sigma_ms", "delay_correlation",
             "world_from_stage", "body_from_camera", "rms_position_mm", "rms_rotation_deg",
             "mount_sigma_mm", "mount_sigma_deg", "samples", "rejected"});
        !s)
        return s.error();
    Result<std::optional<std::string>> format = r.string(root, "", "format");
    if (!format) return format.error();
    if (*format && **format != kFormat)
        return r.fail(root.get("format"), "'format' is '{}'; expected '{}'", **format, kFormat);
    int64_t version = 0;
    if (Status s = r.integerIn(root, "", "version", version, 1, 1000); !s) return s.error();
    if (version == 0)
        return r.fail(&root, "'version' is missing (this previs writes {})", kVersion);
    if (version > kVersion)
        return r.fail(root.get("version"),
                      "'version' is {}; this previs reads version {}: update previs", version,
                      kVersion);
    FreedCalibration c;
    Result<std::optional<std::string>> created = r.string(root, "", "created");
    if (!created) return created.error();
    c.created = created->value_or("");
    if (!root.contains("delay_ms")) return r.fail(&root, "'delay_ms' is missing");
    if (Status s = r.numberIn(root, "", "delay_ms", c.delayMs, -10'000.0, 10'000.0); !s)
        return s.error();
    if (Status s = r.numberIn(root, "", "delay_sigma_ms", c.delaySigmaMs, 0.0, 10'000.0); !s)
        return s.error();
    if (Status s = r.numberIn(root, "", "delay_correlation", c.delayCorrelation, -1.0, 1.0); !s)
        return s.error();
    Result<cv::Matx44d> worldFromStage = readRigid(r, root, "world_from_stage");
    if (!worldFromStage) return worldFromStage.error();
    c.worldFromStage = *worldFromStage;
    Result<cv::Matx44d> bodyFromCamera = readRigid(r, root, "body_from_camera");
    if (!bodyFromCamera) return bodyFromCamera.error();
    c.bodyFromCamera = *bodyFromCamera;
    if (Status s = r.numberIn(root, "", "rms_position_mm", c.rmsPositionMm, 0.0, 1e9); !s)
        return s.error();
    if (Status s = r.numberIn(root, "", "rms_rotation_deg", c.rmsRotationDeg, 0.0, 360.0); !s)
        return s.error();
    if (Status s = r.numberIn(root, "", "mount_sigma_mm", c.mountSigmaMm, 0.0, 1e9); !s)
        return s.error();
    if (Status s = r.numberIn(root, "", "mount_sigma_deg", c.mountSigmaDeg, 0.0, 360.0); !s)
        return s.error();
    if (Status s = r.integerIn(root, "", "samples", c.samples, 0, INT32_MAX); !s) return s.error();
    if (Status s = r.integerIn(root, "", "rejected", c.rejected, 0, INT32_MAX); !s)
        return s.error();
    return c;
}

std::string freedRecordingLine(int64_t receivedNs, std::span<const uint8_t> datagram) {
    std::string line = fmt::format("{},", receivedNs);
    for (uint8_t b : datagram) line += fmt::format("{:02x}", b);
    line += '\n';
    return line;
}

namespace {

int hexDigit(char c) {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

}  // namespace

Result<FreedRecording> loadFreedRecording(const std::string& path,
                                          std::optional<uint8_t> cameraId) {
    std::error_code statError;
    if (!std::filesystem::exists(std::filesystem::symlink_status(path, statError)))
        return makeError("cannot read '{}': no such file; the take has no recorded FreeD packets",
                         path);
    // A take is untrusted: no link followed, no FIFO waited on, the size bounded before reading.
    Result<std::string> text =
        readBoundedText(path, kMaxFreedRecordingBytes, FileLinks::Refuse, "FreeD recording");
    if (!text) return text.error();
    FreedRecording out;
    size_t lineNo = 0;
    for (size_t pos = 0; pos < text->size();) {
        const size_t eol = text->find('\n', pos);
        // A last line without its '\n' was cut mid-write (docs/session-format.md): ignored.
        if (eol == std::string::npos) break;
        const std::string_view line(text->data() + pos, eol - pos);
        pos = eol + 1;
        ++lineNo;
        if (lineNo == 1) {
            if (line != kFreedRecordingHeader)
                return makeError("'{}' line 1: expected the header '{}'", path,
                                 kFreedRecordingHeader);
            continue;
        }
        const size_t comma = line.find(',');
        std::vector<uint8_t> bytes;
        bool ok = comma != std::string::npos && comma > 0 && (line.size() - comma - 1) % 2 == 0;
        int64_t ns = 0;
        if (ok) {
            const char* first = line.data();
            const auto [end, ec] = std::from_chars(first, first + comma, ns);
            ok = ec == std::errc() && end == first + comma;
        }
        for (size_t i = comma + 1; ok && i + 1 < line.size(); i += 2) {
            const int hi = hexDigit(line[i]), lo = hexDigit(line[i + 1]);
            ok = hi >= 0 && lo >= 0;
            bytes.push_back(uint8_t(hi << 4 | lo));
        }
        if (!ok)
            return makeError(
                "'{}' line {}: expected 'receivedNs,hexbytes' (the take's file is "
                "damaged; record the take again)",
                path, lineNo);
        const FreedParse parse = decodeFreed(bytes, cameraId);
        if (parse.ok() || parse.error == FreedError::OtherCamera) {
            const uint8_t id = bytes[1];
            auto at = std::lower_bound(out.cameraIds.begin(), out.cameraIds.end(), id);
            if (at == out.cameraIds.end() || *at != id) out.cameraIds.insert(at, id);
        }
        if (parse.error == FreedError::OtherCamera) continue;
        if (!parse.ok()) {
            ++out.rejected;
            continue;
        }
        out.stageFromBody.push_back({ns, worldFromFreed(parse.packet)});
    }
    if (lineNo == 0)
        return makeError("'{}' is empty: expected the header '{}'", path, kFreedRecordingHeader);
    // Receipt order is time order on one clock; sort anyway so a merged file still reads.
    std::stable_sort(
        out.stageFromBody.begin(), out.stageFromBody.end(),
        [](const TimedPose& a, const TimedPose& b) { return a.timestampNs < b.timestampNs; });
    return out;
}

}  // namespace previs
