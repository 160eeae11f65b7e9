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
#include <glm/glm.hpp>
#include <optional>
#include <span>

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

// Seconds until `target` at `secondsPerSample` (per sample per pixel), 0 once reached; nothing
// without an estimate or a measured rate.
std::optional<double> etaSeconds(std::optional<double> noise, uint64_t samples, double target,
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

}  // namespace previs
