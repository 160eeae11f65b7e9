#pragma once

// The convergence meter: how far an accumulating image is from its converged value, from the
// image alone.
//
// The path tracer interleaves two independently randomised sample sequences per pixel
// (replicates; gpu/shaders/shared/sampler.h) and keeps the second one's sums apart. With means
// A and B of nA and nB samples, the image is (nA·A + nB·B)/n, and since A and B are independent
// unbiased estimates of the same value, E[(A − B)²] = Var A + Var B; scaling by nA·nB/n² turns
// it into the variance of the image's mean when each replicate's variance falls as 1/count.
// Unlike a per-sample variance, this sees what stratification gains (Sobol' converges faster
// than independent samples), because each replicate is itself a stratified estimate.
//
// One pixel's (A − B)² is a one-degree-of-freedom figure; the meter reduces it over the image to
// DESIGN §4's relMSE, mean over pixels and channels of err² / (ref² + 0.01), with the image
// itself standing in for the unknown reference, and reports its square root.

#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <optional>
#include <span>

#include "base/result.h"

namespace previs {

// relMSE's offset in the denominator (DESIGN §4): keeps black pixels from dominating.
inline constexpr double kRelMseOffset = 0.01;

// One pixel's accumulation as the meter reads it: sums over all its kept samples and over
// replicate 1's, and the counts.
struct MeterPixel {
    glm::dvec3 sum{0.0};      // Σ of the signal over the pixel's samples
    glm::dvec3 halfSum{0.0};  // Σ over replicate 1's samples
    double count = 0.0;       // samples that count
    double halfCount = 0.0;   // of which replicate 1's
};

// The estimated √relMSE of an image (DESIGN §4), or nothing while no pixel has samples in both
// replicates (fewer than 2 samples per pixel).
struct NoiseEstimate {
    std::optional<double> relativeRmse;
    uint64_t pixelsMeasured = 0;  // pixels with samples in both replicates
};

// The estimate over `pixels`. Finite for any finite input; a black or noiseless image gives 0.
NoiseEstimate estimateNoise(std::span<const MeterPixel> pixels);

// What the renderer reports: the composite (Eq. 1 with the plate, what the monitor shows) and
// the differential signal L_om − L_or (what rendering adds to the camera picture).
struct Convergence {
    NoiseEstimate composite;
    NoiseEstimate differential;
    uint64_t samplesPerPixel = 0;
};

// Samples per pixel at which the noise should reach `target`, from the estimate `noise` at
// `samples`: the Monte Carlo rate, noise ∝ 1/√samples (stratified sampling converges at least
// as fast, so this errs toward more samples). `samples` when already there; capped at
// kMaxPredictedSamples, so a target of 0 or a noise that is not finite never overflows.
uint64_t samplesForNoise(double noise, uint64_t samples, double target);
inline constexpr uint64_t kMaxPredictedSamples = uint64_t(1) << 40;

// Seconds until an accumulation stops — at `targetNoise` (relative RMSE; ≤ 0 or not finite:
// none) or at `maxSamples` per pixel (0: none), whichever comes first — from the estimate `noise`
// at `samples` and the measured `secondsPerSample` (per sample per pixel). The model is Monte
// Carlo's, noise ∝ 1/√samples, so the target needs samples·(noise/target)². 0 once stopped;
// nothing when nothing can be said (no samples and no maximum, no usable estimate and no maximum,
// no measured rate, or no stopping point at all). Never NaN or infinite. StoppingRule::eta's
// formula; the one ETA of the shot, `previs render` and render-session.
std::optional<double> secondsToStop(uint64_t samples, std::optional<double> noise,
                                    double targetNoise, uint64_t maxSamples,
                                    double secondsPerSample);

// When to consult the meter (each look reads the whole accumulation back): at sample counts
// growing by half each time — a few dozen looks over a million samples — and, aiming at a
// target, no later than where samplesForNoise says it is reached. The 1.5× steps bound the
// overshoot: Sobol' sampling can converge as fast as 1/samples, so between two looks the noise
// falls by at most that factor, and a render stopped at the first look at or under the target
// lands within 1.5× of it. Looks fall on even counts, where both replicates have as many
// samples.
class NoiseSchedule {
public:
    explicit NoiseSchedule(double target = 0.0) : target_(target) {}
    bool due(uint64_t samples) const { return samples >= next_; }
    // The sample count of the next look (a render in chunks ends one there).
    uint64_t nextLook() const { return next_; }
    // Records a look at `samples` and plans the next one.
    void looked(uint64_t samples, std::optional<double> noise);
    // The last look's estimate, and whether it reached the target (never without a target).
    std::optional<double> noise() const { return noise_; }
    bool reached() const { return target_ > 0.0 && noise_ && *noise_ <= target_; }
    double target() const { return target_; }

private:
    double target_;
    uint64_t next_ = 2;
    std::optional<double> noise_;
};

// "Refine until good enough", the one stopping rule of the shot's refinement, `previs render`'s
// loop and render-session's frames: stop at the target noise (the meter's last look at or under
// it) or at the maximum samples per pixel, whichever comes first. The meter looks at
// NoiseSchedule's counts; between looks the estimate is carried forward at the Monte Carlo rate,
// 1/√samples — conservative, as stratified sampling converges at least that fast — so a status
// line and the ETA move every step, while stopping at the target waits for a look.
class StoppingRule {
public:
    // `targetNoise`: relative RMSE (DESIGN.md §4; ≤ 0: none); `maxSamples`: per pixel (0: none).
    explicit StoppingRule(double targetNoise = 0.0, uint64_t maxSamples = 0);
    double targetNoise() const { return target_; }
    uint64_t maxSamples() const { return max_; }

    // A fresh accumulation: looks start over.
    void restart();
    // New limits for the accumulation under way (a reload): done() and eta() use them at once;
    // the looks already planned stand until restart().
    void setLimits(double targetNoise, uint64_t maxSamples);
    // Whether the meter should look at `samples` per pixel, and the count of its next look.
    bool lookDue(uint64_t samples) const { return schedule_.due(samples); }
    uint64_t nextLook() const { return schedule_.nextLook(); }
    // Records a look at `samples` (the composite's relative RMSE, if the meter could say).
    void looked(uint64_t samples, std::optional<double> noise);
    // Looks at `samples` through `look` (one readback of the accumulation) if a look is due.
    Status lookIfDue(uint64_t samples, const std::function<Result<std::optional<double>>()>& look);

    // Where a chunk of samples from `samples` should end at the latest: the maximum, and aiming at
    // a target, the next look. UINT64_MAX when neither.
    uint64_t nextStop(uint64_t samples) const;
    // The last look's estimate (measured), and that estimate carried to `samples` (≥ the look's).
    std::optional<double> measured() const { return schedule_.noise(); }
    std::optional<double> noiseAt(uint64_t samples) const;
    // Whether the last look reached the target (never without one).
    bool reachedTarget() const;
    // Whether the accumulation stops at `samples`: the maximum reached, or the target.
    bool done(uint64_t samples) const;
    // Seconds until done (secondsToStop from the carried-forward estimate).
    std::optional<double> eta(uint64_t samples, double secondsPerSample) const;

private:
    double target_;
    uint64_t max_;
    NoiseSchedule schedule_;
    uint64_t lookSamples_ = 0;
};

}  // namespace previs
