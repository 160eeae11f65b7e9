#include "render/upsample.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <thread>
#include <vector>

#include "base/log.h"
#include "gpu/shaders/shared/composite.h"

namespace previs {

namespace {

// The range kernel exp(−x) tabulated on x = d²/(2σ²) ∈ [0, PV_RANGE_CUT) in steps of
// 1/PV_RANGE_STEPS (shared/composite.h: the display pass rounds x alike).
constexpr int kRangeSteps = int(PV_RANGE_STEPS);
constexpr int kRangeTable = int(PV_RANGE_CUT) * kRangeSteps;

// Where the sum of range-weighted taps is this small a fraction of the spatial weights, the
// pixel's guide colour matches none of its neighbours (a detail finer than the traced grid):
// the spatial kernel alone is used rather than dividing by almost nothing.
constexpr double kMinRangeWeightFraction = 1e-4;

// The uniform cubic B-spline's four weights for a sample at fraction t ∈ [0, 1) past the second
// tap: a partition of unity that reproduces linear functions (Σ w_k·k = 1 + t over taps 0..3).
std::array<double, 4> cubicBSplineWeights(double t) {
    const double t2 = t * t, t3 = t2 * t, s = 1.0 - t;
    return {s * s * s / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
            (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0, t3 / 6.0};
}

// The four low-resolution taps of each output column (or row): the first tap's index (−1 and
// beyond the end are possible; their weights are 0) and the weights.
struct Taps {
    std::vector<int> first;
    std::vector<std::array<double, 4>> weights;
};

Taps makeTaps(uint32_t full, uint32_t low) {
    Taps taps;
    taps.first.resize(full);
    taps.weights.resize(full);
    const double scale = double(low) / double(full);
    for (uint32_t x = 0; x < full; ++x) {
        // The output pixel centre on the low grid, whose pixel centres are at integers.
        const double u = (double(x) + 0.5) * scale - 0.5;
        const double base = std::floor(u);
        const int i1 = int(base);
        std::array<double, 4> w = cubicBSplineWeights(u - base);
        for (int k = 0; k < 4; ++k) {
            const int i = i1 - 1 + k;
            if (i < 0 || i >= int(low)) w[k] = 0.0;
        }
        taps.first[x] = i1 - 1;
        taps.weights[x] = w;
    }
    return taps;
}

// Box-filter overlap of each low pixel's footprint [i·full/low, (i+1)·full/low) with the full
// pixels [x, x + 1): (x, fraction of the footprint) pairs per low pixel.
std::vector<std::vector<std::pair<uint32_t, double>>> areaWeights(uint32_t full, uint32_t low) {
    std::vector<std::vector<std::pair<uint32_t, double>>> out(low);
    const double step = double(full) / double(low);
    for (uint32_t i = 0; i < low; ++i) {
        const double a = i * step, b = (i + 1) * step;
        for (uint32_t x = uint32_t(a); x < full && double(x) < b; ++x) {
            const double overlap = std::min(b, double(x) + 1.0) - std::max(a, double(x));
            if (overlap > 0.0) out[i].push_back({x, overlap / step});
        }
    }
    return out;
}

using shader::fastLog2;

// The outline the taps around an output pixel steer to (shared/composite.h's outlineMask: −1 for
// none) from the spatial mean of the mask (channel 3 of `low`) and its extremes over the taps.
float outlineTarget(const ImageF& low, int i0, int j0, const std::array<double, 4>& wx,
                    const std::array<double, 4>& wy, float sharpness) {
    double mean = 0.0, weight = 0.0;
    float lowest = 1.0f, highest = 0.0f;
    for (int b = 0; b < 4; ++b)
        for (int a = 0; a < 4; ++a) {
            const double ws = wx[a] * wy[b];
            if (ws == 0.0) continue;
            const float m = low.pixels[(size_t(j0 + b) * low.width + size_t(i0 + a)) * 4 + 3];
            mean += ws * m;
            weight += ws;
            lowest = std::min(lowest, m);
            highest = std::max(highest, m);
        }
    return shader::outlineMask(float(mean / weight), lowest, highest, sharpness);
}

// Runs body(rowBegin, rowEnd) over [0, rows) on `threads` threads (this one included).
template <typename Body>
void forRows(uint32_t rows, uint32_t threads, Body body) {
    threads = std::clamp(threads, 1u, std::max(1u, rows / 16u));
    if (threads <= 1) {
        body(0u, rows);
        return;
    }
    std::vector<std::thread> workers;
    workers.reserve(threads - 1);
    for (uint32_t t = 1; t < threads; ++t)
        workers.emplace_back(body, rows * t / threads, rows * (t + 1) / threads);
    body(0u, rows / threads);
    for (std::thread& w : workers) w.join();
}

}  // namespace

OutlineKernel outlineKernel(const UpsampleSettings& settings, uint32_t width, uint32_t height,
                            uint32_t traceWidth, uint32_t traceHeight) {
    if (!(settings.outlineSharpening > 0.0f) || !(settings.maskRangeSigma > 0.0f) ||
        traceWidth == 0 || traceHeight == 0 || (traceWidth >= width && traceHeight >= height))
        return {};
    // The traced pixel's size in output pixels, the larger of the two directions.
    const float footprint =
        std::max(float(width) / float(traceWidth), float(height) / float(traceHeight));
    return {.sharpness = settings.outlineSharpening * footprint,
            .rangeScale = 1.0f / (2.0f * settings.maskRangeSigma * settings.maskRangeSigma)};
}

namespace {

// Which output pixels have any non-zero neighbour, per low pixel: a low pixel's 4 × 4
// neighbourhood (taps i1 − 1 … i1 + 2, stored at index i1 + 1) dilated separably, on a
// (w + 1) × (h + 1) grid. Elsewhere the output stays exactly 0 without any work: most of a
// preview frame is plate alone.
std::vector<uint8_t> nonZeroNeighbourhoods(const ImageF& low) {
    const uint32_t w = low.width, h = low.height, nc = low.channels;
    std::vector<uint8_t> nonZero(size_t(w) * h, 0);
    for (size_t i = 0; i < nonZero.size(); ++i)
        for (uint32_t c = 0; c < nc; ++c)
            if (low.pixels[i * nc + c] != 0.0f) nonZero[i] = 1;
    std::vector<uint8_t> dilatedX(size_t(w + 1) * h, 0), needs(size_t(w + 1) * (h + 1), 0);
    for (uint32_t j = 0; j < h; ++j)
        for (int i1 = -1; i1 < int(w); ++i1) {
            uint8_t any = 0;
            for (int i = std::max(i1 - 1, 0); i <= std::min(i1 + 2, int(w) - 1); ++i)
                any |= nonZero[size_t(j) * w + i];
            dilatedX[size_t(j) * (w + 1) + (i1 + 1)] = any;
        }
    for (int j1 = -1; j1 < int(h); ++j1)
        for (uint32_t i = 0; i <= w; ++i) {
            uint8_t any = 0;
            for (int j = std::max(j1 - 1, 0); j <= std::min(j1 + 2, int(h) - 1); ++j)
                any |= dilatedX[size_t(j) * (w + 1) + i];
            needs[size_t(j1 + 1) * (w + 1) + i] = any;
        }
    return needs;
}

// The guide on the low grid: the log2 of the guide's area mean over each low pixel's
// footprint, and the epsilon added before every log (a fraction of the mean brightness).
struct LowGuide {
    std::vector<float> logMean;  // 3 per low pixel
    float epsilon = 0.0f;
};

LowGuide lowResolutionGuide(const ImageF& guide, uint32_t w, uint32_t h, float logEpsilonFraction) {
    const uint32_t width = guide.width, height = guide.height, gc = guide.channels;
    const auto ax = areaWeights(width, w), ay = areaWeights(height, h);
    std::vector<double> rowMean(size_t(w) * height * 3, 0.0);
    for (uint32_t y = 0; y < height; ++y)
        for (uint32_t i = 0; i < w; ++i)
            for (auto [x, f] : ax[i])
                for (int c = 0; c < 3; ++c)
                    rowMean[(size_t(y) * w + i) * 3 + c] +=
                        f * double(guide.pixels[(size_t(y) * width + x) * gc + c]);
    std::vector<double> mean(size_t(w) * h * 3, 0.0);
    double total = 0.0;
    for (uint32_t j = 0; j < h; ++j)
        for (uint32_t i = 0; i < w; ++i)
            for (int c = 0; c < 3; ++c) {
                double v = 0.0;
                for (auto [y, f] : ay[j]) v += f * rowMean[(size_t(y) * w + i) * 3 + c];
                mean[(size_t(j) * w + i) * 3 + c] = v;
                total += v;
            }
    LowGuide out;
    out.epsilon = std::max(float(logEpsilonFraction * total / double(mean.size())), 1e-12f);
    out.logMean.resize(mean.size());
    for (size_t k = 0; k < mean.size(); ++k)
        out.logMean[k] = fastLog2(std::max(float(mean[k]), 0.0f) + out.epsilon);
    return out;
}

// Everything the per-pixel filter reads: the low image, its taps, and the range kernel (guide
// colour and outline mask distances, both as steps into the tabulated exp(−x)).
struct BilateralFilter {
    const ImageF& low;
    const ImageF* guide;  // null: no colour range term
    Taps cols, rows;
    LowGuide lowGuide{};
    OutlineKernel outline{};
    float toTable = 0.0f;      // squared log2 colour distance → table steps
    float maskToTable = 0.0f;  // squared mask distance → table steps (0: no outline term)
    std::array<float, kRangeTable + 1> rangeTable{};

    // One output pixel (x, y) whose tap origin is (i0, j0) into `o`.
    void filterPixel(uint32_t x, uint32_t y, int i0, int j0, float* o) const;
};

void BilateralFilter::filterPixel(uint32_t x, uint32_t y, int i0, int j0, float* o) const {
    const uint32_t w = low.width, nc = low.channels;
    const std::array<double, 4>& wx = cols.weights[x];
    const std::array<double, 4>& wy = rows.weights[y];
    const bool ranged = guide != nullptr;
    float gp[3] = {};
    if (ranged) {
        const float* g = &guide->pixels[(size_t(y) * guide->width + x) * guide->channels];
        for (int c = 0; c < 3; ++c) gp[c] = fastLog2(std::max(g[c], 0.0f) + lowGuide.epsilon);
    }
    const float target =
        maskToTable > 0.0f ? outlineTarget(low, i0, j0, wx, wy, outline.sharpness) : -1.0f;
    // Pass 0 with the range kernel; pass 1, rarely, the spatial kernel alone.
    double acc[4] = {};
    double weight = 0.0, spatial = 0.0;
    for (int pass = 0; pass < 2; ++pass) {
        for (int b = 0; b < 4; ++b) {
            if (wy[b] == 0.0) continue;
            const size_t rowBase = size_t(j0 + b) * w;
            for (int a = 0; a < 4; ++a) {
                if (wx[a] == 0.0) continue;
                const size_t q = rowBase + size_t(i0 + a);
                const double ws = wx[a] * wy[b];
                const float* v = &low.pixels[q * nc];
                double r = 1.0;
                if ((ranged || target >= 0.0f) && pass == 0) {
                    float t = 0.0f;
                    if (ranged) {
                        const float* gq = &lowGuide.logMean[q * 3];
                        const float d0 = gp[0] - gq[0], d1 = gp[1] - gq[1], d2 = gp[2] - gq[2];
                        t = (d0 * d0 + d1 * d1 + d2 * d2) * toTable;
                    }
                    if (target >= 0.0f) {
                        const float dm = target - v[3];
                        t += dm * dm * maskToTable;
                    }
                    r = t < float(kRangeTable) ? rangeTable[int(t)] : 0.0f;
                }
                for (uint32_t c = 0; c < nc; ++c) acc[c] += ws * r * double(v[c]);
                weight += ws * r;
                spatial += ws;
            }
        }
        if (weight > kMinRangeWeightFraction * spatial) break;
        acc[0] = acc[1] = acc[2] = acc[3] = 0.0;
        weight = spatial = 0.0;
        PV_DCHECK(pass == 0);
    }
    for (uint32_t c = 0; c < nc; ++c) o[c] = float(acc[c] / weight);
}

BilateralFilter makeFilter(const ImageF& low, uint32_t width, uint32_t height, const ImageF* guide,
                           const UpsampleSettings& settings) {
    const uint32_t w = low.width, h = low.height;
    const bool ranged = guide && settings.rangeSigma > 0.0f;
    BilateralFilter f{.low = low,
                      .guide = ranged ? guide : nullptr,
                      .cols = makeTaps(width, w),
                      .rows = makeTaps(height, h)};
    if (ranged) {
        PV_ASSERT(guide->width == width && guide->height == height && guide->channels >= 3);
        f.lowGuide = lowResolutionGuide(*guide, w, h, settings.logEpsilonFraction);
        // exp(−d²/(2σ²)) with d in natural-log units; the guide is in log2 (d_ln = ln2 · d_log2).
        const float ln2 = 0.69314718f;
        f.toTable = ln2 * ln2 / (2.0f * settings.rangeSigma * settings.rangeSigma) * kRangeSteps;
    }
    f.outline = low.channels == 4 ? outlineKernel(settings, width, height, w, h) : OutlineKernel{};
    f.maskToTable = f.outline.rangeScale * kRangeSteps;
    for (int k = 0; k < kRangeTable; ++k) f.rangeTable[k] = std::exp(-float(k) / kRangeSteps);
    return f;
}

}  // namespace

ImageF jointBilateralUpsample(const ImageF& low, uint32_t width, uint32_t height,
                              const ImageF* guide, const UpsampleSettings& settings) {
    PV_ASSERT(low.width > 0 && low.height > 0 && low.channels >= 1 && low.channels <= 4);
    PV_ASSERT(low.pixels.size() == size_t(low.width) * low.height * low.channels);
    const uint32_t nc = low.channels, stride = low.width + 1;
    ImageF out;
    out.width = width;
    out.height = height;
    out.channels = nc;
    out.pixels.assign(size_t(width) * height * nc, 0.0f);
    if (width == 0 || height == 0) return out;

    const std::vector<uint8_t> needs = nonZeroNeighbourhoods(low);
    const BilateralFilter filter = makeFilter(low, width, height, guide, settings);
    const uint32_t threads =
        settings.threads ? settings.threads : std::max(1u, std::thread::hardware_concurrency());
    forRows(height, threads, [&](uint32_t y0, uint32_t y1) {
        for (uint32_t y = y0; y < y1; ++y) {
            const int j0 = filter.rows.first[y];
            const uint8_t* needRow = &needs[size_t(j0 + 2) * stride];
            for (uint32_t x = 0; x < width; ++x) {
                const int i0 = filter.cols.first[x];
                if (!needRow[i0 + 2]) continue;
                filter.filterPixel(x, y, i0, j0, &out.pixels[(size_t(y) * width + x) * nc]);
            }
        }
    });
    return out;
}

}  // namespace previs
