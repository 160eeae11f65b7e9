#include "render/plate_consistency.h"

#include <algorithm>
#include <cmath>

namespace previs {

namespace {

// A ratio of 0 (a real surface the render leaves unlit) has no logarithm; its spread counts it as
// this far below 1, which is off any scale that matters.
constexpr double kMinLogRatio = 1e-6;

}  // namespace

double quantile(std::vector<double>& values, double q) {
    if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
    const double at = std::clamp(q, 0.0, 1.0) * double(values.size() - 1);
    const size_t lo = size_t(std::floor(at));
    const size_t hi = std::min(lo + 1, values.size() - 1);
    std::nth_element(values.begin(), values.begin() + ptrdiff_t(lo), values.end());
    const double low = values[lo];
    if (hi == lo) return low;
    // The next order statistic is the smallest of those after lo.
    const double high = *std::min_element(values.begin() + ptrdiff_t(lo) + 1, values.end());
    return low + (at - double(lo)) * (high - low);
}

std::optional<PlateConsistency> measurePlateConsistency(const PlateMeterGrid& grid,
                                                        const PlateLimits& limits,
                                                        size_t minPixels) {
    const size_t cells = size_t(grid.width) * grid.height;
    if (grid.real.size() < cells || grid.plate.size() < cells || grid.realSurface.size() < cells)
        return std::nullopt;
    std::array<std::vector<double>, 3> ratios;
    for (size_t i = 0; i < cells; ++i) {
        if (!grid.realSurface[i]) continue;
        const glm::vec3 r = grid.real[i], p = grid.plate[i];
        bool usable = true;
        for (int c = 0; c < 3; ++c)
            usable = usable && std::isfinite(r[c]) && r[c] >= 0.0f && std::isfinite(p[c]) &&
                     p[c] >= limits.dark[c] && p[c] > 0.0f && p[c] < limits.clipped[c];
        if (!usable) continue;
        for (int c = 0; c < 3; ++c) ratios[c].push_back(double(r[c]) / double(p[c]));
    }
    const size_t n = ratios[0].size();
    if (n < std::max<size_t>(minPixels, 1)) return std::nullopt;
    PlateConsistency out;
    out.pixels = n;
    out.gridWidth = grid.width;
    out.gridHeight = grid.height;
    out.ok = true;
    for (int c = 0; c < 3; ++c) {
        out.ratio[c] = quantile(ratios[c], 0.5);
        std::vector<double> logs(n);
        for (size_t i = 0; i < n; ++i) logs[i] = std::log(std::max(ratios[c][i], kMinLogRatio));
        const double p16 = quantile(logs, 0.16), p84 = quantile(logs, 0.84);
        out.spread[c] = 0.5 * (p84 - p16);
        out.ok =
            out.ok && out.ratio[c] >= kPlateConsistencyLow && out.ratio[c] <= kPlateConsistencyHigh;
    }
    return out;
}

uint32_t plateMeterGridWidth(uint32_t tracedWidth, uint64_t samplesPerPixel) {
    const double edge = std::ceil(
        std::sqrt(kPlateMeterCellSamples / double(std::max<uint64_t>(samplesPerPixel, 1))));
    const uint32_t across = uint32_t(double(tracedWidth) / std::max(edge, 1.0));
    return std::clamp(across, 1u, kPlateMeterGridWidth);
}

PlateMeterCell plateMeterCell(const PlateMeterGrid& grid, uint32_t cx, uint32_t cy, uint32_t width,
                              uint32_t height) {
    return {uint32_t(uint64_t(cx) * width / grid.width),
            uint32_t(uint64_t(cx + 1) * width / grid.width),
            uint32_t(uint64_t(cy) * height / grid.height),
            uint32_t(uint64_t(cy + 1) * height / grid.height)};
}

PlateMeterGrid plateMeterGrid(const ImageF& traced, const ImageF& plate, const PlateLimits& limits,
                              uint32_t gridWidth) {
    PlateMeterGrid g;
    if (traced.channels < 5 || plate.channels < 3 || traced.width == 0 || traced.height == 0 ||
        plate.width == 0 || plate.height == 0 || gridWidth == 0)
        return g;
    g.width = std::min(gridWidth, traced.width);
    g.height = std::clamp(uint32_t(std::lround(double(g.width) * plate.height / plate.width)), 1u,
                          traced.height);
    const size_t cells = size_t(g.width) * g.height;
    g.real.assign(cells, glm::vec3(0.0f));
    g.plate.assign(cells, glm::vec3(0.0f));
    g.realSurface.assign(cells, 0);
    // Whether everything traced in a cell hit phantom geometry first (before the margin).
    std::vector<uint8_t> clean(cells, 0);
    std::vector<uint8_t> clipped(cells, 0);
    // Every sample hit phantom geometry: the fraction is a mean of 0s and 1s in float.
    constexpr float kAll = 1.0f - 1e-4f;
    for (uint32_t cy = 0; cy < g.height; ++cy) {
        for (uint32_t cx = 0; cx < g.width; ++cx) {
            const size_t cell = size_t(cy) * g.width + cx;
            // The cell's traced pixels and output pixels: the same fraction of each image.
            const auto [tx0, tx1, ty0, ty1] =
                plateMeterCell(g, cx, cy, traced.width, traced.height);
            glm::dvec3 sum(0.0);
            bool allReal = true;
            for (uint32_t y = ty0; y < ty1; ++y)
                for (uint32_t x = tx0; x < tx1; ++x) {
                    for (int c = 0; c < 3; ++c) sum[c] += traced.at(x, y, uint32_t(c));
                    allReal = allReal && traced.at(x, y, 3) >= kAll && traced.at(x, y, 4) <= 0.0f;
                }
            const double tracedCount = double(tx1 - tx0) * double(ty1 - ty0);
            g.real[cell] = glm::vec3(sum / std::max(tracedCount, 1.0));
            clean[cell] = allReal && tracedCount > 0.0;
            const auto [px0, px1, py0, py1] = plateMeterCell(g, cx, cy, plate.width, plate.height);
            glm::dvec3 plateSum(0.0);
            for (uint32_t y = py0; y < py1; ++y)
                for (uint32_t x = px0; x < px1; ++x)
                    for (int c = 0; c < 3; ++c) {
                        const float v = plate.at(x, y, uint32_t(c));
                        plateSum[c] += v;
                        if (!(v < limits.clipped[c])) clipped[cell] = 1;
                    }
            const double plateCount = double(px1 - px0) * double(py1 - py0);
            g.plate[cell] = glm::vec3(plateSum / std::max(plateCount, 1.0));
            if (plateCount == 0.0) clipped[cell] = 1;
        }
    }
    for (uint32_t cy = 0; cy < g.height; ++cy)
        for (uint32_t cx = 0; cx < g.width; ++cx) {
            const size_t cell = size_t(cy) * g.width + cx;
            bool ok = clean[cell] && !clipped[cell];
            // The margin: the picture's own edge is no boundary.
            for (int dy = -1; dy <= 1 && ok; ++dy)
                for (int dx = -1; dx <= 1 && ok; ++dx) {
                    const int64_t x = int64_t(cx) + dx, y = int64_t(cy) + dy;
                    if (x < 0 || y < 0 || x >= int64_t(g.width) || y >= int64_t(g.height)) continue;
                    ok = clean[size_t(y) * g.width + size_t(x)];
                }
            g.realSurface[cell] = ok;
        }
    return g;
}

}  // namespace previs
