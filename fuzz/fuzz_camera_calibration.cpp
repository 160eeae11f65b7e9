// CameraCalibration::load on an OpenCV YAML calibration (docs/camera-calibration.md), and the
// projections a loaded calibration then runs.
#include "fuzz/fuzz_support.h"
#include "vision/camera_calibration.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace previs;
    const std::string path = fuzz::writeScratch("calibration.yaml", fuzz::asText(data, size));
    Result<CameraCalibration> calib = CameraCalibration::load(path);
    if (calib.ok()) {
        (void)calib->projectPoints({cv::Point3d(0.1, -0.2, 1.0)});
        (void)calib->undistortPixels({cv::Point2d(10.0, 20.0)});
    }
    return 0;
}
