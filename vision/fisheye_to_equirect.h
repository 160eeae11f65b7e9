#pragma once

// Fisheye frame → equirectangular environment map (DESIGN.md §3 `previs envmap`, §4
// orientation) through a lookup built once per calibration, mount and size.

#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include "base/result.h"
#include "vision/camera_calibration.h"

namespace previs {

struct FisheyeToEquirectSettings {
    // worldFromFisheye = Rz(RZ)·Ry(RY)·Rx(RX), degrees; the default -90,0,0 looks at the zenith
    // with the image's bottom edge toward world −Z.
    cv::Vec3d mountRotationDeg{-90.0, 0.0, 0.0};
    int width = 1024;  // the map is width × width/2
    // Directions further than this from the optical axis count as unseen even when they
    // project into the image: beyond the angle a calibration was fitted on, its model is
    // extrapolation (the shared/data KB calibrations stop at 95°).
    double maxFieldAngleDeg = 95.0;
    // Width of the band at the edge of the seen field whose mean radiance fills the unseen
    // directions (see apply()).
    double fillRingDeg = 5.0;
};

class FisheyeToEquirect {
public:
    static Result<FisheyeToEquirect> create(const CameraCalibration& calibration,
                                            const FisheyeToEquirectSettings& settings = {});

    // Linear RGB fisheye frame (CV_32FC3, the calibration's size) → linear RGB map (CV_32FC3,
    // width × width/2), bilinear. Fill rule for the directions the lens does not see: they get
    // one constant radiance, the solid-angle-weighted mean over the outermost fillRingDeg of
    // the seen field (the "lowest visible ring" for an upward-looking lens). A constant keeps
    // the unseen part's power plausible (the ground reflects roughly the mean of what it sees)
    // without inventing a second sun as mirroring the visible hemisphere would.
    // Non-finite or negative input radiance is taken as 0.
    Result<cv::Mat> apply(const cv::Mat& linearRgb) const;

    // The lookup: for each map texel the fisheye pixel it samples (OpenCV convention, integer =
    // pixel centre), -1 where unseen.
    const cv::Mat& mapX() const { return mapX_; }
    const cv::Mat& mapY() const { return mapY_; }
    const cv::Mat& seenMask() const { return seen_; }      // CV_8U, 255 = seen
    double seenFraction() const { return seenFraction_; }  // of the sphere's solid angle
    const cv::Matx33d& worldFromFisheye() const { return worldFromFisheye_; }
    int width() const { return mapX_.cols; }
    int height() const { return mapX_.rows; }

    // The fisheye pixel a world direction projects to, or nullopt when unseen (the same code
    // that builds the lookup).
    std::optional<cv::Point2d> pixelForDirection(const cv::Vec3d& worldDirection) const;

private:
    FisheyeToEquirect() = default;

    std::optional<cv::Point2d> project(const cv::Vec3d& fisheyeDirection) const;

    // Calibration held by value (CameraCalibration has no empty state).
    cv::Matx33d cameraMatrix_ = cv::Matx33d::eye();
    std::vector<double> distortion_;
    DistortionModel model_ = DistortionModel::Fisheye;
    cv::Size imageSize_;
    FisheyeToEquirectSettings settings_;
    cv::Matx33d worldFromFisheye_ = cv::Matx33d::eye();
    double maxThetaRad_ = 0.0;
    cv::Mat mapX_;
    cv::Mat mapY_;
    cv::Mat seen_;
    cv::Mat fixedMap1_;  // the lookup as cv::convertMaps fixed point, for remap's fast path
    cv::Mat fixedMap2_;
    double seenFraction_ = 0.0;
    std::vector<int> ringTexels_;     // map texel indices in the fill ring
    std::vector<float> ringWeights_;  // their solid angles
};

}  // namespace previs
