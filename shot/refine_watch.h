#pragma once

// When a refinement starts over (issue 10; when it stops is render/convergence.h's StoppingRule).
// Refinement freezes a shot — frame, pose, lighting — and accumulates samples; a crew that moves
// the camera or changes the lights wants the accumulation to follow, while sensor noise on the
// tracked pose or on the fisheye must never throw samples away. RefineWatch compares every new
// observation with the frozen one against [refine]'s thresholds and asks for a restart only once a
// change has been seen in `restart_after` consecutive observations, so a single tracking outlier
// does not restart. The service's render loop and `previs replay` use the same object, so the
// recorded tests (tests/daemon/) check the very rule the box runs.

#include <array>
#include <cstdint>
#include <functional>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>

#include "base/result.h"
#include "config/service_config.h"
#include "shot/pipeline_stages.h"

namespace previs {

// How far apart two lighting snapshots are.
struct LightingDelta {
    // ‖sh(a) − sh(b)‖ / ‖sh(b)‖ over LiveLighting::luminanceSh: by Parseval, the relative L2
    // change on the sphere of the lighting's low-frequency part (what a diffuse surface sees).
    // 0.1 = 10 % brighter, or a turn that moves that much of it; the refinement threshold.
    double change = 0.0;
    double powerChange = 0.0;  // relative change of the total power (for the log line)
    // How far the dominant direction (band 1, ∝ ∫ L ω dω) turned, degrees; NaN when either
    // snapshot has too little band-1 energy for a direction to mean anything.
    double directionDeg = 0.0;
};
// `from` is the frozen snapshot: changes are relative to it.
LightingDelta lightingDelta(const LiveLighting& to, const LiveLighting& from);

class RefineWatch {
public:
    explicit RefineWatch(const RefineConfig& config = {}) : config_(config) {}
    // New thresholds (SIGHUP); a change already being confirmed keeps its count.
    void setConfig(const RefineConfig& config) { config_ = config; }

    // The shot froze on `frame` with `lighting` (null: the scene's own). Forgets the pending
    // counts.
    void freeze(const TrackedFrame& frame, const std::shared_ptr<const LiveLighting>& lighting);

    // A tracked frame seen while refining: why refinement must restart on it, if it must. A
    // frame without a trusted pose is no evidence either way (it neither counts nor resets).
    std::optional<std::string> observeFrame(const TrackedFrame& frame);
    // The newest lighting snapshot (may be called with the same one again: counted once).
    std::optional<std::string> observeLighting(const std::shared_ptr<const LiveLighting>& lighting);

    int pendingPose() const { return poseBeyond_; }
    int pendingLighting() const { return lightingBeyond_; }

private:
    RefineConfig config_;
    std::optional<cv::Matx44d> frozenPose_;
    std::shared_ptr<const LiveLighting> frozenLighting_, lastLighting_;
    int poseBeyond_ = 0;      // consecutive trusted poses beyond a threshold
    int lightingBeyond_ = 0;  // consecutive lighting snapshots beyond the threshold
};

}  // namespace previs
