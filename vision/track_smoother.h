#pragma once

// Better camera poses offline (issue 36): a fixed-interval smoother over a whole take's track.
// Each of the camera's three position coordinates and three rotation-vector coordinates is a
// constant-velocity process driven by white-noise acceleration; the tracker's own one-sigma
// uncertainty of each pose (BoardPose::positionStdM, rotationStdDeg) is the measurement noise.
// A Kalman filter runs forward and the Rauch–Tung–Striebel pass backward (Rauch, Tung & Striebel
// 1965; Bar-Shalom, Li & Kirubarajan, "Estimation with Applications to Tracking and
// Navigation", §6.2 and §8.6), so every pose uses the frames before and after it. Lost frames
// are predicted across: a gap is bridged when short, and left without a pose when not.

#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <vector>

namespace previs {

struct TrackSample {
    uint64_t timestampNs = 0;
    std::optional<cv::Matx44d> worldFromCamera;  // none: lost on this frame
    double positionStdM = 0.001;                 // the tracker's one sigma
    double rotationStdDeg = 0.05;
};

struct SmootherSettings {
    // The white-noise acceleration's spectral density q: how much the velocity may wander per
    // second (its variance grows by q each second). A dolly or hand-held camera's acceleration
    // changes every ~0.1 s with σ ≈ 1 m/s², so q ≈ σ²·0.1 s = 0.1 m²/s³; a pan's σ ≈ 30 °/s²
    // gives 100 °²/s³. Larger follows sharper moves, smaller averages more frames.
    double positionQ = 0.1;    // m²/s³
    double rotationQ = 100.0;  // °²/s³
    // Scale q (10^-4 … 10^4) and the tracker's variances (10^-2 … 10) by the factors under
    // which the take's own measurements are most likely (maximum likelihood of the filter's
    // innovations), position and rotation apart.
    bool estimateNoise = true;
    // A lost stretch longer than this is not bridged: its frames get no pose.
    double maxGapSeconds = 1.0;
};

// One pose per sample, smoothed; none before the first or after the last tracked frame, or
// inside a gap longer than maxGapSeconds. Timestamps must not decrease.
std::vector<std::optional<cv::Matx44d>> smoothTrack(const std::vector<TrackSample>& samples,
                                                    const SmootherSettings& settings = {});

}  // namespace previs
