#pragma once

// The calibrated lens as the renderer needs it: for each pixel corner of a W×H image, the
// normalised camera-ray coordinates (x/z, y/z in OpenCV's camera frame: x right, y down,
// z forward) that the lens maps there. Primary rays interpolate this grid, so rendered pixels
// line up with the camera image without resampling it (issue: "real camera lenses").

#include <cstdint>
#include <glm/glm.hpp>
#include <opencv2/core.hpp>
#include <vector>

#include "base/result.h"
#include "vision/camera_calibration.h"

namespace previs {

// (W+1)×(H+1) entries, row-major; corner (i, j) is the image position (i, j) in previs's pixel
// convention (pixel x covers [x, x+1)), i.e. OpenCV's (i − 0.5, j − 0.5). The image must have the
// calibration's size. Fails for a lens that sees a corner at or beyond 90° off axis (the grid
// cannot represent it).
Result<std::vector<glm::vec2>> lensRayGrid(const CameraCalibration& calibration, uint32_t width,
                                           uint32_t height);

// The renderer's camera (looks along −Z, +Y up; DESIGN.md §4) from a pose in OpenCV's camera
// axes (x right, y down, z forward; BoardPose::worldFromCamera): the same frame with y and z
// flipped.
inline glm::mat4 renderWorldFromOpenCvCamera(const cv::Matx44d& worldFromCameraCv) {
    glm::mat4 out(1.0f);  // column-major
    for (int r = 0; r < 3; ++r) {
        out[0][r] = float(worldFromCameraCv(r, 0));
        out[1][r] = float(-worldFromCameraCv(r, 1));
        out[2][r] = float(-worldFromCameraCv(r, 2));
        out[3][r] = float(worldFromCameraCv(r, 3));
    }
    return out;
}

}  // namespace previs
