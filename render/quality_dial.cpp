#include "render/quality_dial.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "render/renderer.h"

namespace previs {

std::string DialPoint::describe() const {
    return fmt::format("scale 1/{:.3g}, {} spp, depth {}{}", 1.0 / resolutionScale, samplesPerFrame,
                       maxDepth, denoise ? ", denoised" : "");
}

std::vector<DialPoint> dialGrid(std::span<const float> scales, std::span<const uint32_t> samples,
                                std::span<const uint32_t> depths, bool withDenoise) {
    std::vector<DialPoint> grid;
    for (float s : scales)
        for (uint32_t n : samples)
            for (uint32_t d : depths)
                for (int denoise = 0; denoise <= int(withDenoise); ++denoise)
                    grid.push_back({s, n, d, denoise == 1});
    return grid;
}

namespace {

bool dominates(const DialMeasurement& a, const DialMeasurement& b) {
    return a.frameSeconds <= b.frameSeconds && a.error <= b.error &&
           (a.frameSeconds < b.frameSeconds || a.error < b.error);
}

bool valid(const DialMeasurement& m) {
    return std::isfinite(m.frameSeconds) && std::isfinite(m.error) && m.frameSeconds > 0.0 &&
           m.error >= 0.0;
}

}  // namespace

std::vector<size_t> paretoFront(std::span<const DialMeasurement> measurements) {
    std::vector<size_t> front;
    for (size_t i = 0; i < measurements.size(); ++i) {
        if (!valid(measurements[i])) continue;
        bool dominated = false;
        for (size_t j = 0; j < measurements.size() && !dominated; ++j)
            dominated =
                j != i && valid(measurements[j]) && dominates(measurements[j], measurements[i]);
        if (!dominated) front.push_back(i);
    }
    std::sort(front.begin(), front.end(), [&](size_t a, size_t b) {
        return measurements[a].frameSeconds < measurements[b].frameSeconds;
    });
    return front;
}

std::optional<size_t> chooseForFrameRate(std::span<const DialMeasurement> measurements,
                                         double targetFps) {
    if (!(targetFps > 0.0)) return std::nullopt;
    const double budget = 1.0 / targetFps;
    std::optional<size_t> best;
    for (size_t i = 0; i < measurements.size(); ++i) {
        const DialMeasurement& m = measurements[i];
        if (!valid(m) || m.frameSeconds > budget) continue;
        // Ties in error go to the faster point, so the choice is never dominated.
        if (!best || m.error < measurements[*best].error ||
            (m.error == measurements[*best].error &&
             m.frameSeconds < measurements[*best].frameSeconds))
            best = i;
    }
    return best;
}

std::vector<size_t> gridNeighbours(std::span<const DialMeasurement> measurements, size_t chosen,
                                   std::span<const float> scales, std::span<const uint32_t> samples,
                                   std::span<const uint32_t> depths) {
    auto indexIn = [](auto values, auto v) {
        return std::find(values.begin(), values.end(), v) - values.begin();
    };
    const DialPoint& c = measurements[chosen].point;
    std::vector<size_t> out;
    for (size_t i = 0; i < measurements.size(); ++i) {
        const DialPoint& p = measurements[i].point;
        const long ds = std::labs(
            long(indexIn(scales, p.resolutionScale) - indexIn(scales, c.resolutionScale)));
        const long dn = std::labs(
            long(indexIn(samples, p.samplesPerFrame) - indexIn(samples, c.samplesPerFrame)));
        const long dd = std::labs(long(indexIn(depths, p.maxDepth) - indexIn(depths, c.maxDepth)));
        const long dz = p.denoise != c.denoise;
        if (ds + dn + dd + dz == 1) out.push_back(i);
    }
    return out;
}

Result<std::vector<DialMeasurement>> measureDial(Renderer& renderer,
                                                 std::span<const DialPoint> grid,
                                                 const ImageF& reference, int reps) {
    using Clock = std::chrono::steady_clock;
    std::vector<DialMeasurement> out;
    for (const DialPoint& p : grid) {
        renderer.setMaxDepth(p.maxDepth);
        if (Status s = renderer.setResolutionScale(p.resolutionScale); !s) return s.error();
        // A first frame unmeasured: it may allocate (a new traced size) or size dispatches.
        if (Status s = renderer.renderPreviewFrame(p.samplesPerFrame); !s) return s.error();
        std::vector<double> times;
        std::optional<ImageF> frame;
        for (int i = 0; i < std::max(1, reps); ++i) {
            const auto start = Clock::now();
            if (Status s = renderer.renderPreviewFrame(p.samplesPerFrame); !s) return s.error();
            auto image = renderer.image(Aov::Composite);
            if (!image) return image.error();
            times.push_back(std::chrono::duration<double>(Clock::now() - start).count());
            frame = std::move(*image);
        }
        if (frame->pixels.size() != reference.pixels.size())
            return makeError("the dial's reference is {}x{}; the frames are {}x{}", reference.width,
                             reference.height, frame->width, frame->height);
        double squares = 0.0;
        for (size_t i = 0; i < frame->pixels.size(); ++i) {
            const double d = double(frame->pixels[i]) - reference.pixels[i];
            squares += d * d;
        }
        std::sort(times.begin(), times.end());
        const size_t n = times.size();
        const double median = n % 2 ? times[n / 2] : 0.5 * (times[n / 2 - 1] + times[n / 2]);
        out.push_back({p, median, std::sqrt(squares / double(frame->pixels.size()))});
    }
    return out;
}

}  // namespace previs
