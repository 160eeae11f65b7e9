#pragma once

// Camera pose from all visible tags of a board at once (OpenCV solvePnP + Levenberg–Marquardt
// refinement), and a Tracker that holds the last good pose when tracking is lost.

#include <cmath>
#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "vision/camera_calibration.h"
#include "vision/tag_board.h"
#include "vision/tag_detector.h"
#include "vision/tag_edges.h"
#include "vision/tag_search.h"

namespace previs {

struct BoardPose {
    cv::Matx44d worldFromCamera = cv::Matx44d::eye();
    // RMS distance between the detected corners and the board's corners projected with the pose
    // and the full distortion model, in the image's own (distorted) pixels.
    double reprojErrorPx = 0.0;
    std::vector<int> tagIds;  // tags used, ascending
    // How well the corners determine the pose: one standard deviation of the camera position
    // (metres) and orientation (degrees) for corner noise of max(reprojErrorPx,
    // kNominalCornerNoisePx), first order (σ²(JᵀJ)⁻¹ of the projection Jacobian). A few small,
    // distant tags fit a wrong pose within a pixel; only this says the fit means nothing.
    double positionStdM = 0.0;
    double rotationStdDeg = 0.0;
    double distanceM = 0.0;  // camera to the centroid of the corners used
    // A coplanar board's other pose that fits its corners (the plane tilted the other way), its
    // RMS error in ideal pixels: near the residual itself the corners cannot tell the two apart
    // (a distant or small board). Infinite for a board that is not flat.
    double alternativeErrorPx = INFINITY;
    double planarErrorPx = 0.0;        // the better of the two, measured the same way
    double alternativeAngleDeg = 0.0;  // between the two poses' orientations
};

// Below this the residual of a plane's better pose is not a measure of the corners' noise
// (synthetic corners fit to hundredths of a pixel; real ones to a quarter, tests/vision).
inline constexpr double kAmbiguityNoiseFloorPx = 0.25;

// Corner noise assumed when the residual is smaller (a few corners fit almost any pose): what
// libapriltag achieves on sharp 8-bit frames (tests/vision/rendered_pose_test.cpp measures
// 0.25 px RMS linear, up to 0.7 px with sRGB and blur).
inline constexpr double kNominalCornerNoisePx = 0.5;

// Uses every detection whose id is on the board. An id seen twice in one image is ambiguous
// (which one is the board's?) and is left out. nullopt: no usable tag.
std::optional<BoardPose> estimateBoardPose(const std::vector<TagDetection>& detections,
                                           const TagBoard& board,
                                           const CameraCalibration& calibration);

// Rigid inverse of a 4x4 [R t; 0 1].
cv::Matx44d invertRigid(const cv::Matx44d& m);

struct TrackerSettings {
    double maxReprojErrorPx = 3.0;  // a pose worse than this is not trusted (wrong id, blur)
    int minTags = 1;
    // A pose whose one-sigma uncertainty exceeds these is ill-conditioned and not trusted. The
    // estimate is conservative (σ from the residual, the trace over all three axes): on the ViSP
    // RBT video it reaches 1.8 % / 1.05° where the true error is under 0.4 % / 0.3°, while the
    // wrong poses of distant small tags score 20–170 % / 10–95°; the limits sit between.
    double maxPositionStdFraction = 0.05;
    double maxRotationStdDeg = 3.0;
    // A flat board whose other pose (tilted the other way, BoardPose::alternativeErrorPx) lies
    // more than ambiguityAngleDeg away yet fits the corners within minAmbiguityRatio times the
    // better pose's residual is ambiguous: a little more noise picks the other. The first-order
    // uncertainty above cannot see it (it is computed at whichever minimum was found). In the
    // reach sweep (BENCHMARKS.md) a wrong pose at 8 m (140 %, 88°) had 0.22 against 0.28 px,
    // the good ones at 5-6 m 0.7-1.0 against 0.28 px; frontal views' two poses lie within 5°.
    double ambiguityAngleDeg = 10.0;
    double minAmbiguityRatio = 2.0;
    // Re-fit the corners in linear light (vision/tag_edges.h) through the camera's curve: the
    // table of its radiometric model (linearFromCodeTable of the [cameras.scene.radiometry]
    // the service config gives; pipeline_stages.cpp). Without one the curve is unknown and the
    // corners stay libapriltag's: a refit through a guessed curve moves every edge (sRGB
    // assumed on ViSP's linear renders: 0.7 px outward, tag poses 30-70 mm off).
    bool linearEdges = true;
    std::optional<LinearFromCode> linearFromCode;

    bool operator==(const TrackerSettings&) const = default;
};

// Why a frame gave no trusted pose, by kind, so the service can count them (status
// "trackingLost"): a board out of view, another board or tag family, too little of the board,
// a blurred or wrongly detected frame, a pose its corners do not determine.
enum class LostReason {
    None,            // a trusted pose
    NoTags,          // no tag of the configured family detected
    NoBoardTag,      // tags detected, none on the board (another board, ids not on it)
    TooFewTags,      // fewer board tags than TrackerSettings::minTags
    Reprojection,    // the corners do not fit one pose (blur, a wrong detection)
    IllConditioned,  // a pose the corners do not determine (few, small, far or grazing tags)
    FrameSize,       // the frame is not the calibrated size
    NoTrackerData,   // [tracking] source = "freed": no packet near the frame's time
};
constexpr int kLostReasonCount = 8;
// "noTags", "noBoardTag", …: the status's keys.
const char* toString(LostReason reason);

struct TrackingState {
    std::optional<BoardPose> pose;  // the last good pose (held while lost); none before the first
    bool lost = true;               // this frame gave no trusted pose
    uint64_t framesSinceGood = 0;   // 0 when this frame's pose is good
    std::string reason;             // why the frame was rejected, empty when good
    LostReason lostReason = LostReason::NoTags;  // its kind; None when good
};

// Detection + board pose for one camera, frame after frame (the service's tracking thread).
class Tracker {
public:
    static Result<Tracker> create(const TagDetectorSettings& detectorSettings, TagBoard board,
                                  CameraCalibration calibration, TrackerSettings settings = {});

    // 8-bit grey frame. Logs "tracking lost" / "tracking regained" on transitions only. Tags are
    // searched for where the last pose (if at most kPredictFrames old) puts them
    // (vision/tag_search.h), their corners re-fitted in linear light (vision/tag_edges.h) when
    // the settings give the camera's curve.
    const TrackingState& track(const cv::Mat& gray);
    // The same from detections made elsewhere.
    const TrackingState& update(const std::vector<TagDetection>& detections);

    const TrackingState& state() const { return state_; }
    // Forgets every frame seen: the next is tracked on its own (a benchmark's unrelated views).
    void reset();
    // The tags track() found on its last frame, corners as refined.
    const std::vector<TagDetection>& detections() const { return detections_; }
    const TagSearchStats& searchStats() const { return search_; }

    // A pose older than this many frames predicts nothing: the search goes to full resolution.
    static constexpr uint64_t kPredictFrames = 2;

private:
    Tracker(TagDetector detector, TagBoard board, CameraCalibration calibration,
            TrackerSettings settings);

    TagDetector detector_;
    TagBoard board_;
    CameraCalibration calibration_;
    TrackerSettings settings_;
    TrackingState state_;
    std::vector<TagDetection> detections_;
    TagSearchStats search_;
    bool everGood_ = false;
};

}  // namespace previs
