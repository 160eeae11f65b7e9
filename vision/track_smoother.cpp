#include "vision/track_smoother.h"

#include <array>
#include <cmath>
#include <opencv2/calib3d.hpp>

namespace previs {

namespace {

// One coordinate: state (value, rate), covariance [[a, b], [b, c]].
struct AxisState {
    double x = 0.0, v = 0.0;
    double pxx = 0.0, pxv = 0.0, pvv = 0.0;
};

// x' = F x, P' = F P Fᵀ + Q for F = [[1, dt], [0, 1]] and the white-noise-acceleration
// Q = q [[dt³/3, dt²/2], [dt²/2, dt]].
AxisState predict(const AxisState& s, double dt, double q) {
    AxisState p;
    p.x = s.x + dt * s.v;
    p.v = s.v;
    p.pxx = s.pxx + 2.0 * dt * s.pxv + dt * dt * s.pvv + q * dt * dt * dt / 3.0;
    p.pxv = s.pxv + dt * s.pvv + q * dt * dt / 2.0;
    p.pvv = s.pvv + q * dt;
    return p;
}

// Measurement z of the value with variance r.
AxisState update(const AxisState& s, double z, double r) {
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

// RTS step: the smoothed state at k from its filtered state, the prediction of k+1 from k, and
// the smoothed state at k+1. C = P_k Fᵀ (P⁻_{k+1})⁻¹.
AxisState smoothStep(const AxisState& filtered, const AxisState& predicted,
                     const AxisState& smoothedNext, double dt) {
    // P_k Fᵀ.
    const double a = filtered.pxx + dt * filtered.pxv, b = filtered.pxv;
    const double c = filtered.pxv + dt * filtered.pvv, d = filtered.pvv;
    const double det = predicted.pxx * predicted.pvv - predicted.pxv * predicted.pxv;
    if (!(std::abs(det) > 0.0)) return filtered;
    const double i00 = predicted.pvv / det, i01 = -predicted.pxv / det, i11 = predicted.pxx / det;
    const double c00 = a * i00 + b * i01, c01 = a * i01 + b * i11;
    const double c10 = c * i00 + d * i01, c11 = c * i01 + d * i11;
    const double dx = smoothedNext.x - predicted.x, dv = smoothedNext.v - predicted.v;
    AxisState s = filtered;
    s.x += c00 * dx + c01 * dv;
    s.v += c10 * dx + c11 * dv;
    return s;  // the smoothed covariance is not needed
}

// The rotation vector of R, chosen among its equivalents (θ + 2πn along the axis) nearest
// `near`, so a sequence of rotations gives a continuous sequence of vectors.
cv::Vec3d continuousRotationVector(const cv::Matx33d& r, const cv::Vec3d& near) {
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

}  // namespace

std::vector<std::optional<cv::Matx44d>> smoothTrack(const std::vector<TrackSample>& samples,
                                                    const SmootherSettings& settings) {
    const size_t n = samples.size();
    std::vector<std::optional<cv::Matx44d>> out(n);
    size_t first = n, last = 0;
    for (size_t i = 0; i < n; ++i)
        if (samples[i].worldFromCamera) {
            first = std::min(first, i);
            last = i;
        }
    if (first == n) return out;

    // Rotations relative to the first tracked one, as continuous rotation vectors.
    const cv::Matx33d reference = samples[first].worldFromCamera->get_minor<3, 3>(0, 0);
    std::vector<std::array<double, 6>> z(n);
    cv::Vec3d previous(0, 0, 0);
    for (size_t i = first; i <= last; ++i) {
        if (!samples[i].worldFromCamera) continue;
        const cv::Matx44d& m = *samples[i].worldFromCamera;
        const cv::Vec3d r =
            continuousRotationVector(reference.t() * m.get_minor<3, 3>(0, 0), previous);
        previous = r;
        z[i] = {m(0, 3), m(1, 3), m(2, 3), r[0], r[1], r[2]};
    }

    const double deg = CV_PI / 180.0;
    std::vector<std::array<AxisState, 6>> predicted(n), filtered(n);
    std::vector<double> dts(n, 0.0);
    // The forward Kalman pass; returns the log-likelihood of its innovations, position and
    // rotation apart (the two groups' axes are independent in this model).
    auto forward = [&](double qPosition, double qRotation, double rScalePosition,
                       double rScaleRotation) {
        std::array<double, 2> logLikelihood{0.0, 0.0};
        for (size_t i = first; i <= last; ++i) {
            std::array<AxisState, 6> state{};
            if (i == first) {
                // Starts at the first measurement, at rest but with a generous rate variance.
                for (int a = 0; a < 6; ++a) {
                    state[size_t(a)].x = z[i][size_t(a)];
                    state[size_t(a)].pxx = 1.0;
                    state[size_t(a)].pvv = a < 3 ? 1.0 : 10.0;
                }
            } else {
                dts[i] = double(samples[i].timestampNs - samples[i - 1].timestampNs) * 1e-9;
                for (int a = 0; a < 6; ++a)
                    state[size_t(a)] =
                        predict(filtered[i - 1][size_t(a)], dts[i], a < 3 ? qPosition : qRotation);
            }
            predicted[i] = state;
            if (samples[i].worldFromCamera) {
                const double rPosition =
                    rScalePosition * std::pow(std::max(samples[i].positionStdM, 1e-5), 2);
                const double rRotation =
                    rScaleRotation * std::pow(std::max(samples[i].rotationStdDeg, 1e-3) * deg, 2);
                for (int a = 0; a < 6; ++a) {
                    const double r = a < 3 ? rPosition : rRotation;
                    const double innovation = z[i][size_t(a)] - state[size_t(a)].x;
                    const double variance = state[size_t(a)].pxx + r;
                    if (i != first)
                        logLikelihood[a < 3 ? 0 : 1] -=
                            0.5 * (std::log(variance) + innovation * innovation / variance);
                    state[size_t(a)] = update(state[size_t(a)], z[i][size_t(a)], r);
                }
            }
            filtered[i] = state;
        }
        return logLikelihood;
    };
    // The noise the take itself supports best: the settings' q, and the tracker's own variances,
    // each scaled by the grid point of highest likelihood of the filter's innovations (q by
    // 10^-4 … 10^4, the variances by 10^-2 … 10, in half decades), position and rotation apart.
    // A steady dolly gets a stiff model and a whip pan a loose one, and a tracker that misjudges
    // its own noise is corrected, without anyone choosing.
    std::array<double, 2> q{settings.positionQ, settings.rotationQ * deg * deg};
    std::array<double, 2> rScale{1.0, 1.0};
    if (settings.estimateNoise) {
        std::array<double, 2> best{-INFINITY, -INFINITY};
        std::array<double, 2> bestQ = q, bestR = rScale;
        for (int k = -8; k <= 8; ++k)
            for (int j = -4; j <= 2; ++j) {
                const double qs = std::pow(10.0, 0.5 * k), rs = std::pow(10.0, 0.5 * j);
                const std::array<double, 2> l = forward(q[0] * qs, q[1] * qs, rs, rs);
                for (size_t g = 0; g < 2; ++g)
                    if (l[g] > best[g]) {
                        best[g] = l[g];
                        bestQ[g] = q[g] * qs;
                        bestR[g] = rs;
                    }
            }
        q = bestQ;
        rScale = bestR;
    }
    forward(q[0], q[1], rScale[0], rScale[1]);
    std::vector<std::array<AxisState, 6>> smoothed(n);
    smoothed[last] = filtered[last];
    for (size_t i = last; i-- > first;)
        for (int a = 0; a < 6; ++a)
            smoothed[i][size_t(a)] = smoothStep(filtered[i][size_t(a)], predicted[i + 1][size_t(a)],
                                                smoothed[i + 1][size_t(a)], dts[i + 1]);

    // Gaps: a lost stretch longer than maxGapSeconds between two tracked frames is not bridged.
    std::vector<bool> bridged(n, false);
    for (size_t i = first, previousTracked = first; i <= last; ++i) {
        if (!samples[i].worldFromCamera) continue;
        const double gap =
            double(samples[i].timestampNs - samples[previousTracked].timestampNs) * 1e-9;
        const bool ok = gap <= settings.maxGapSeconds;
        for (size_t j = previousTracked; j <= i; ++j) bridged[j] = ok || j == previousTracked;
        bridged[i] = true;
        previousTracked = i;
    }
    for (size_t i = first; i <= last; ++i) {
        if (!bridged[i]) continue;
        const auto& s = smoothed[i];
        cv::Matx33d r;
        cv::Rodrigues(cv::Vec3d(s[3].x, s[4].x, s[5].x), r);
        const cv::Matx33d rotation = reference * r;
        cv::Matx44d m = cv::Matx44d::eye();
        for (int row = 0; row < 3; ++row) {
            for (int col = 0; col < 3; ++col) m(row, col) = rotation(row, col);
            m(row, 3) = s[size_t(row)].x;
        }
        out[i] = m;
    }
    return out;
}

}  // namespace previs
