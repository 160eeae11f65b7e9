#pragma once

// The speed ⇄ accuracy dial: the settings a preview frame can be rendered with, their measured
// cost and error, the Pareto front among them, and the point one setting — a target frame rate
// — selects. measureDial times each point on the scene itself and scores it against a reference
// (bench/bench_trade.cpp: a converged one; the service: a short one, which adds the same noise
// to every point's expected squared error and so leaves their order as it is).

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/result.h"
#include "image/image.h"

namespace previs {

// One way to render a preview frame.
struct DialPoint {
    float resolutionScale = 1.0f;  // RenderSettings::resolutionScale
    uint32_t samplesPerFrame = 1;
    uint32_t maxDepth = 4;
    uint32_t denoiseIterations = 0;  // the denoiser's strength (à-trous levels); 0: off
    uint32_t photons = 0;            // the photon pass's budget per frame; 0: no photon pass
    std::string describe() const;
};

struct DialMeasurement {
    DialPoint point;
    double frameSeconds = 0.0;  // median wall time of a frame on this scene and device
    double error = 0.0;         // e.g. RMSE of one frame against the converged image
};

// The values each setting takes. Empty denoise levels or photon budgets: that axis is not
// swept (no denoiser; no photon pass) and its value is 0.
struct DialAxes {
    std::vector<float> scales;
    std::vector<uint32_t> samples;
    std::vector<uint32_t> depths;
    std::vector<uint32_t> denoiseLevels;  // include 0 to measure "off"
    std::vector<uint32_t> photonBudgets;
};

// Every combination of the axes' values.
std::vector<DialPoint> dialGrid(const DialAxes& axes);

// Indices of the measurements no other one dominates (as fast or faster and as accurate or
// more, strictly better in one), ordered by time.
std::vector<size_t> paretoFront(std::span<const DialMeasurement> measurements);

// The most accurate measurement whose frame fits in 1/targetFps; nothing when none does. It is
// on the Pareto front by construction: anything that dominated it would also fit and be more
// accurate.
// `slowdown` scales every measured time first: what the live service's frames took against
// what the dial measured with the machine to itself (tracking and lighting share its cores).
std::optional<size_t> chooseForFrameRate(std::span<const DialMeasurement> measurements,
                                         double targetFps, double slowdown = 1.0);

// The fastest measurement (the fallback when none fits); nothing when there are none.
std::optional<size_t> fastest(std::span<const DialMeasurement> measurements);

// A dearer point, or refinement's depth for a held camera once dropped, must fit within this
// share of the frame budget, so that the live choice does not swing back and forth.
inline constexpr double kDialUpgradeMargin = 0.85;
// A held cost up to this keeps refinement's depth however slow the frames: the point's depth
// would gain under a tenth of the rate and lose the held view's convergence toward refinement's
// picture (the demo measures about 1).
inline constexpr double kHoldDepthWorthCost = 1.1;

// How many of adaptDial's windows a point's own live time outweighs the estimate from another
// point's at first (about 8 s at 15 fps): long enough that a point found too slow is not tried
// again at every window, short enough that a passing load does not keep it out.
inline constexpr uint64_t kDialLiveMemoryWindows = 8;
// The longest it does (about a minute): a point tried again after its memory lapsed and found too
// slow again doubles it, up to this, so a lasting load costs a slow window ever more rarely and
// a load that is gone is found within a minute.
inline constexpr uint64_t kDialLiveMemoryMaxWindows = 64;

// What the live service saw one point's frames take (the median of a window), adaptDial's window
// count when it did, and for how many windows from then it outweighs the estimate.
struct DialLiveTime {
    double seconds = 0.0;
    uint64_t window = 0;
    uint64_t memory = kDialLiveMemoryWindows;
};

// A point's live time `seconds` in window `window`, after its record `before` (if any): frames
// over the budget of `targetFps` in a window that follows a gap (the point tried again after
// its memory lapsed) where they were over it before too double the memory; frames within the
// budget start it afresh.
DialLiveTime nextLiveTime(const std::optional<DialLiveTime>& before, double seconds,
                          uint64_t window, double targetFps);

// The measurements as the live dial weighs them in window `window`: every time scaled by
// `slowdown` (the point in use's live time against its measured one), and a point whose own live
// frames took longer within its memory's windows (DialLiveTime::memory) costs that. Frames do not
// slow every point alike (a dearer point's longer frames meet more of the tracking and the
// lighting beside them), so the scaled estimate alone moves the dial back to a point that just
// proved too slow, window after window. `live` is by measurement index; missing entries are
// unknown.
std::vector<DialMeasurement> liveCosts(std::span<const DialMeasurement> measured, double slowdown,
                                       std::span<const std::optional<DialLiveTime>> live,
                                       uint64_t window);

// Whether a held camera's frames, which take `heldSeconds` at refinement's depth (`heldCost`
// times the point's frames), trace that depth at `targetFps`: within the budget while they do
// (`keepsNow`), within kDialUpgradeMargin of it to come back; always where the depth costs
// under kHoldDepthWorthCost (an unknown cost, 1, included).
bool holdKeepsRefineDepth(double heldSeconds, double heldCost, double targetFps, bool keepsNow);

// The grid neighbours of measurement `chosen`: points one step away along one axis (scale,
// samples, depth, denoiser strength or photon budget) — what the bench shows to prove the
// choice is not dominated.
std::vector<size_t> gridNeighbours(std::span<const DialMeasurement> measurements, size_t chosen,
                                   const DialAxes& axes);

class Renderer;

// How measureDial moves the camera while it measures a point. Still (panStepRad 0): every frame
// from the renderer's view, with preview's fixed sequence, filtered on its own. A pan: `frames`
// preview frames, each turned by panStepRad about the camera's up axis from the one before and
// ending at the renderer's view (the reference's); with `accumulate` each frame draws new
// samples and is filtered through the denoiser's temporal reprojection (its history afresh at
// each point), as the service's accumulating preview is. The error is the last frame's: what
// reprojection keeps in motion; the time every frame's but the first (it may allocate) and the
// last (scored, not shown), so at least 3 frames. What a held camera gains later
// (render/held_view.h) is not scored.
struct DialMotion {
    double panStepRad = 0.0;
    uint32_t frames = 5;
    bool accumulate = false;
};

// Measures every point of `grid` on `renderer` (its scene, plate, pose and lighting as they
// are): the median wall time of `reps` preview frames as the monitor gets them (traced, finished
// on the device and read back as 8 bits: Renderer::display; a pan's frames but its first and
// last) and the RMSE of the last one's float composite against `reference` (the output's size,
// from the renderer's view). Points
// that denoise need a renderer created with RenderSettings::denoise; points with photons, an
// active photon pass. Leaves the renderer at the last point's settings.
//
// With a `budgetSeconds`, points that cannot fit are not rendered: every axis costs time as it
// grows (scale, samples, depth, strength, photons), so a point at or above, on every axis, one
// measured over the budget (by kDialPruneMargin, for the timing noise) is left out of the
// result. Cheap points are measured first. The bench measures all (no budget), to show the front.
//
// `progress`, when set, hears how many of the grid's points are done (measured or left out) of
// all of them: once with 0 before the first, then after each (previsd's start shows it).
inline constexpr double kDialPruneMargin = 1.25;
using DialProgress = std::function<void(size_t done, size_t total)>;
bool cannotFit(std::span<const DialMeasurement> measured, const DialPoint& p, double budgetSeconds);
Result<std::vector<DialMeasurement>> measureDial(Renderer& renderer,
                                                 std::span<const DialPoint> grid,
                                                 const ImageF& reference, int reps,
                                                 std::optional<double> budgetSeconds = {},
                                                 const DialMotion& motion = {},
                                                 const DialProgress& progress = {});

}  // namespace previs
