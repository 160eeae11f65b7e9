#pragma once

// Fisheye frame → equirectangular environment map (DESIGN.md §3 `previs envmap`, §4
// orientation) through a lookup built once per calibration, mount and size. Each texel is the
// solid-angle mean of the fisheye image over the texel's footprint, not a point sample: a sun a
// few fisheye pixels across keeps its power in the map whatever the map's resolution.

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

    bool operator==(const FisheyeToEquirectSettings&) const = default;
};

class FisheyeToEquirect {
public:
    static Result<FisheyeToEquirect> create(const CameraCalibration& calibration,
                                            const FisheyeToEquirectSettings& settings = {});

    // Linear RGB fisheye frame (CV_32FC3, the calibration's size) → linear RGB map (CV_32FC3,
    // width × width/2): each texel the mean, weighted by solid angle, of the bilinearly
    // interpolated image over sub-directions spread across the texel, dense enough (at least two
    // per fisheye pixel each way) that the integral of the interpolated image over the texel is
    // the sum of the pixels it covers times their solid angles. Fill rule for the directions the
    // lens does not see: they get one constant radiance, the solid-angle-weighted mean over the
    // outermost fillRingDeg of the seen field (the "lowest visible ring" for an upward-looking
    // lens). A constant keeps the unseen part's power plausible (the ground reflects roughly the
    // mean of what it sees) without inventing a second sun as mirroring the visible hemisphere
    // would. Non-finite or negative input radiance is taken as 0.
    Result<cv::Mat> apply(const cv::Mat& linearRgb) const;
    // A per-pixel flag (CV_8U, the calibration's size, non-zero = set) → the map's texels whose
    // footprint holds a flagged pixel (CV_8U, 255 = set; unseen texels are never set). For the
    // texels a bracket left clipped.
    Result<cv::Mat> applyAny(const cv::Mat& pixelFlags) const;

    // For each map texel the fisheye pixel its centre projects to (OpenCV convention, integer =
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
    // Appends texel (x, y)'s footprint to the footprint lists; false when no part of it is seen.
    bool addFootprint(int x, int y, const cv::Matx33d& fisheyeFromWorld);

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
    // The footprints as a sparse matrix, texel by texel (row i = texel i, compressed rows):
    // entries footprintStart_[i] .. footprintStart_[i+1] of footprintPixel_ (y·W + x) and
    // footprintWeight_ (summing to 1 per seen texel).
    std::vector<uint32_t> footprintStart_;
    std::vector<uint32_t> footprintPixel_;
    std::vector<float> footprintWeight_;
    double seenFraction_ = 0.0;
    std::vector<int> ringTexels_;     // map texel indices in the fill ring
    std::vector<float> ringWeights_;  // their solid angles
};

}  // namespace previs
