#pragma once

// The live pose filter for preview (issue 38): the One-Euro filter (Casiez, Roussel & Vogel,
// "1€ Filter", CHI 2012) on the camera's position and rotation. A first-order low-pass whose
// cutoff rises with the filtered speed: a held camera is smoothed hard (no shimmer), a moving one
// hardly at all (no visible lag), with no model of the motion to get wrong. Position and rotation
// each have their own cutoff and speed gain, in physical units. Lost frames hold the last
// filtered pose (as the tracker holds its own); a gap longer than maxGapSeconds starts the filter
// again at the next pose.
//
// Not the offline smoother's constant-velocity Kalman model (vision/track_smoother.h): fitted on
// a live window, that model's one noise level is either stiff and lags a pan's start by several
// frames, or loose and passes a held camera's jitter through (measured: BENCHMARKS.md, "The live
// pose filter"); the smoother sees the whole take and both sides of each frame, so it need not
// choose.

#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>

#include "vision/track_smoother.h"  // TrackSample

namespace previs {

struct PoseFilterSettings {
    // Cutoff of a held camera, Hz: at 15 fps 0.5 Hz keeps about a third of the noise's standard
    // deviation; the delay it adds to a slow drift is 1/(2π·0.5) ≈ 0.3 s, invisible while held.
    double minCutoffHz = 0.5;
    // Cutoff added per unit of speed: a 0.1 m/s dolly or a 10°/s pan lifts it to 15-20 Hz (a
    // few milliseconds of delay at 15-30 fps), while the tracker's noise at rest (a few mm/s,
    // tenths of a degree per second) lifts it by under half a hertz. Chosen on the measured
    // sequences of `previs bench --only filter` (BENCHMARKS.md): 75 and 1 left 5-7 ms of lag.
    double positionBetaPerMps = 150.0;  // Hz per m/s
    double rotationBetaPerDegps = 2.0;  // Hz per °/s
    double speedCutoffHz = 1.0;         // the speed estimate's own low-pass
    double maxGapSeconds = 0.5;
};

class PoseFilter {
public:
    explicit PoseFilter(PoseFilterSettings settings = {});

    // This sample's filtered pose (none before the first tracked one). Timestamps must not
    // decrease; a sample without a pose holds the last filtered one.
    std::optional<cv::Matx44d> update(const TrackSample& sample);
    void reset();

private:
    void start(const cv::Matx44d& pose, uint64_t timestampNs);

    PoseFilterSettings settings_;
    bool started_ = false;
    uint64_t lastNs_ = 0;
    cv::Vec3d position_;
    cv::Matx33d rotation_ = cv::Matx33d::eye();
    double positionSpeed_ = 0.0;  // m/s, low-passed
    double rotationSpeed_ = 0.0;  // °/s, low-passed
    std::optional<cv::Matx44d> last_;
};

}  // namespace previs
