#include "vision/board_pose.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <opencv2/calib3d.hpp>

#include "base/log.h"

namespace previs {

cv::Matx44d invertRigid(const cv::Matx44d& m) {
    cv::Matx33d r = m.get_minor<3, 3>(0, 0);
    cv::Vec3d t(m(0, 3), m(1, 3), m(2, 3));
    cv::Matx33d rt = r.t();
    cv::Vec3d ti = -(rt * t);
    cv::Matx44d out = cv::Matx44d::eye();
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) out(i, j) = rt(i, j);
        out(i, 3) = ti[i];
    }
    return out;
}

namespace {

// First-order uncertainty of the pose from the corners (BoardPose::positionStdM). Parameters:
// a small rotation δ applied in the camera frame (R = exp(δ)·R₀) and the camera centre C in the
// world, X_c = R·(X_w − C); the Jacobian of the distorted pixels is taken numerically, so both
// lens models are covered by CameraCalibration::projectPoints.
void poseUncertainty(const std::vector<cv::Point3d>& world, const cv::Matx33d& r0,
                     const cv::Vec3d& t0, const CameraCalibration& calibration, BoardPose& pose) {
    const cv::Vec3d c0 = -(r0.t() * t0);
    cv::Vec3d centroid(0, 0, 0);
    for (const cv::Point3d& p : world) centroid += cv::Vec3d(p.x, p.y, p.z);
    centroid *= 1.0 / double(world.size());
    pose.distanceM = cv::norm(centroid - c0);
    auto project = [&](const cv::Vec3d& delta, const cv::Vec3d& c) {
        cv::Matx33d dr;
        cv::Rodrigues(delta, dr);
        const cv::Matx33d r = dr * r0;
        std::vector<cv::Point3d> camera;
        camera.reserve(world.size());
        for (const cv::Point3d& p : world) {
            const cv::Vec3d q = r * (cv::Vec3d(p.x, p.y, p.z) - c);
            camera.emplace_back(q[0], q[1], q[2]);
        }
        return calibration.projectPoints(camera);
    };
    const std::vector<cv::Point2d> base = project({0, 0, 0}, c0);
    const size_t n = base.size();
    cv::Mat jacobian(int(2 * n), 6, CV_64F);
    const double hRotation = 1e-6;
    const double hPosition = 1e-6 * std::max(pose.distanceM, 1e-3);
    for (int k = 0; k < 6; ++k) {
        cv::Vec3d delta(0, 0, 0);
        cv::Vec3d c = c0;
        const double h = k < 3 ? hRotation : hPosition;
        if (k < 3)
            delta[k] = h;
        else
            c[k - 3] += h;
        const std::vector<cv::Point2d> moved = project(delta, c);
        for (size_t i = 0; i < n; ++i) {
            jacobian.at<double>(int(2 * i), k) = (moved[i].x - base[i].x) / h;
            jacobian.at<double>(int(2 * i + 1), k) = (moved[i].y - base[i].y) / h;
        }
    }
    cv::Mat covariance;
    const double sigma = std::max(pose.reprojErrorPx, kNominalCornerNoisePx);
    if (cv::invert(jacobian.t() * jacobian, covariance, cv::DECOMP_SVD) == 0.0 ||
        !cv::checkRange(covariance)) {
        pose.positionStdM = pose.rotationStdDeg = std::numeric_limits<double>::infinity();
        return;
    }
    covariance *= sigma * sigma;
    const auto trace3 = [&](int from) {
        return covariance.at<double>(from, from) + covariance.at<double>(from + 1, from + 1) +
               covariance.at<double>(from + 2, from + 2);
    };
    pose.rotationStdDeg = std::sqrt(std::max(trace3(0), 0.0)) * 180.0 / M_PI;
    pose.positionStdM = std::sqrt(std::max(trace3(3), 0.0));
}

}  // namespace

namespace {

// A plane seen from far away or head on has two poses that fit its image (the two minima of IPPE,
// Collins & Bartoli 2014: the plane tilted either way). The second one's RMS error, on ideal
// pixels, and the angle between the two; infinite error when the points are not coplanar or
// only one pose fits.
struct PlanarAlternative {
    double bestErrorPx = 0.0;
    double errorPx = INFINITY;
    double angleDeg = 0.0;
};
PlanarAlternative planarAlternative(const std::vector<cv::Point3d>& world,
                                    const std::vector<cv::Point2d>& ideal, const cv::Mat& k) {
    cv::Mat centred(int(world.size()), 3, CV_64F);
    cv::Vec3d mean(0, 0, 0);
    for (const cv::Point3d& p : world) mean += cv::Vec3d(p.x, p.y, p.z);
    mean *= 1.0 / double(world.size());
    for (size_t i = 0; i < world.size(); ++i)
        for (int c = 0; c < 3; ++c)
            centred.at<double>(int(i), c) =
                cv::Vec3d(world[i].x, world[i].y, world[i].z)[c] - mean[c];
    cv::Mat w;
    cv::SVD::compute(centred, w, cv::SVD::NO_UV);
    if (!(w.at<double>(2) <= 1e-9 * w.at<double>(0))) return {};
    std::vector<cv::Mat> rvecs, tvecs;
    cv::Mat errors;
    try {
        cv::solvePnPGeneric(world, ideal, k, cv::noArray(), rvecs, tvecs, false, cv::SOLVEPNP_IPPE,
                            cv::noArray(), cv::noArray(), errors);
    } catch (const cv::Exception& e) {
        logDebug("IPPE failed: {}", e.what());
        return {};
    }
    if (rvecs.size() < 2 || errors.total() < 2) return {};
    errors.convertTo(errors, CV_64F);
    cv::Matx33d r0, r1;
    cv::Rodrigues(rvecs[0], r0);
    cv::Rodrigues(rvecs[1], r1);
    const cv::Matx33d d = r0.t() * r1;
    const double c = std::clamp((d(0, 0) + d(1, 1) + d(2, 2) - 1.0) / 2.0, -1.0, 1.0);
    return {std::min(errors.at<double>(0), errors.at<double>(1)),
            std::max(errors.at<double>(0), errors.at<double>(1)), std::acos(c) * 180.0 / M_PI};
}

}  // namespace

std::optional<BoardPose> estimateBoardPose(const std::vector<TagDetection>& detections,
                                           const TagBoard& board,
                                           const CameraCalibration& calibration) {
    std::map<int, int> count;
    for (const TagDetection& d : detections) ++count[d.id];

    std::vector<cv::Point3d> world;
    std::vector<cv::Point2d> pixels;
    std::vector<int> ids;
    for (const TagDetection& d : detections) {
        const BoardTag* tag = board.find(d.id);
        if (!tag || count[d.id] != 1) continue;
        std::array<cv::Point3d, 4> corners = board.worldCorners(*tag);
        world.insert(world.end(), corners.begin(), corners.end());
        for (const cv::Point2d& c : d.corners) pixels.push_back(openCvPixel(c));
        ids.push_back(d.id);
    }
    if (ids.empty()) return std::nullopt;

    // Solve on ideal pinhole pixels (the same for both distortion models), then measure the
    // error on the raw pixels through the full model.
    std::vector<cv::Point2d> ideal = calibration.undistortPixels(pixels);
    std::vector<cv::Point3d> worldUsed;
    std::vector<cv::Point2d> idealUsed;
    std::vector<cv::Point2d> pixelsUsed;
    for (size_t i = 0; i < ideal.size(); ++i) {
        if (!std::isfinite(ideal[i].x) || !std::isfinite(ideal[i].y)) continue;
        worldUsed.push_back(world[i]);
        idealUsed.push_back(ideal[i]);
        pixelsUsed.push_back(pixels[i]);
    }
    if (worldUsed.size() < 4) return std::nullopt;

    cv::Mat k(calibration.cameraMatrix());
    cv::Vec3d rvec;
    cv::Vec3d tvec;
    // OpenCV throws on degenerate input (all points collinear, ...): caught here.
    try {
        // SQPnP: globally optimal for any point layout (coplanar boards included), no initial
        // guess; LM then minimises the reprojection error itself.
        if (!cv::solvePnP(worldUsed, idealUsed, k, cv::noArray(), rvec, tvec, false,
                          cv::SOLVEPNP_SQPNP))
            return std::nullopt;
        cv::solvePnPRefineLM(worldUsed, idealUsed, k, cv::noArray(), rvec, tvec);
    } catch (const cv::Exception& e) {
        logDebug("solvePnP failed: {}", e.what());
        return std::nullopt;
    }
    const PlanarAlternative alternative = planarAlternative(worldUsed, idealUsed, k);
    cv::Matx33d r;
    cv::Rodrigues(rvec, r);
    cv::Matx44d cameraFromWorld = cv::Matx44d::eye();
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) cameraFromWorld(i, j) = r(i, j);
        cameraFromWorld(i, 3) = tvec[i];
    }
    for (int i = 0; i < 16; ++i)
        if (!std::isfinite(cameraFromWorld.val[i])) return std::nullopt;

    std::vector<cv::Point3d> cameraPoints;
    cameraPoints.reserve(worldUsed.size());
    for (const cv::Point3d& p : worldUsed) {
        cv::Vec3d q = r * cv::Vec3d(p.x, p.y, p.z) + tvec;
        cameraPoints.emplace_back(q[0], q[1], q[2]);
    }
    std::vector<cv::Point2d> projected = calibration.projectPoints(cameraPoints);
    double sum = 0.0;
    for (size_t i = 0; i < projected.size(); ++i) {
        cv::Point2d e = projected[i] - pixelsUsed[i];
        sum += e.dot(e);
    }

    BoardPose pose;
    pose.worldFromCamera = invertRigid(cameraFromWorld);
    pose.planarErrorPx = alternative.bestErrorPx;
    pose.alternativeErrorPx = alternative.errorPx;
    pose.alternativeAngleDeg = alternative.angleDeg;
    pose.reprojErrorPx = std::sqrt(sum / double(projected.size()));
    poseUncertainty(worldUsed, r, tvec, calibration, pose);
    std::sort(ids.begin(), ids.end());
    pose.tagIds = std::move(ids);
    return pose;
}

Tracker::Tracker(TagDetector detector, TagBoard board, CameraCalibration calibration,
                 TrackerSettings settings)
    : detector_(std::move(detector)),
      board_(std::move(board)),
      calibration_(std::move(calibration)),
      settings_(settings) {}

Result<Tracker> Tracker::create(const TagDetectorSettings& detectorSettings, TagBoard board,
                                CameraCalibration calibration, TrackerSettings settings) {
    Result<TagDetector> detector = TagDetector::create(detectorSettings);
    if (!detector) return detector.error();
    return Tracker(std::move(detector).value(), std::move(board), std::move(calibration), settings);
}

void Tracker::reset() {
    state_ = {};
    detections_.clear();
    search_ = {};
    everGood_ = false;
}

const TrackingState& Tracker::track(const cv::Mat& gray) {
    std::vector<PredictedTag> predicted;
    if (state_.pose && state_.framesSinceGood <= kPredictFrames)
        predicted = predictTags(board_, calibration_, state_.pose->worldFromCamera, gray.size());
    detections_ = searchTags(detector_, gray, predicted, &search_);
    if (settings_.linearEdges && settings_.linearFromCode)
        refineTagCornersInLinearLight(detections_, gray, *settings_.linearFromCode,
                                      detector_.border(), &calibration_);
    return update(detections_);
}

const char* toString(LostReason reason) {
    switch (reason) {
        case LostReason::None:
            return "none";
        case LostReason::NoTags:
            return "noTags";
        case LostReason::NoBoardTag:
            return "noBoardTag";
        case LostReason::TooFewTags:
            return "tooFewTags";
        case LostReason::Reprojection:
            return "reprojection";
        case LostReason::IllConditioned:
            return "illConditioned";
        case LostReason::FrameSize:
            return "frameSize";
        case LostReason::NoTrackerData:
            return "noTrackerData";
    }
    return "?";
}

const TrackingState& Tracker::update(const std::vector<TagDetection>& detections) {
    std::optional<BoardPose> pose = estimateBoardPose(detections, board_, calibration_);
    std::string reason;
    LostReason kind = LostReason::None;
    if (!pose) {
        kind = detections.empty() ? LostReason::NoTags : LostReason::NoBoardTag;
        reason = detections.empty() ? "no tags detected" : "no tag of the board detected";
    } else if (int(pose->tagIds.size()) < settings_.minTags) {
        kind = LostReason::TooFewTags;
        reason =
            fmt::format("{} board tag(s) seen, {} needed", pose->tagIds.size(), settings_.minTags);
    } else if (pose->reprojErrorPx > settings_.maxReprojErrorPx) {
        kind = LostReason::Reprojection;
        reason = fmt::format("reprojection error {:.2f} px over the {:.2f} px limit",
                             pose->reprojErrorPx, settings_.maxReprojErrorPx);
    } else if (pose->alternativeAngleDeg > settings_.ambiguityAngleDeg &&
               pose->alternativeErrorPx <
                   settings_.minAmbiguityRatio *
                       std::max(pose->planarErrorPx, kAmbiguityNoiseFloorPx)) {
        kind = LostReason::IllConditioned;
        reason = fmt::format(
            "pose ambiguous ({} tag(s) seen): the board tilted {:.0f} deg the other way fits the "
            "corners within {:.2f} px, against {:.2f} px",
            pose->tagIds.size(), pose->alternativeAngleDeg, pose->alternativeErrorPx,
            pose->planarErrorPx);
    } else if (!(pose->positionStdM <= settings_.maxPositionStdFraction * pose->distanceM) ||
               !(pose->rotationStdDeg <= settings_.maxRotationStdDeg)) {
        kind = LostReason::IllConditioned;
        reason = fmt::format(
            "pose ill-conditioned ({} tag(s) seen): uncertain by {:.1f}% of "
            "the distance and {:.2f} deg, limits {:.1f}% and {:.2f} deg",
            pose->tagIds.size(), 100.0 * pose->positionStdM / pose->distanceM, pose->rotationStdDeg,
            100.0 * settings_.maxPositionStdFraction, settings_.maxRotationStdDeg);
    }
    state_.lostReason = kind;

    if (reason.empty()) {
        if (state_.lost && everGood_)
            logInfo("tracking regained after {} frame(s)", state_.framesSinceGood);
        everGood_ = true;
        state_.pose = std::move(pose);
        state_.lost = false;
        state_.framesSinceGood = 0;
        state_.reason.clear();
    } else {
        if (!state_.lost) logWarning("tracking lost ({}); holding the last good pose", reason);
        state_.lost = true;
        ++state_.framesSinceGood;
        state_.reason = std::move(reason);
    }
    return state_;
}

}  // namespace previs
