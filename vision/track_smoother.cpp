#include "vision/track_smoother.h"

#include <array>
#include <cmath>
#include <opencv2/calib3d.hpp>
#include <optional>

namespace previs {

namespace {

constexpr double kRadPerDeg = CV_PI / 180.0;

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

// The state at a first measurement z: at rest, but with a generous rate variance.
std::array<AxisState, 6> initialState(const std::array<double, 6>& z) {
    std::array<AxisState, 6> state{};
    for (size_t a = 0; a < 6; ++a) {
        state[a].x = z[a];
        state[a].pxx = 1.0;
        state[a].pvv = a < 3 ? 1.0 : 10.0;
    }
    return state;
}

// The model's noise: white-noise acceleration densities (position m²/s³, rotation rad²/s³) and
// the factors on the tracker's own variances.
struct NoiseModel {
    double positionQ = 0.1;
    double rotationQ = 0.03;
    double positionRScale = 1.0;
    double rotationRScale = 1.0;
};

// The measurement variances of one tracked sample under `noise`: position (m²), rotation (rad²).
std::array<double, 2> measurementVariances(const TrackSample& sample, const NoiseModel& noise) {
    return {noise.positionRScale * std::pow(std::max(sample.positionStdM, 1e-5), 2),
            noise.rotationRScale * std::pow(std::max(sample.rotationStdDeg, 1e-3) * kRadPerDeg, 2)};
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

// The tracked samples as six coordinates: position, and the rotation relative to the first
// tracked one as a continuous rotation vector.
struct Coordinates {
    size_t first = 0, last = 0;
    cv::Matx33d reference = cv::Matx33d::eye();
    std::vector<std::array<double, 6>> z;
};

std::optional<Coordinates> coordinatesOf(const std::vector<TrackSample>& samples) {
    const size_t n = samples.size();
    Coordinates c;
    c.first = n;
    for (size_t i = 0; i < n; ++i)
        if (samples[i].worldFromCamera) {
            c.first = std::min(c.first, i);
            c.last = i;
        }
    if (c.first == n) return std::nullopt;
    c.reference = samples[c.first].worldFromCamera->get_minor<3, 3>(0, 0);
    c.z.resize(n);
    cv::Vec3d previous(0, 0, 0);
    for (size_t i = c.first; i <= c.last; ++i) {
        if (!samples[i].worldFromCamera) continue;
        const cv::Matx44d& m = *samples[i].worldFromCamera;
        const cv::Vec3d r =
            continuousRotationVector(c.reference.t() * m.get_minor<3, 3>(0, 0), previous);
        previous = r;
        c.z[i] = {m(0, 3), m(1, 3), m(2, 3), r[0], r[1], r[2]};
    }
    return c;
}

struct ForwardPass {
    std::vector<std::array<AxisState, 6>> predicted, filtered;
    std::vector<double> dts;
    // Of the innovations, position and rotation apart (the two groups' axes are independent).
    std::array<double, 2> logLikelihood{0.0, 0.0};
};

// The forward Kalman pass over [first, last].
ForwardPass forwardPass(const std::vector<TrackSample>& samples, const Coordinates& c,
                        const NoiseModel& noise) {
    const size_t n = samples.size();
    ForwardPass f{std::vector<std::array<AxisState, 6>>(n),
                  std::vector<std::array<AxisState, 6>>(n),
                  std::vector<double>(n, 0.0),
                  {0.0, 0.0}};
    for (size_t i = c.first; i <= c.last; ++i) {
        std::array<AxisState, 6> state{};
        if (i == c.first) {
            state = initialState(c.z[i]);
        } else {
            f.dts[i] = double(samples[i].timestampNs - samples[i - 1].timestampNs) * 1e-9;
            for (int a = 0; a < 6; ++a)
                state[size_t(a)] = predict(f.filtered[i - 1][size_t(a)], f.dts[i],
                                           a < 3 ? noise.positionQ : noise.rotationQ);
        }
        f.predicted[i] = state;
        if (samples[i].worldFromCamera) {
            const std::array<double, 2> r = measurementVariances(samples[i], noise);
            for (int a = 0; a < 6; ++a) {
                const double innovation = c.z[i][size_t(a)] - state[size_t(a)].x;
                const double variance = state[size_t(a)].pxx + r[a < 3 ? 0 : 1];
                if (i != c.first)
                    f.logLikelihood[a < 3 ? 0 : 1] -=
                        0.5 * (std::log(variance) + innovation * innovation / variance);
                state[size_t(a)] = update(state[size_t(a)], c.z[i][size_t(a)], r[a < 3 ? 0 : 1]);
            }
        }
        f.filtered[i] = state;
    }
    return f;
}

NoiseModel fitNoise(const std::vector<TrackSample>& samples, const Coordinates& c,
                    const SmootherSettings& settings) {
    NoiseModel model{settings.positionQ, settings.rotationQ * kRadPerDeg * kRadPerDeg, 1.0, 1.0};
    if (!settings.estimateNoise) return model;
    // The noise the take itself supports best: the settings' q, and the tracker's own
    // variances, each scaled by the grid point of highest likelihood of the filter's
    // innovations (q by 10^-4 … 10^4, the variances by 10^-2 … 10, in half decades), position
    // and rotation apart. A steady dolly gets a stiff model and a whip pan a loose one, and a
    // tracker that misjudges its own noise is corrected, without anyone choosing.
    std::array<double, 2> best{-INFINITY, -INFINITY};
    NoiseModel fitted = model;
    for (int k = -8; k <= 8; ++k)
        for (int j = -4; j <= 2; ++j) {
            const double qs = std::pow(10.0, 0.5 * k), rs = std::pow(10.0, 0.5 * j);
            const NoiseModel trial{model.positionQ * qs, model.rotationQ * qs, rs, rs};
            const std::array<double, 2> l = forwardPass(samples, c, trial).logLikelihood;
            if (l[0] > best[0]) {
                best[0] = l[0];
                fitted.positionQ = trial.positionQ;
                fitted.positionRScale = rs;
            }
            if (l[1] > best[1]) {
                best[1] = l[1];
                fitted.rotationQ = trial.rotationQ;
                fitted.rotationRScale = rs;
            }
        }
    return fitted;
}

}  // namespace

std::vector<std::optional<cv::Matx44d>> smoothTrack(const std::vector<TrackSample>& samples,
                                                    const SmootherSettings& settings) {
    const size_t n = samples.size();
    std::vector<std::optional<cv::Matx44d>> out(n);
    const std::optional<Coordinates> c = coordinatesOf(samples);
    if (!c) return out;
    const size_t first = c->first, last = c->last;
    const cv::Matx33d& reference = c->reference;
    const ForwardPass pass = forwardPass(samples, *c, fitNoise(samples, *c, settings));
    const auto& predicted = pass.predicted;
    const auto& filtered = pass.filtered;
    const auto& dts = pass.dts;

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
