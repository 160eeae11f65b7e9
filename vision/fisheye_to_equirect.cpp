#include "vision/fisheye_to_equirect.h"

#include <algorithm>
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

bool FisheyeToEquirect::addFootprint(int x, int y, const cv::Matx33d& fisheyeFromWorld) {
    const int w = settings_.width;
    const int h = w / 2;
    auto pixelAt = [&](double u, double v) {
        return project(fisheyeFromWorld * equirectDirection(u / w, v / h));
    };
    // The texel's extent in fisheye pixels along u and v, from where the centres of its
    // neighbours land (or of the one on the other side at the field's edge).
    const std::optional<cv::Point2d> centre = pixelAt(x + 0.5, y + 0.5);
    auto extent = [&](double du, double dv) {
        if (!centre) return 1.0;
        for (double sign : {1.0, -1.0})
            if (auto n = pixelAt(x + 0.5 + sign * du, y + 0.5 + sign * dv))
                return cv::norm(*n - *centre);
        return 1.0;
    };
    // Two sub-directions per fisheye pixel each way: then the integral of the bilinear
    // interpolant over the texel is the sum of the pixels it covers times their areas. The cap
    // bounds the lookup's size for maps far coarser than the fisheye.
    auto count = [](double pixels) { return std::clamp(int(std::ceil(2.0 * pixels)), 1, 32); };
    const int kx = count(extent(1.0, 0.0));
    const int ky = count(extent(0.0, 1.0));
    std::vector<std::pair<uint32_t, float>> taps;
    taps.reserve(size_t(kx) * ky * 4);
    double weightSum = 0.0;
    const int iw = imageSize_.width;
    const int ih = imageSize_.height;
    for (int sy = 0; sy < ky; ++sy) {
        const double v = y + (sy + 0.5) / ky;
        // Solid angle per unit of u·v is proportional to the cosine of the latitude.
        const double weight = std::cos((0.5 - v / h) * M_PI);
        for (int sx = 0; sx < kx; ++sx) {
            const std::optional<cv::Point2d> p = pixelAt(x + (sx + 0.5) / kx, v);
            if (!p) continue;
            const int x0 = int(std::floor(p->x));
            const int y0 = int(std::floor(p->y));
            const double fx = p->x - x0;
            const double fy = p->y - y0;
            for (int t = 0; t < 4; ++t) {
                const int tx = std::clamp(x0 + (t & 1), 0, iw - 1);
                const int ty = std::clamp(y0 + (t >> 1), 0, ih - 1);
                const double b = ((t & 1) ? fx : 1.0 - fx) * ((t >> 1) ? fy : 1.0 - fy);
                if (b > 0.0) taps.emplace_back(uint32_t(ty * iw + tx), float(weight * b));
            }
            weightSum += weight;
        }
    }
    if (!(weightSum > 0.0)) return false;
    std::sort(taps.begin(), taps.end());
    for (size_t i = 0; i < taps.size();) {
        double sum = 0.0;
        size_t j = i;
        for (; j < taps.size() && taps[j].first == taps[i].first; ++j) sum += taps[j].second;
        footprintPixel_.push_back(taps[i].first);
        footprintWeight_.push_back(float(sum / weightSum));
        i = j;
    }
    return true;
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
    f.footprintStart_.reserve(size_t(w) * h + 1);
    f.footprintStart_.push_back(0);
    const double ringTheta = f.maxThetaRad_ - settings.fillRingDeg * M_PI / 180.0;
    const cv::Matx33d fisheyeFromWorld = f.worldFromFisheye_.t();
    double seenSolidAngle = 0.0;
    for (int y = 0; y < h; ++y) {
        const double texelSolidAngle = equirectTexelSolidAngle(y, w, h);
        for (int x = 0; x < w; ++x) {
            const cv::Vec3d d = fisheyeFromWorld * equirectTexelDirection(x, y, w, h);
            const std::optional<cv::Point2d> px = f.project(d);
            f.mapX_.at<float>(y, x) = px ? float(px->x) : -1.0f;
            f.mapY_.at<float>(y, x) = px ? float(px->y) : -1.0f;
            const bool seen = f.addFootprint(x, y, fisheyeFromWorld);
            f.footprintStart_.push_back(uint32_t(f.footprintPixel_.size()));
            if (!seen) continue;
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
    cv::Mat out(height(), width(), CV_32FC3);
    const cv::Vec3f* pixels = clean.ptr<cv::Vec3f>(0);
    cv::parallel_for_(cv::Range(0, out.rows), [&](const cv::Range& rows) {
        for (int y = rows.start; y < rows.end; ++y) {
            cv::Vec3f* row = out.ptr<cv::Vec3f>(y);
            for (int x = 0; x < out.cols; ++x) {
                const size_t texel = size_t(y) * out.cols + x;
                cv::Vec3f sum(0.0f, 0.0f, 0.0f);
                for (uint32_t e = footprintStart_[texel]; e < footprintStart_[texel + 1]; ++e)
                    sum += footprintWeight_[e] * pixels[footprintPixel_[e]];
                row[x] = sum;
            }
        }
    });
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

Result<cv::Mat> FisheyeToEquirect::applyAny(const cv::Mat& pixelFlags) const {
    if (pixelFlags.type() != CV_8U || pixelFlags.size() != imageSize_ || !pixelFlags.isContinuous())
        return makeError("fisheye flags: expected one byte per pixel of the calibration's {}x{}",
                         imageSize_.width, imageSize_.height);
    cv::Mat out = cv::Mat::zeros(height(), width(), CV_8U);
    const uint8_t* flags = pixelFlags.ptr<uint8_t>(0);
    for (int i = 0; i < out.rows * out.cols; ++i)
        for (uint32_t e = footprintStart_[i]; e < footprintStart_[i + 1]; ++e)
            if (flags[footprintPixel_[e]] != 0 && footprintWeight_[e] > 0.0f) {
                out.data[i] = 255;
                break;
            }
    return out;
}

}  // namespace previs
