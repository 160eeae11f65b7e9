#pragma once

// The speed ⇄ accuracy dial: the settings a preview frame can be rendered with, their measured
// cost and error, the Pareto front among them, and the point one setting — a target frame rate
// — selects. measureDial times each point on the scene itself and scores it against a reference
// (bench/bench_trade.cpp: a converged one; the service: a short one, which adds the same noise
// to every point's expected squared error and so leaves their order as it is).

#include <cstdint>
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
    bool denoise = false;
    std::string describe() const;
};

struct DialMeasurement {
    DialPoint point;
    double frameSeconds = 0.0;  // median wall time of a frame on this scene and device
    double error = 0.0;         // e.g. RMSE of one frame against the converged image
};

// The grid of points the dial chooses among: each scale × samples × depth (× denoising when
// `withDenoise`).
std::vector<DialPoint> dialGrid(std::span<const float> scales, std::span<const uint32_t> samples,
                                std::span<const uint32_t> depths, bool withDenoise);

// Indices of the measurements no other one dominates (as fast or faster and as accurate or
// more, strictly better in one), ordered by time.
std::vector<size_t> paretoFront(std::span<const DialMeasurement> measurements);

// The most accurate measurement whose frame fits in 1/targetFps; nothing when none does. It is
// on the Pareto front by construction: anything that dominated it would also fit and be more
// accurate.
std::optional<size_t> chooseForFrameRate(std::span<const DialMeasurement> measurements,
                                         double targetFps);

// The grid neighbours of measurement `chosen`: points one step away along one axis (scale,
// samples, depth or denoising) — what the bench shows to prove the choice is not dominated.
std::vector<size_t> gridNeighbours(std::span<const DialMeasurement> measurements, size_t chosen,
                                   std::span<const float> scales, std::span<const uint32_t> samples,
                                   std::span<const uint32_t> depths);

class Renderer;

// Measures every point of `grid` on `renderer` (its scene, plate, pose and lighting as they
// are): the median wall time of `reps` preview frames (render, read back, upsample, composite)
// and the RMSE of the last one against `reference` (the output's size). Leaves the renderer at
// the last point's settings.
Result<std::vector<DialMeasurement>> measureDial(Renderer& renderer,
                                                 std::span<const DialPoint> grid,
                                                 const ImageF& reference, int reps);

}  // namespace previs
