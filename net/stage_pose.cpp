#include "net/stage_pose.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace previs {

namespace {

constexpr double kStageDegPerRad = 180.0 / std::numbers::pi;

// stageFromWorld: glTF Y-up to the stage's Z-up (a proper rotation, both frames right-handed).
const cv::Matx33d kStageFromWorld(1, 0, 0, 0, 0, -1, 0, 1, 0);
// bodyFromCv: OpenCV camera axes (right, down, forward) to the stage body axes (right, forward,
// up) of a camera at pan = tilt = roll = 0.
const cv::Matx33d kBodyFromCv(1, 0, 0, 0, 0, 1, 0, -1, 0);

// Below this cos(tilt) (tilt within ~2e-4° of ±90°, finer than FreeD's 1/32768°) pan and roll
// cannot be told apart; the rotation is then carried by pan alone.
constexpr double kGimbalCos = 1e-6;

cv::Matx33d rotationPart(const cv::Matx44d& m) {
    return cv::Matx33d(m(0, 0), m(0, 1), m(0, 2), m(1, 0), m(1, 1), m(1, 2), m(2, 0), m(2, 1),
                       m(2, 2));
}

}  // namespace

cv::Matx33d stageRotation(double panDeg, double tiltDeg, double rollDeg) {
    double p = panDeg / kStageDegPerRad, t = tiltDeg / kStageDegPerRad,
           r = rollDeg / kStageDegPerRad;
    cv::Matx33d rz(std::cos(p), -std::sin(p), 0, std::sin(p), std::cos(p), 0, 0, 0, 1);
    cv::Matx33d rx(1, 0, 0, 0, std::cos(t), -std::sin(t), 0, std::sin(t), std::cos(t));
    cv::Matx33d ry(std::cos(r), 0, std::sin(r), 0, 1, 0, -std::sin(r), 0, std::cos(r));
    return rz * rx * ry;
}

StagePose stagePoseFromWorld(const cv::Matx44d& worldFromCamera) {
    // R = Rz(p)Rx(t)Ry(r) has R21 = sin t, R01 = −sin p cos t, R11 = cos p cos t,
    // R20 = −cos t sin r, R22 = cos t cos r.
    cv::Matx33d r = kStageFromWorld * rotationPart(worldFromCamera) * kBodyFromCv.t();
    StagePose pose;
    cv::Vec3d t(worldFromCamera(0, 3), worldFromCamera(1, 3), worldFromCamera(2, 3));
    pose.translationM = kStageFromWorld * t;
    double sinTilt = std::clamp(r(2, 1), -1.0, 1.0);
    pose.tiltDeg = std::asin(sinTilt) * kStageDegPerRad;
    double cosTilt = std::hypot(r(0, 1), r(1, 1));
    if (cosTilt > kGimbalCos) {
        pose.panDeg = std::atan2(-r(0, 1), r(1, 1)) * kStageDegPerRad;
        pose.rollDeg = std::atan2(-r(2, 0), r(2, 2)) * kStageDegPerRad;
    } else {
        // R = Rz(p)Rx(±90°): R00 = cos p, R10 = sin p.
        pose.panDeg = std::atan2(r(1, 0), r(0, 0)) * kStageDegPerRad;
        pose.rollDeg = 0;
    }
    return pose;
}

cv::Matx44d worldFromStagePose(const StagePose& pose) {
    return worldFromStage(stageRotation(pose.panDeg, pose.tiltDeg, pose.rollDeg),
                          pose.translationM);
}

cv::Matx44d worldFromStage(const cv::Matx33d& stageFromBody, const cv::Vec3d& translationM) {
    cv::Matx33d r = kStageFromWorld.t() * stageFromBody * kBodyFromCv;
    cv::Vec3d t = kStageFromWorld.t() * translationM;
    return cv::Matx44d(r(0, 0), r(0, 1), r(0, 2), t[0], r(1, 0), r(1, 1), r(1, 2), t[1], r(2, 0),
                       r(2, 1), r(2, 2), t[2], 0, 0, 0, 1);
}

}  // namespace previs
