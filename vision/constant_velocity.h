#pragma once

// The motion model shared by the offline smoother (vision/track_smoother.h) and the live pose
// filter (vision/pose_filter.h): each of the camera's three position coordinates and three
// rotation-vector coordinates is a constant-velocity process driven by white-noise acceleration
// (Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to Tracking and Navigation",
// §6.2), measured by the tracker with its own one-sigma uncertainty.

#include <array>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

namespace previs {

inline constexpr double kRadPerDeg = CV_PI / 180.0;

// One coordinate: state (value, rate), covariance [[a, b], [b, c]].
struct AxisState {
    double x = 0.0, v = 0.0;
    double pxx = 0.0, pxv = 0.0, pvv = 0.0;
};

// x' = F x, P' = F P Fᵀ + Q for F = [[1, dt], [0, 1]] and the white-noise-acceleration
// Q = q [[dt³/3, dt²/2], [dt²/2, dt]].
inline AxisState predict(const AxisState& s, double dt, double q) {
    AxisState p;
    p.x = s.x + dt * s.v;
    p.v = s.v;
    p.pxx = s.pxx + 2.0 * dt * s.pxv + dt * dt * s.pvv + q * dt * dt * dt / 3.0;
    p.pxv = s.pxv + dt * s.pvv + q * dt * dt / 2.0;
    p.pvv = s.pvv + q * dt;
    return p;
}

// Measurement z of the value with variance r.
inline AxisState update(const AxisState& s, double z, double r) {
    const double innovation = z - s.x;
    const double sVar = s.pxx + r;
    const double kx = s.pxx / sVar, kv = s.pxv / sVar;
    AxisState u;
    u.x = s.x + kx * innovation;
    u.v = s.v + kv * innovation;
    u.pxx = (1.0 - kx) * s.pxx;
    u.pxv = (1.0 - kx) * s.pxv;
    u.pvv = s.pvv - kv * s.pxv;
    return u;
}

// The rotation vector of R, chosen among its equivalents (θ + 2πn along the axis) nearest
// `near`, so a sequence of rotations gives a continuous sequence of vectors.
inline cv::Vec3d continuousRotationVector(const cv::Matx33d& r, const cv::Vec3d& near) {
    cv::Vec3d v;
    cv::Rodrigues(r, v);
    const double angle = cv::norm(v);
    if (angle < 1e-12) return v;
    const cv::Vec3d axis = v / angle;
    cv::Vec3d best = v;
    for (int n = -2; n <= 2; ++n) {
        const cv::Vec3d candidate = axis * (angle + 2.0 * CV_PI * n);
        if (cv::norm(candidate - near) < cv::norm(best - near)) best = candidate;
    }
    return best;
}

// The state at a first measurement z: at rest, but with a generous rate variance.
inline std::array<AxisState, 6> initialState(const std::array<double, 6>& z) {
    std::array<AxisState, 6> state{};
    for (size_t a = 0; a < 6; ++a) {
        state[a].x = z[a];
        state[a].pxx = 1.0;
        state[a].pvv = a < 3 ? 1.0 : 10.0;
    }
    return state;
}

}  // namespace previs
