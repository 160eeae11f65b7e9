#pragma once

// The plate-consistency meter (DESIGN.md §4): with a trusted pose, the real-only render L_or
// should explain the plate L_oc over the real surfaces the camera sees. Per channel, the median of
// L_or / plate over those surfaces is 1 when the captured lighting is right; a fisheye that clips
// the lamps gives a render far too dim (the demo's 0.08). A crew reads it before the shoot.
//
// Pure functions on host images, so the rule is tested on analytic input
// (tests/render/plate_consistency_test.cpp); the service takes the inputs from the renderer's
// accumulation (Renderer::realSurfaceMeans) and its plate (shot/pipeline_renderer.h).

#include <array>
#include <cstddef>
#include <cstdint>
#include <glm/glm.hpp>
#include <limits>
#include <optional>
#include <vector>

#include "image/image.h"

namespace previs {

// The range a right lighting keeps the ratio in (the issue's): outside it the status warns.
constexpr double kPlateConsistencyLow = 0.8;
constexpr double kPlateConsistencyHigh = 1.25;
// Meter cells needed for a reading: the median of n cells whose ratios scatter by σ is known to
// about 1.25·σ/√n, so 32 cells of 25 % scatter give ±6 %; fewer say nothing worth showing.
constexpr size_t kPlateMeterMinPixels = 32;
// The meter's grid: at most this many cells across the picture (rows in proportion; 16×16 output
// pixels a cell at 640×360), fewer where a cell would hold under kPlateMeterCellSamples samples.
constexpr uint32_t kPlateMeterGridWidth = 40;
// Samples of L_or a cell should average before its ratio is taken. A few samples' mean is skewed
// (most paths miss the small bright lights, a few find them), so the median of such cells reads
// low: on the demo's first take (clipped lamps) at 1 spp per pixel the per-pixel median was 0.05
// where 4096-sample cells read 0.08, 64-sample cells read 5 % low, 256-sample ones 2–6 %.
constexpr double kPlateMeterCellSamples = 256.0;

// The grid width for a trace `tracedWidth` pixels wide at `samplesPerPixel`: square cells of
// at least kPlateMeterCellSamples samples, at most kPlateMeterGridWidth across, at least 1.
uint32_t plateMeterGridWidth(uint32_t tracedWidth, uint64_t samplesPerPixel);

// Plate values the meter trusts, per channel, in the plate's linear units. Below `dark` the 8-bit
// code's quantisation step and the sensor's noise are a large part of the value (code 16: a step
// is 6 % of it); at or above `clipped` the sensor saturated, so the scene's radiance there is only
// bounded below and any ratio against it would read too high (a lamp, a window).
struct PlateLimits {
    std::array<float, 3> dark{0.0f, 0.0f, 0.0f};
    std::array<float, 3> clipped{std::numeric_limits<float>::infinity(),
                                 std::numeric_limits<float>::infinity(),
                                 std::numeric_limits<float>::infinity()};
};

// The meter's low-resolution view of one frame, row-major: per cell the mean of L_or, the mean of
// the linearised plate, and whether the cell shows real surface only (plateMeterGrid says when).
struct PlateMeterGrid {
    uint32_t width = 0;
    uint32_t height = 0;
    std::vector<glm::vec3> real;
    std::vector<glm::vec3> plate;
    std::vector<uint8_t> realSurface;
};

struct PlateConsistency {
    // Per channel (RGB): the median over the cells that count of L_or / plate; 1 when the
    // lighting explains the plate, below 1 when the render is too dim.
    std::array<double, 3> ratio{};
    // Per channel: half the 16–84 % range of ln(L_or / plate) over those cells (about the
    // ratio's relative scatter: 0.05 ≈ ±5 %). Large when the lighting's shape is wrong (one side
    // of the set too bright, the other too dim) even where the median is 1.
    std::array<double, 3> spread{};
    uint64_t pixels = 0;  // cells that counted
    uint32_t gridWidth = 0;
    uint32_t gridHeight = 0;
    // Every channel's ratio within [kPlateConsistencyLow, kPlateConsistencyHigh].
    bool ok = false;
};

// A reading as the service keeps and reports it: the frame it was taken on.
struct PlateConsistencyReading {
    PlateConsistency value;
    uint64_t frame = 0;        // the scene camera frame's sequence
    uint64_t timestampNs = 0;  // its capture timestamp (Frame::timestampNs)
};

// The meter over a grid: the cells that count are those with realSurface set, L_or finite and
// not negative, and every channel of the plate within [limits.dark, limits.clipped) — one set for
// all three channels, so the three ratios describe the same surfaces and their differences are
// the lighting's colour error. None (no reading) with fewer than `minPixels` such cells.
std::optional<PlateConsistency> measurePlateConsistency(const PlateMeterGrid& grid,
                                                        const PlateLimits& limits,
                                                        size_t minPixels = kPlateMeterMinPixels);

// The grid from the renderer's traced-size means `traced` (5 channels: L_or's RGB, the fraction
// of samples whose camera ray first hit phantom geometry, the mask M) and the linear plate at the
// output size (RGB), `gridWidth` cells across (at most the traced width). A cell shows real
// surface when every sample in it hit phantom geometry first (so neither a virtual object nor
// the environment), none of its eight neighbours holds anything else (a margin: a tracked pose
// is off by a pixel or so, a virtual object often stands where the phantom set models the real
// prop only roughly, and the mask's edge is soft), and none of its plate pixels is clipped in any
// channel (its mean would hide the clipped one).
PlateMeterGrid plateMeterGrid(const ImageF& traced, const ImageF& plate, const PlateLimits& limits,
                              uint32_t gridWidth = kPlateMeterGridWidth);

// The pixels [x0, x1) × [y0, y1) of a width × height image that cell (cx, cy) of `grid` covers:
// the same fraction of any image, traced or output.
struct PlateMeterCell {
    uint32_t x0 = 0, x1 = 0, y0 = 0, y1 = 0;
};
PlateMeterCell plateMeterCell(const PlateMeterGrid& grid, uint32_t cx, uint32_t cy, uint32_t width,
                              uint32_t height);

// The q-quantile (0 ≤ q ≤ 1) of `values` by linear interpolation between order statistics (the
// median of an even count is the mean of the middle two); reorders `values`. NaN when empty.
double quantile(std::vector<double>& values, double q);

}  // namespace previs
