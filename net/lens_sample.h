#pragma once

// The lens of one tracked frame as the protocols need it, from the calibration the tracker uses
// (vision/camera_calibration.h gives every field but the sensor size): kept free of vision/ so
// the protocols build without it. From a CameraCalibration `c`:
//     LensSample lens{c.fx(), c.fy(), c.cx(), c.cy(), c.imageSize().width,
//                     c.imageSize().height, sensorWidthMm /* or kFullFrameWidthMm */,
//                     c.distortion(), c.model() == DistortionModel::Fisheye};

#include <vector>

namespace previs {

// 36 mm: a full-frame (35 mm still) gate. Used when the sensor width is not configured, which
// makes every millimetre value a 35 mm-equivalent one (the field of view stays exact).
inline constexpr double kFullFrameWidthMm = 36.0;

struct LensSample {
    // OpenCV camera matrix, pixels, origin at the top-left pixel's corner as OpenCV's is.
    double fxPx = 0, fyPx = 0, cxPx = 0, cyPx = 0;
    int widthPx = 0, heightPx = 0;
    // Width of the image's area on the sensor, millimetres (kFullFrameWidthMm if unknown).
    double sensorWidthMm = kFullFrameWidthMm;
    // OpenCV radial-tangential coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6]]), mapping
    // undistorted to distorted normalised coordinates; empty means none. Ignored when fisheye.
    std::vector<double> distortion;
    bool fisheye = false;  // Kannala–Brandt (cv::fisheye): OpenTrackIO has no such model
    // Focus distance in metres; 0 when unknown (previs' fixed calibration has no focus encoder).
    double focusDistanceM = 0;

    bool valid() const { return fxPx > 0 && widthPx > 0 && heightPx > 0 && sensorWidthMm > 0; }
    double mmPerPx() const { return sensorWidthMm / widthPx; }
    // The pinhole focal length in millimetres on the stated sensor width.
    double focalLengthMm() const { return fxPx * mmPerPx(); }
};

}  // namespace previs
