#include "vision/lens_grid.h"

#include <cmath>
#include <opencv2/calib3d.hpp>

namespace previs {

Result<std::vector<glm::vec2>> lensRayGrid(const CameraCalibration& calibration, uint32_t width,
                                           uint32_t height) {
    cv::Size size = calibration.imageSize();
    if (size.width != int(width) || size.height != int(height))
        return makeError(
            "the camera calibration is for {}x{} images but the render is {}x{}; "
            "render at the calibrated size",
            size.width, size.height, width, height);
    std::vector<cv::Point2d> corners;
    corners.reserve(size_t(width + 1) * (height + 1));
    for (uint32_t j = 0; j <= height; ++j)
        for (uint32_t i = 0; i <= width; ++i) corners.emplace_back(i - 0.5, j - 0.5);
    std::vector<cv::Point2d> normalised;
    try {
        cv::Mat k(calibration.cameraMatrix());
        if (calibration.model() == DistortionModel::Fisheye) {
            cv::fisheye::undistortPoints(corners, normalised, k, calibration.distortion());
        } else {
            // Iterate to convergence: the default 5 iterations leave pixel-sized errors at the
            // corners of wide lenses.
            cv::undistortPoints(
                corners, normalised, k, calibration.distortion(), cv::noArray(), cv::noArray(),
                cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 200, 1e-14));
        }
    } catch (const cv::Exception& e) {
        return makeError("cannot invert the lens model: {}", e.what());
    }
    std::vector<glm::vec2> grid;
    grid.reserve(normalised.size());
    for (const auto& p : normalised) {
        if (!std::isfinite(p.x) || !std::isfinite(p.y))
            return makeError(
                "the lens model has no ray for some image corner (field of view at "
                "or beyond 180°?)");
        grid.emplace_back(float(p.x), float(p.y));
    }
    return grid;
}

}  // namespace previs
