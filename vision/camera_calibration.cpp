#include "vision/camera_calibration.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <exception>
#include <opencv2/calib3d.hpp>
#include <thread>
#include <utility>

namespace previs {

namespace {

// OpenCV 4.6's YAML parser loops forever on some malformed files (fuzz/fuzz_camera_calibration
// found a 91-byte one, tests/vision/data/fuzz_opencv_yaml_hang.yaml), and a box must not hang on
// a half-written file. So the file is first parsed in a forked child with a time limit; only a
// file that parses there in time is parsed again here. Parsing is deterministic, so the second
// parse ends too. The child only parses and exits (_exit: no atexit handlers, no flushes).
constexpr int kParseTimeLimitMs = 5000;

Status parsesInBoundedTime(const std::string& path) {
    const pid_t child = ::fork();
    if (child < 0) return {};  // cannot fork: parse in-process as before
    if (child == 0) {
        int code = 0;
        try {
            cv::FileStorage fs(path, cv::FileStorage::READ);
        } catch (...) {
            code = 1;  // the in-process parse reports it
        }
        ::_exit(code);
    }
    const auto deadline =
        std::chrono::steady_clock::now() + std::chrono::milliseconds(kParseTimeLimitMs);
    for (;;) {
        int status = 0;
        const pid_t r = ::waitpid(child, &status, WNOHANG);
        if (r == child || (r < 0 && errno != EINTR)) return {};
        if (std::chrono::steady_clock::now() > deadline) {
            ::kill(child, SIGKILL);
            ::waitpid(child, &status, 0);
            return makeError(
                "cannot read camera calibration '{}': OpenCV's parser did not finish within {} s "
                "(a malformed or truncated YAML/XML file?); check or rewrite the file",
                path, kParseTimeLimitMs / 1000);
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
}

bool validCoefficientCount(DistortionModel model, size_t n) {
    if (model == DistortionModel::Fisheye) return n == 4;
    return n == 0 || n == 4 || n == 5 || n == 8 || n == 12 || n == 14;
}

}  // namespace

Result<CameraCalibration> CameraCalibration::create(const cv::Matx33d& cameraMatrix,
                                                    std::vector<double> distortion,
                                                    cv::Size imageSize, DistortionModel model,
                                                    const std::string& source) {
    const cv::Matx33d& k = cameraMatrix;
    for (int i = 0; i < 9; ++i)
        if (!std::isfinite(k.val[i]))
            return makeError("{}: camera_matrix has a non-finite entry; recalibrate the camera",
                             source);
    if (!(k(0, 0) > 0.0) || !(k(1, 1) > 0.0))
        return makeError("{}: camera_matrix has focal lengths fx={} fy={}; both must be > 0",
                         source, k(0, 0), k(1, 1));
    if (k(1, 0) != 0.0 || k(2, 0) != 0.0 || k(2, 1) != 0.0 || k(2, 2) != 1.0)
        return makeError(
            "{}: camera_matrix is not of the form [fx s cx; 0 fy cy; 0 0 1]; write it as "
            "OpenCV's calibration does",
            source);
    if (imageSize.width <= 0 || imageSize.height <= 0)
        return makeError("{}: image_width/image_height {}x{} must both be positive", source,
                         imageSize.width, imageSize.height);
    if (!validCoefficientCount(model, distortion.size()))
        return makeError(
            "{}: {} distortion coefficients for the {} model (expected {})", source,
            distortion.size(), model == DistortionModel::Fisheye ? "fisheye" : "pinhole",
            model == DistortionModel::Fisheye ? "4: k1 k2 k3 k4" : "0, 4, 5, 8, 12 or 14");
    for (double d : distortion)
        if (!std::isfinite(d))
            return makeError("{}: distortion_coefficients has a non-finite entry", source);

    CameraCalibration calib;
    calib.cameraMatrix_ = cameraMatrix;
    calib.distortion_ = std::move(distortion);
    calib.imageSize_ = imageSize;
    calib.model_ = model;
    return calib;
}

Result<CameraCalibration> CameraCalibration::load(const std::string& path) {
    if (Status bounded = parsesInBoundedTime(path); !bounded) return bounded.error();
    // cv::FileStorage throws cv::Exception on malformed files: caught here, at the module edge.
    try {
        cv::FileStorage fs(path, cv::FileStorage::READ);
        if (!fs.isOpened())
            return makeError(
                "cannot read camera calibration '{}': not found or not an OpenCV YAML/XML file",
                path);
        // OpenCV allocates a matrix of the declared rows x cols before reading its data, so a
        // hostile file declaring billions of elements exhausted memory (found by
        // fuzz/fuzz_camera_calibration): the declared size is checked first.
        for (const auto& [key, maxElements] : {std::pair<const char*, int64_t>{"camera_matrix", 9},
                                               {"distortion_coefficients", 14}}) {
            const cv::FileNode node = fs[key];
            if (node.empty() || !node.isMap()) continue;  // absent, or not a matrix: below
            const cv::FileNode rows = node["rows"];
            const cv::FileNode cols = node["cols"];
            if (!rows.isInt() || !cols.isInt() || int(rows) < 0 || int(cols) < 0 ||
                int64_t(int(rows)) * int(cols) > maxElements)
                return makeError(
                    "{}: {} must be an !!opencv-matrix of at most {} elements with "
                    "integer rows and cols",
                    path, key, maxElements);
        }
        cv::Mat k;
        cv::Mat d;
        fs["camera_matrix"] >> k;
        fs["distortion_coefficients"] >> d;
        int width = 0;
        int height = 0;
        if (fs["image_width"].isInt()) fs["image_width"] >> width;
        if (fs["image_height"].isInt()) fs["image_height"] >> height;
        std::string modelName;
        if (fs["distortion_model"].isString()) fs["distortion_model"] >> modelName;
        if (k.empty() || k.rows != 3 || k.cols != 3)
            return makeError("{}: camera_matrix is missing or not a 3x3 !!opencv-matrix", path);
        if (fs["image_width"].empty() || fs["image_height"].empty())
            return makeError("{}: image_width and image_height are required", path);
        DistortionModel model = DistortionModel::Pinhole;
        if (modelName == "fisheye" || modelName == "kannala_brandt" || modelName == "equidistant")
            model = DistortionModel::Fisheye;
        else if (!modelName.empty() && modelName != "pinhole" && modelName != "plumb_bob" &&
                 modelName != "radtan" && modelName != "rational_polynomial")
            return makeError(
                "{}: distortion_model '{}' is not supported (use 'fisheye' for cv::fisheye, or "
                "leave it out for OpenCV's pinhole model)",
                path, modelName);
        cv::Matx33d km;
        k.convertTo(cv::Mat(3, 3, CV_64F, km.val), CV_64F);
        std::vector<double> dist;
        if (!d.empty()) {
            if (d.rows != 1 && d.cols != 1)
                return makeError("{}: distortion_coefficients must be a row or column vector",
                                 path);
            cv::Mat d64;
            d.convertTo(d64, CV_64F);
            d64 = d64.reshape(1, 1);
            dist.assign(d64.ptr<double>(), d64.ptr<double>() + d64.cols);
        }
        return create(km, std::move(dist), cv::Size(width, height), model, path);
    } catch (const cv::Exception& e) {
        return makeError("cannot parse camera calibration '{}': {} (expected OpenCV YAML/XML)",
                         path, e.err);
    } catch (const std::exception& e) {  // std::bad_alloc from a hostile size, and the like
        return makeError("cannot parse camera calibration '{}': {} (expected OpenCV YAML/XML)",
                         path, e.what());
    }
}

bool CameraCalibration::hasDistortion() const {
    for (double d : distortion_)
        if (d != 0.0) return true;
    return false;
}

std::vector<cv::Point2d> CameraCalibration::undistortPixels(
    const std::vector<cv::Point2d>& pixels) const {
    if (pixels.empty() || (!hasDistortion() && model_ == DistortionModel::Pinhole)) return pixels;
    std::vector<cv::Point2d> out;
    cv::Mat k(cameraMatrix_);
    if (model_ == DistortionModel::Fisheye)
        cv::fisheye::undistortPoints(pixels, out, k, distortion_, cv::noArray(), k);
    else
        cv::undistortPoints(pixels, out, k, distortion_, cv::noArray(), k);
    return out;
}

std::vector<cv::Point2d> CameraCalibration::projectPoints(
    const std::vector<cv::Point3d>& cameraPoints) const {
    std::vector<cv::Point2d> out;
    if (cameraPoints.empty()) return out;
    cv::Mat k(cameraMatrix_);
    cv::Vec3d zero(0.0, 0.0, 0.0);
    if (model_ == DistortionModel::Fisheye) {
        std::vector<double> d = distortion_;
        cv::fisheye::projectPoints(cameraPoints, out, zero, zero, k, d);
    } else {
        cv::projectPoints(cameraPoints, zero, zero, k, distortion_, out);
    }
    return out;
}

}  // namespace previs
