#include "vision/fisheye_to_equirect.h"

#include <cmath>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "vision/equirect.h"
#include "vision/tag_board.h"

namespace previs {

namespace {

// Kannala–Brandt θd(θ) of cv::fisheye.
double kbDistort(double theta, const std::vector<double>& k) {
    const double t2 = theta * theta;
    return theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
}

}  // namespace

std::optional<cv::Point2d> FisheyeToEquirect::project(const cv::Vec3d& d) const {
    const double rho = std::hypot(d[0], d[1]);
    const double theta = std::atan2(rho, d[2]);
    if (theta > maxThetaRad_) return std::nullopt;
    cv::Point2d px;
    const cv::Matx33d& k = cameraMatrix_;
    if (model_ == DistortionModel::Fisheye) {
        // cv::fisheye's projection, written out because cv::fisheye::projectPoints goes through
        // x/z and cannot represent directions 90° or more off the axis.
        double xd = 0.0;
        double yd = 0.0;
        if (rho > 1e-12) {
            const double thetaD = kbDistort(theta, distortion_);
            xd = thetaD * d[0] / rho;
            yd = thetaD * d[1] / rho;
        }
        px = cv::Point2d(k(0, 0) * xd + k(0, 1) * yd + k(0, 2), k(1, 1) * yd + k(1, 2));
    } else {
        if (d[2] <= 1e-9) return std::nullopt;
        std::vector<cv::Point3d> in{cv::Point3d(d[0], d[1], d[2])};
        std::vector<cv::Point2d> out;
        cv::Vec3d zero(0, 0, 0);
        cv::projectPoints(in, zero, zero, cv::Mat(k), distortion_, out);
        px = out[0];
    }
    // Half a pixel beyond the outermost pixel centres is still on the sensor.
    if (!(px.x >= -0.5 && px.y >= -0.5 && px.x <= imageSize_.width - 0.5 &&
          px.y <= imageSize_.height - 0.5))
        return std::nullopt;
    return px;
}

std::optional<cv::Point2d> FisheyeToEquirect::pixelForDirection(
    const cv::Vec3d& worldDirection) const {
    const double n = cv::norm(worldDirection);
    if (!(n > 0.0)) return std::nullopt;
    return project(worldFromFisheye_.t() * (worldDirection / n));
}

Result<FisheyeToEquirect> FisheyeToEquirect::create(const CameraCalibration& calibration,
                                                    const FisheyeToEquirectSettings& settings) {
    if (settings.width < 8 || settings.width > 16384 || settings.width % 2 != 0)
        return makeError("--width {}: the map width must be even and within 8..16384",
                         settings.width);
    for (int i = 0; i < 3; ++i)
        if (!std::isfinite(settings.mountRotationDeg[i]))
            return makeError("--mount-rotation: angles must be finite numbers (degrees)");
    if (!(settings.maxFieldAngleDeg > 0.0 && settings.maxFieldAngleDeg <= 180.0))
        return makeError("max field angle {}°: must be within (0, 180]", settings.maxFieldAngleDeg);

    FisheyeToEquirect f;
    f.cameraMatrix_ = calibration.cameraMatrix();
    f.distortion_ = calibration.distortion();
    f.model_ = calibration.model();
    f.imageSize_ = calibration.imageSize();
    f.settings_ = settings;
    f.worldFromFisheye_ = rotationFromEulerDeg(
        settings.mountRotationDeg[0], settings.mountRotationDeg[1], settings.mountRotationDeg[2]);
    f.maxThetaRad_ = settings.maxFieldAngleDeg * M_PI / 180.0;
    if (f.model_ == DistortionModel::Fisheye) {
        // Past the angle where θd(θ) stops growing, two directions share a pixel: stop there.
        const double step = 1e-3;
        for (double t = step; t <= f.maxThetaRad_; t += step) {
            if (kbDistort(t, f.distortion_) <= kbDistort(t - step, f.distortion_)) {
                f.maxThetaRad_ = t - step;
                break;
            }
        }
    } else {
        f.maxThetaRad_ = std::min(f.maxThetaRad_, M_PI / 2.0 - 1e-6);
    }

    const int w = settings.width;
    const int h = w / 2;
    f.mapX_.create(h, w, CV_32F);
    f.mapY_.create(h, w, CV_32F);
    f.seen_ = cv::Mat::zeros(h, w, CV_8U);
    const double ringTheta = f.maxThetaRad_ - settings.fillRingDeg * M_PI / 180.0;
    const cv::Matx33d fisheyeFromWorld = f.worldFromFisheye_.t();
    double seenSolidAngle = 0.0;
    for (int y = 0; y < h; ++y) {
        const double texelSolidAngle = equirectTexelSolidAngle(y, w, h);
        for (int x = 0; x < w; ++x) {
            const cv::Vec3d d = fisheyeFromWorld * equirectTexelDirection(x, y, w, h);
            std::optional<cv::Point2d> px = f.project(d);
            if (!px) {
                f.mapX_.at<float>(y, x) = -1.0f;
                f.mapY_.at<float>(y, x) = -1.0f;
                continue;
            }
            f.mapX_.at<float>(y, x) = float(px->x);
            f.mapY_.at<float>(y, x) = float(px->y);
            f.seen_.at<uint8_t>(y, x) = 255;
            seenSolidAngle += texelSolidAngle;
            const double theta = std::atan2(std::hypot(d[0], d[1]), d[2]);
            if (theta >= ringTheta) {
                f.ringTexels_.push_back(y * w + x);
                f.ringWeights_.push_back(float(texelSolidAngle));
            }
        }
    }
    f.seenFraction_ = seenSolidAngle / (4.0 * M_PI);
    if (f.seenFraction_ <= 0.0)
        return makeError(
            "the calibration and mount leave no direction seen (image {}x{}, field {:.1f}°); "
            "check the calibration file",
            f.imageSize_.width, f.imageSize_.height, f.maxThetaRad_ * 180.0 / M_PI);
    cv::convertMaps(f.mapX_, f.mapY_, f.fixedMap1_, f.fixedMap2_, CV_16SC2);
    return f;
}

Result<cv::Mat> FisheyeToEquirect::apply(const cv::Mat& linearRgb) const {
    if (linearRgb.type() != CV_32FC3)
        return makeError("fisheye frame: expected linear float RGB (CV_32FC3)");
    if (linearRgb.size() != imageSize_)
        return makeError(
            "fisheye frame is {}x{} but the calibration is for {}x{}; use the "
            "calibration of this camera mode",
            linearRgb.cols, linearRgb.rows, imageSize_.width, imageSize_.height);
    cv::Mat clean = linearRgb.clone();
    for (int y = 0; y < clean.rows; ++y) {
        float* p = clean.ptr<float>(y);
        for (int i = 0; i < clean.cols * 3; ++i)
            if (!(p[i] >= 0.0f) || !std::isfinite(p[i])) p[i] = 0.0f;
    }
    cv::Mat out;
    // OpenCV throws only on programming errors here (types were checked): caught at the edge.
    try {
        cv::remap(clean, out, fixedMap1_, fixedMap2_, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
    } catch (const cv::Exception& e) {
        return makeError("fisheye resampling failed: {}", e.err);
    }
    double sum[3] = {0.0, 0.0, 0.0};
    double weight = 0.0;
    const cv::Vec3f* texels = out.ptr<cv::Vec3f>(0);
    for (size_t i = 0; i < ringTexels_.size(); ++i) {
        const cv::Vec3f& t = texels[ringTexels_[i]];
        for (int c = 0; c < 3; ++c) sum[c] += double(ringWeights_[i]) * t[c];
        weight += ringWeights_[i];
    }
    cv::Vec3f fill(0.0f, 0.0f, 0.0f);
    if (weight > 0.0)
        fill = cv::Vec3f(float(sum[0] / weight), float(sum[1] / weight), float(sum[2] / weight));
    out.setTo(cv::Scalar(fill[0], fill[1], fill[2]), ~seen_);
    return out;
}

}  // namespace previs
