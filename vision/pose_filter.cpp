#include "vision/pose_filter.h"

#include <cmath>
#include <opencv2/calib3d.hpp>

namespace previs {

namespace {

// The 1€ filter's smoothing factor for a cutoff at a sample interval.
double alpha(double cutoffHz, double dt) {
    const double tau = 1.0 / (2.0 * CV_PI * cutoffHz);
    return 1.0 / (1.0 + tau / dt);
}

cv::Matx44d poseOf(const cv::Matx33d& rotation, const cv::Vec3d& position) {
    cv::Matx44d m = cv::Matx44d::eye();
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) m(r, c) = rotation(r, c);
        m(r, 3) = position[r];
    }
    return m;
}

}  // namespace

PoseFilter::PoseFilter(PoseFilterSettings settings) : settings_(settings) {}

void PoseFilter::reset() { *this = PoseFilter(settings_); }

void PoseFilter::start(const cv::Matx44d& pose, uint64_t timestampNs) {
    position_ = {pose(0, 3), pose(1, 3), pose(2, 3)};
    rotation_ = pose.get_minor<3, 3>(0, 0);
    positionSpeed_ = rotationSpeed_ = 0.0;
    started_ = true;
    lastNs_ = timestampNs;
    last_ = poseOf(rotation_, position_);
}

std::optional<cv::Matx44d> PoseFilter::update(const TrackSample& sample) {
    if (!sample.worldFromCamera) return last_;
    const cv::Matx44d& m = *sample.worldFromCamera;
    if (!started_ || sample.timestampNs <= lastNs_ ||
        double(sample.timestampNs - lastNs_) * 1e-9 > settings_.maxGapSeconds) {
        start(m, sample.timestampNs);
        return last_;
    }
    const double dt = double(sample.timestampNs - lastNs_) * 1e-9;
    lastNs_ = sample.timestampNs;
    const double speedAlpha = alpha(settings_.speedCutoffHz, dt);

    // Position: the raw step's speed, low-passed, sets this frame's cutoff.
    const cv::Vec3d position(m(0, 3), m(1, 3), m(2, 3));
    const cv::Vec3d step = position - position_;
    positionSpeed_ += speedAlpha * (cv::norm(step) / dt - positionSpeed_);
    position_ +=
        alpha(settings_.minCutoffHz + settings_.positionBetaPerMps * positionSpeed_, dt) * step;

    // Rotation: the same on the rotation from the filtered orientation to the measured one,
    // taken a fraction of the way along its geodesic.
    cv::Vec3d turn;
    cv::Rodrigues(rotation_.t() * m.get_minor<3, 3>(0, 0), turn);
    const double turnDeg = cv::norm(turn) * 180.0 / CV_PI;
    rotationSpeed_ += speedAlpha * (turnDeg / dt - rotationSpeed_);
    cv::Matx33d partial;
    cv::Rodrigues(
        alpha(settings_.minCutoffHz + settings_.rotationBetaPerDegps * rotationSpeed_, dt) * turn,
        partial);
    rotation_ = rotation_ * partial;

    last_ = poseOf(rotation_, position_);
    return last_;
}

}  // namespace previs
