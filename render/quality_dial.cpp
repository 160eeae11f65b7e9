#include "render/quality_dial.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>

#include "render/renderer.h"

namespace previs {

std::string DialPoint::describe() const {
    std::string out = fmt::format("scale 1/{:.3g}, {} spp, depth {}", 1.0 / resolutionScale,
                                  samplesPerFrame, maxDepth);
    if (denoiseIterations > 0) out += fmt::format(", denoised ({} levels)", denoiseIterations);
    if (photons > 0) out += fmt::format(", {} photons", photons);
    return out;
}

std::vector<DialPoint> dialGrid(const DialAxes& axes) {
    const std::vector<uint32_t> none = {0};
    const std::vector<uint32_t>& levels = axes.denoiseLevels.empty() ? none : axes.denoiseLevels;
    const std::vector<uint32_t>& budgets = axes.photonBudgets.empty() ? none : axes.photonBudgets;
    std::vector<DialPoint> grid;
    for (float s : axes.scales)
        for (uint32_t n : axes.samples)
            for (uint32_t d : axes.depths)
                for (uint32_t z : levels)
                    for (uint32_t ph : budgets) grid.push_back({s, n, d, z, ph});
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
                                         double targetFps, double slowdown) {
    if (!(targetFps > 0.0) || !(slowdown > 0.0) || !std::isfinite(slowdown)) return std::nullopt;
    const double budget = 1.0 / (targetFps * slowdown);
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

std::optional<size_t> fastest(std::span<const DialMeasurement> measurements) {
    if (measurements.empty()) return std::nullopt;
    size_t best = 0;
    for (size_t i = 1; i < measurements.size(); ++i)
        if (measurements[i].frameSeconds < measurements[best].frameSeconds) best = i;
    return best;
}

std::vector<DialMeasurement> liveCosts(std::span<const DialMeasurement> measured, double slowdown,
                                       std::span<const std::optional<DialLiveTime>> live,
                                       uint64_t window) {
    std::vector<DialMeasurement> costs(measured.begin(), measured.end());
    for (size_t i = 0; i < costs.size(); ++i) {
        costs[i].frameSeconds *= slowdown;
        if (i < live.size() && live[i] && window - live[i]->window < live[i]->memory)
            costs[i].frameSeconds = std::max(costs[i].frameSeconds, live[i]->seconds);
    }
    return costs;
}

DialLiveTime nextLiveTime(const std::optional<DialLiveTime>& before, double seconds,
                          uint64_t window, double targetFps) {
    DialLiveTime next{seconds, window, kDialLiveMemoryWindows};
    const double budget = 1.0 / targetFps;
    if (seconds <= budget || !before || before->seconds <= budget) return next;
    const bool triedAgain = window > before->window + 1;
    next.memory =
        triedAgain ? std::min(2 * before->memory, kDialLiveMemoryMaxWindows) : before->memory;
    return next;
}

bool holdKeepsRefineDepth(double heldSeconds, double heldCost, double targetFps, bool keepsNow) {
    const double budget = (keepsNow ? 1.0 : kDialUpgradeMargin) / targetFps;
    return !(heldCost > kHoldDepthWorthCost) || heldSeconds <= budget;
}

std::vector<size_t> gridNeighbours(std::span<const DialMeasurement> measurements, size_t chosen,
                                   const DialAxes& axes) {
    // Steps along an axis: a value missing from it (an axis not swept) counts as one place.
    auto step = [](const auto& values, auto a, auto b) {
        const auto ia = std::find(values.begin(), values.end(), a) - values.begin();
        const auto ib = std::find(values.begin(), values.end(), b) - values.begin();
        return std::labs(long(ia - ib));
    };
    const DialPoint& c = measurements[chosen].point;
    std::vector<size_t> out;
    for (size_t i = 0; i < measurements.size(); ++i) {
        const DialPoint& p = measurements[i].point;
        const long steps = step(axes.scales, p.resolutionScale, c.resolutionScale) +
                           step(axes.samples, p.samplesPerFrame, c.samplesPerFrame) +
                           step(axes.depths, p.maxDepth, c.maxDepth) +
                           step(axes.denoiseLevels, p.denoiseIterations, c.denoiseIterations) +
                           step(axes.photonBudgets, p.photons, c.photons);
        if (steps == 1) out.push_back(i);
    }
    return out;
}

namespace {

// Whether `a` costs at most what `b` does on every axis (a smaller scale traces fewer pixels).
bool costsNoMore(const DialPoint& a, const DialPoint& b) {
    return a.resolutionScale <= b.resolutionScale && a.samplesPerFrame <= b.samplesPerFrame &&
           a.maxDepth <= b.maxDepth && a.denoiseIterations <= b.denoiseIterations &&
           a.photons <= b.photons;
}

double tracedSamples(const DialPoint& p) {
    return double(p.resolutionScale) * p.resolutionScale * p.samplesPerFrame;
}

}  // namespace

bool cannotFit(std::span<const DialMeasurement> measured, const DialPoint& p,
               double budgetSeconds) {
    return std::any_of(measured.begin(), measured.end(), [&](const DialMeasurement& m) {
        return m.frameSeconds > budgetSeconds * kDialPruneMargin && costsNoMore(m.point, p);
    });
}

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) {
    return std::chrono::duration<double>(Clock::now() - start).count();
}

// Sets the renderer to point `p`.
Status usePoint(Renderer& renderer, const DialPoint& p) {
    renderer.setMaxDepth(p.maxDepth);
    if (Status s = renderer.setResolutionScale(p.resolutionScale); !s) return s;
    if (p.denoiseIterations > 0)
        if (Status s = renderer.setDenoiseIterations(p.denoiseIterations); !s) return s;
    if (p.photons > 0) {
        if (!renderer.photonsActive())
            return makeError("the dial point '{}' needs the photon pass, which is off",
                             p.describe());
        if (Status s = renderer.setPreviewPhotons(p.photons); !s) return s;
    }
    return {};
}

// The pan's pose `stepsLeft` steps of motion.panStepRad short of `end`.
glm::dmat4 panPose(const glm::dmat4& end, const DialMotion& motion, uint32_t stepsLeft) {
    return end *
           glm::rotate(glm::dmat4(1.0), motion.panStepRad * double(stepsLeft), glm::dvec3(0, 1, 0));
}

// One timed preview frame as the monitor gets it: traced, finished on the device (Film::display:
// the filter, the upsampling, the held view, Eq. 1, the tone curve) and read back as 8 bits;
// what the live service re-times the dial on (ShotController::previewShown). The float image
// the dial scores is a host readback the monitor never waits for, so it is not timed.
Status timedFrame(Renderer& renderer, const DialPoint& p, uint64_t sequence, bool filtered,
                  std::vector<double>& times) {
    const Clock::time_point start = Clock::now();
    if (Status s = renderer.renderPreviewFrame(p.samplesPerFrame, sequence); !s) return s;
    if (Result<DisplayImage> shown = renderer.display(filtered, DisplaySettings{}); !shown)
        return shown.error();
    times.push_back(secondsSince(start));
    return {};
}

// A still camera's frames: the times of `reps` after one untimed; the last frame is scored.
Result<ImageF> stillFrames(Renderer& renderer, const DialPoint& p, int reps,
                           std::vector<double>& times) {
    const bool filtered = p.denoiseIterations > 0;
    // A first frame unmeasured, shown too: it may allocate (a new traced size, the display pass,
    // the denoiser at that size) or size dispatches.
    std::vector<double> first;
    if (Status s = timedFrame(renderer, p, 0, filtered, first); !s) return s.error();
    for (int i = 0; i < std::max(1, reps); ++i)
        if (Status s = timedFrame(renderer, p, 0, filtered, times); !s) return s.error();
    return renderer.image(Aov::Composite, filtered);
}

// A pan's frames (DialMotion), `times` empty on entry: the times of all but the first and the
// last; the last is scored (its image runs the temporal stage once, as a shown frame's does).
Result<ImageF> panFrames(Renderer& renderer, const DialPoint& p, const DialMotion& motion,
                         std::vector<double>& times) {
    const glm::dmat4 end = renderer.denoiseCamera().worldFromCamera;
    const bool filtered = p.denoiseIterations > 0 || motion.accumulate;
    if (Denoiser* d = renderer.film().denoiser()) d->resetHistory();
    renderer.film().setTemporalDenoise(motion.accumulate);
    const uint32_t frames = std::max(3u, motion.frames);
    for (uint32_t i = 0; i + 1 < frames; ++i) {
        renderer.setCameraPose(panPose(end, motion, frames - 1 - i));
        const uint64_t sequence = motion.accumulate ? i + 1 : 0;
        if (Status s = timedFrame(renderer, p, sequence, filtered, times); !s) return s.error();
    }
    times.erase(times.begin());  // the first frame may allocate
    renderer.setCameraPose(end);
    if (Status s = renderer.renderPreviewFrame(p.samplesPerFrame, motion.accumulate ? frames : 0);
        !s)
        return s.error();
    Result<ImageF> frame = renderer.image(Aov::Composite, filtered);
    renderer.film().setTemporalDenoise(false);
    if (Denoiser* d = renderer.film().denoiser()) d->resetHistory();
    return frame;
}

}  // namespace

Result<std::vector<DialMeasurement>> measureDial(
    Renderer& renderer, std::span<const DialPoint> grid, const ImageF& reference, int reps,
    std::optional<double> budgetSeconds, const DialMotion& motion, const DialProgress& progress) {
    auto done = [&progress, total = grid.size()](size_t n) {
        if (progress) progress(n, total);
    };
    done(0);
    std::vector<DialPoint> order(grid.begin(), grid.end());
    if (budgetSeconds)
        std::stable_sort(order.begin(), order.end(), [](const DialPoint& a, const DialPoint& b) {
            return tracedSamples(a) < tracedSamples(b);
        });
    std::vector<DialMeasurement> out;
    for (size_t k = 0; k < order.size(); ++k) {
        const DialPoint& p = order[k];
        if (budgetSeconds && cannotFit(out, p, *budgetSeconds)) {
            done(k + 1);
            continue;
        }
        if (Status s = usePoint(renderer, p); !s) return s.error();
        std::vector<double> times;
        Result<ImageF> frame = motion.panStepRad != 0.0 ? panFrames(renderer, p, motion, times)
                                                        : stillFrames(renderer, p, reps, times);
        if (!frame) return frame.error();
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
        done(k + 1);
    }
    return out;
}

}  // namespace previs
