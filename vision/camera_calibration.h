#pragma once

// Camera intrinsics and lens distortion as OpenCV's calibration tools write them (DESIGN.md §3):
// a YAML/XML file with camera_matrix, distortion_coefficients, image_width, image_height and, for
// the Kannala–Brandt fisheye model of cv::fisheye, `distortion_model: fisheye`.

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

enum class DistortionModel {
    Pinhole,  // OpenCV's radial-tangential model (cv::projectPoints): 0, 4, 5, 8, 12 or 14 coeffs
    Fisheye,  // Kannala–Brandt as cv::fisheye: θd = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸), 4 coeffs
};

class CameraCalibration {
public:
    // Reads and validates an OpenCV calibration file; every error names the file and the field.
    static Result<CameraCalibration> load(const std::string& path);
    // Validates values built in memory (tests, configs); `source` names them in errors.
    static Result<CameraCalibration> create(const cv::Matx33d& cameraMatrix,
                                            std::vector<double> distortion, cv::Size imageSize,
                                            DistortionModel model, const std::string& source);

    const cv::Matx33d& cameraMatrix() const { return cameraMatrix_; }
    const std::vector<double>& distortion() const { return distortion_; }
    cv::Size imageSize() const { return imageSize_; }
    DistortionModel model() const { return model_; }
    double fx() const { return cameraMatrix_(0, 0); }
    double fy() const { return cameraMatrix_(1, 1); }
    double cx() const { return cameraMatrix_(0, 2); }
    double cy() const { return cameraMatrix_(1, 2); }
    // True when every distortion coefficient is zero (pixels are already ideal pinhole pixels).
    bool hasDistortion() const;

    // Removes the lens distortion: measured pixels → the pixels an ideal pinhole camera with the
    // same camera matrix would have seen. For the fisheye model only points within 90° of the
    // axis have such pixels; OpenCV returns garbage beyond, callers must not pass them.
    std::vector<cv::Point2d> undistortPixels(const std::vector<cv::Point2d>& pixels) const;

    // Projects points given in the camera frame (OpenCV: x right, y down, z forward) to pixels
    // with the distortion model.
    std::vector<cv::Point2d> projectPoints(const std::vector<cv::Point3d>& cameraPoints) const;

private:
    CameraCalibration() = default;

    cv::Matx33d cameraMatrix_ = cv::Matx33d::eye();
    std::vector<double> distortion_;
    cv::Size imageSize_;
    DistortionModel model_ = DistortionModel::Pinhole;
};

}  // namespace previs
