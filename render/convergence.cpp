#include "render/convergence.h"

#include <algorithm>
#include <cmath>

namespace previs {

NoiseEstimate estimateNoise(std::span<const MeterPixel> pixels) {
    NoiseEstimate out;
    double total = 0.0;
    for (const MeterPixel& p : pixels) {
        const double nB = p.halfCount;
        const double nA = p.count - nB;
        // A pixel needs a sample in each replicate to say anything about its error.
        if (!(nA > 0.0 && nB > 0.0)) continue;
        const glm::dvec3 mean = p.sum / p.count;
        const glm::dvec3 a = (p.sum - p.halfSum) / nA;
        const glm::dvec3 b = p.halfSum / nB;
        const double scale = nA * nB / (p.count * p.count);
        double term = 0.0;
        for (int c = 0; c < 3; ++c) {
            const double d = a[c] - b[c];
            term += d * d * scale / (mean[c] * mean[c] + kRelMseOffset);
        }
        // Sums read back from the GPU are finite (non-finite samples are dropped there); a pixel
        // that is not, say from a hand-made buffer, says nothing rather than poisoning the mean.
        if (!std::isfinite(term)) continue;
        total += term;
        ++out.pixelsMeasured;
    }
    if (out.pixelsMeasured > 0)
        out.relativeRmse = std::sqrt(total / (3.0 * double(out.pixelsMeasured)));
    return out;
}

uint64_t samplesForNoise(double noise, uint64_t samples, double target) {
    if (!std::isfinite(noise)) return kMaxPredictedSamples;
    if (noise <= target) return samples;
    if (!(target > 0.0)) return kMaxPredictedSamples;
    const double needed =
        std::ceil(double(std::max<uint64_t>(samples, 1)) * (noise / target) * (noise / target));
    return needed >= double(kMaxPredictedSamples) ? kMaxPredictedSamples
                                                  : std::max(samples, uint64_t(needed));
}

std::optional<double> secondsToStop(uint64_t samples, std::optional<double> noise,
                                    double targetNoise, uint64_t maxSamples,
                                    double secondsPerSample) {
    if (maxSamples > 0 && samples >= maxSamples) return 0.0;
    // A pixel's estimate needs samples; a broken one (NaN, infinite, negative) is none.
    const bool haveNoise = samples > 0 && noise && std::isfinite(*noise) && *noise >= 0.0;
    const bool haveTarget = std::isfinite(targetNoise) && targetNoise > 0.0;
    if (haveTarget && haveNoise && *noise <= targetNoise) return 0.0;
    if (!std::isfinite(secondsPerSample) || secondsPerSample <= 0.0) return std::nullopt;
    // Where it stops, as a double: the model's count may be astronomically many.
    double stopAt = maxSamples > 0 ? double(maxSamples) : HUGE_VAL;
    if (haveTarget && haveNoise) {
        const double ratio = *noise / targetNoise;
        stopAt = std::min(stopAt, double(samples) * ratio * ratio);
    }
    if (!std::isfinite(stopAt)) return std::nullopt;
    const double seconds = std::max(0.0, stopAt - double(samples)) * secondsPerSample;
    return std::isfinite(seconds) ? std::optional<double>(seconds) : std::nullopt;
}

void NoiseSchedule::looked(uint64_t samples, std::optional<double> noise) {
    noise_ = noise;
    uint64_t next = std::max(samples + 1, samples * 3 / 2);
    if (target_ > 0.0 && noise)
        next = std::min(next, std::max(samples + 1, samplesForNoise(*noise, samples, target_)));
    next_ = next + next % 2;
}

StoppingRule::StoppingRule(double targetNoise, uint64_t maxSamples)
    : target_(std::isfinite(targetNoise) && targetNoise > 0.0 ? targetNoise : 0.0),
      max_(maxSamples),
      schedule_(target_) {}

void StoppingRule::restart() {
    schedule_ = NoiseSchedule(target_);
    lookSamples_ = 0;
}

void StoppingRule::setLimits(double targetNoise, uint64_t maxSamples) {
    target_ = std::isfinite(targetNoise) && targetNoise > 0.0 ? targetNoise : 0.0;
    max_ = maxSamples;
}

void StoppingRule::looked(uint64_t samples, std::optional<double> noise) {
    schedule_.looked(samples, noise);
    lookSamples_ = samples;
}

Status StoppingRule::lookIfDue(uint64_t samples,
                               const std::function<Result<std::optional<double>>()>& look) {
    if (!lookDue(samples)) return {};
    Result<std::optional<double>> noise = look();
    if (!noise) return noise.error();
    looked(samples, *noise);
    return {};
}

uint64_t StoppingRule::nextStop(uint64_t samples) const {
    uint64_t stop = max_ > 0 ? max_ : UINT64_MAX;
    if (target_ > 0.0) stop = std::min(stop, std::max(schedule_.nextLook(), samples + 1));
    return stop;
}

std::optional<double> StoppingRule::noiseAt(uint64_t samples) const {
    const std::optional<double> noise = measured();
    if (!noise || !std::isfinite(*noise) || lookSamples_ == 0 || samples <= lookSamples_)
        return noise;
    return *noise * std::sqrt(double(lookSamples_) / double(samples));
}

bool StoppingRule::reachedTarget() const {
    const std::optional<double> noise = measured();
    return lookSamples_ > 0 && target_ > 0.0 && noise && std::isfinite(*noise) && *noise >= 0.0 &&
           *noise <= target_;
}

bool StoppingRule::done(uint64_t samples) const {
    return (max_ > 0 && samples >= max_) || reachedTarget();
}

std::optional<double> StoppingRule::eta(uint64_t samples, double secondsPerSample) const {
    return secondsToStop(samples, noiseAt(samples), target_, max_, secondsPerSample);
}

}  // namespace previs
