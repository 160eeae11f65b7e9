#include "shot/refine_watch.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace previs {

namespace {

double norm(const std::array<double, 9>& a) {
    double s = 0.0;
    for (double v : a) s += v * v;
    return std::sqrt(s);
}

// Band 1 as a world vector: Y_1,-1 ∝ y, Y_1,0 ∝ z, Y_1,1 ∝ x (pipeline_stages.h's order).
cv::Vec3d bandOne(const std::array<double, 9>& sh) { return {sh[3], sh[1], sh[2]}; }

// A direction needs band 1 to hold this fraction of the DC term; below it (a nearly uniform
// sky) the dominant direction is noise and the log leaves it out.
constexpr double kMinDirectional = 1e-3;

}  // namespace

LightingDelta lightingDelta(const LiveLighting& to, const LiveLighting& from) {
    LightingDelta d;
    std::array<double, 9> diff;
    for (size_t i = 0; i < diff.size(); ++i) diff[i] = to.luminanceSh[i] - from.luminanceSh[i];
    const double base = norm(from.luminanceSh), moved = norm(diff);
    // Lighting out of darkness is a change of any size; darkness to darkness is none.
    d.change = base > 0.0 ? moved / base : (moved > 0.0 ? HUGE_VAL : 0.0);
    d.powerChange =
        from.totalLuminancePower > 0.0
            ? (to.totalLuminancePower - from.totalLuminancePower) / from.totalLuminancePower
            : 0.0;
    const cv::Vec3d a = bandOne(to.luminanceSh), b = bandOne(from.luminanceSh);
    const double na = cv::norm(a), nb = cv::norm(b);
    if (na > kMinDirectional * std::abs(to.luminanceSh[0]) &&
        nb > kMinDirectional * std::abs(from.luminanceSh[0]))
        d.directionDeg = std::acos(std::clamp(a.dot(b) / (na * nb), -1.0, 1.0)) * 180.0 / M_PI;
    else
        d.directionDeg = std::nan("");
    return d;
}

void RefineWatch::freeze(const TrackedFrame& frame,
                         const std::shared_ptr<const LiveLighting>& lighting) {
    frozenPose_ = frame.worldFromCamera;
    frozenLighting_ = lighting;
    lastLighting_ = lighting;
    poseBeyond_ = lightingBeyond_ = 0;
}

std::optional<std::string> RefineWatch::observeFrame(const TrackedFrame& frame) {
    if (frame.lost || !frame.worldFromCamera) return std::nullopt;
    // Virtual objects appear with the first pose: no noise to wait out, the shot was only
    // the camera picture.
    if (!frozenPose_) return std::string("the first pose arrived");
    const PoseDelta d = poseDelta(*frame.worldFromCamera, *frozenPose_);
    if (d.translationM <= config_.poseThresholdM && d.rotationDeg <= config_.poseThresholdDeg) {
        poseBeyond_ = 0;
        return std::nullopt;
    }
    if (++poseBeyond_ < std::max(1, config_.restartAfter)) return std::nullopt;
    return fmt::format(
        "the camera moved {:.1f} mm / {:.2f} deg (thresholds {:.1f} mm / {:.2f} deg), {} tracked "
        "frames in a row",
        d.translationM * 1e3, d.rotationDeg, config_.poseThresholdM * 1e3, config_.poseThresholdDeg,
        poseBeyond_);
}

std::optional<std::string> RefineWatch::observeLighting(
    const std::shared_ptr<const LiveLighting>& lighting) {
    if (!lighting || lighting == lastLighting_) return std::nullopt;
    lastLighting_ = lighting;
    // The set's lighting replaces the scene's own: a change of kind, not a measurement.
    if (!frozenLighting_) return std::string("the first lighting snapshot arrived");
    const LightingDelta d = lightingDelta(*lighting, *frozenLighting_);
    if (d.change <= config_.lightingThreshold) {
        lightingBeyond_ = 0;
        return std::nullopt;
    }
    if (++lightingBeyond_ < std::max(1, config_.restartAfter)) return std::nullopt;
    return fmt::format(
        "the lighting changed {:.1f} % (threshold {:.1f} %; power {:+.1f} %{}), {} snapshots in "
        "a row",
        d.change * 100.0, config_.lightingThreshold * 100.0, d.powerChange * 100.0,
        std::isnan(d.directionDeg)
            ? std::string()
            : fmt::format(", dominant direction turned {:.1f} deg", d.directionDeg),
        lightingBeyond_);
}

}  // namespace previs
