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

std::optional<double> etaSeconds(std::optional<double> noise, uint64_t samples, double target,
                                 double secondsPerSample) {
    if (!noise || !(secondsPerSample > 0.0) || !std::isfinite(secondsPerSample))
        return std::nullopt;
    if (*noise <= target) return 0.0;
    const uint64_t needed = samplesForNoise(*noise, samples, target);
    return double(needed - samples) * secondsPerSample;
}

void NoiseSchedule::looked(uint64_t samples, std::optional<double> noise) {
    noise_ = noise;
    uint64_t next = std::max(samples + 1, samples * 3 / 2);
    if (target_ > 0.0 && noise)
        next = std::min(next, std::max(samples + 1, samplesForNoise(*noise, samples, target_)));
    next_ = next + next % 2;
}

}  // namespace previs
