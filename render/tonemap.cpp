#include "render/tonemap.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <vector>

#include "base/log.h"
#include "gpu/shaders/shared/composite.h"

namespace previs {

std::optional<ToneMapOperator> parseToneMapOperator(const std::string& name) {
    // srgb and banterle: the names of the inverse operators (vision/inverse_tone_map.h), so one
    // curve name serves both directions.
    if (name == "clamp" || name == "srgb") return ToneMapOperator::Clamp;
    if (name == "reinhard") return ToneMapOperator::Reinhard;
    if (name == "reinhard-extended" || name == "banterle") return ToneMapOperator::ReinhardExtended;
    return std::nullopt;
}

float srgbEncode(float linear) {
    if (!(linear > 0.0f)) return 0.0f;
    if (linear >= 1.0f) return 1.0f;
    return linear <= 0.0031308f ? 12.92f * linear : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
}

namespace {

static_assert(uint32_t(ToneMapOperator::Clamp) == PV_TONE_CLAMP &&
              uint32_t(ToneMapOperator::Reinhard) == PV_TONE_REINHARD &&
              uint32_t(ToneMapOperator::ReinhardExtended) == PV_TONE_REINHARD_EXTENDED);

// Exposed radiance (finite, ≥ 0) → linear display values, in place (shared/composite.h's curve, the
// one the display pass runs).
inline void tonemap(float rgb[3], const ToneMapSettings& settings) {
    if (settings.op == ToneMapOperator::Clamp) return;
    const glm::vec3 out =
        shader::toneCurve(glm::vec3(rgb[0], rgb[1], rgb[2]), uint32_t(settings.op),
                          settings.maxRadiance, settings.whiteLuminance);
    for (int c = 0; c < 3; ++c) rgb[c] = out[c];
}

}  // namespace

// The display code lround(255 · srgbEncode(v)) is a non-decreasing step function of the
// display-linear value v: thresholds[k] is the smallest float whose code is ≥ k (k = 1 … 255;
// [0] unused), found by bisection over the bit patterns of the floats in [0, 1] (ordered as
// integers). Counting the thresholds ≤ v then gives the very code srgbEncode would, without a
// pow per channel (tests/render: equal on every threshold's neighbours and 10⁶ random values).
const std::array<float, 256>& srgb8Thresholds() {
    static const std::array<float, 256> table = [] {
        auto code = [](uint32_t bits) {
            float v;
            std::memcpy(&v, &bits, sizeof(v));
            return std::lround(srgbEncode(v) * 255.0f);
        };
        uint32_t one;
        const float oneF = 1.0f;
        std::memcpy(&one, &oneF, sizeof(one));
        std::array<float, 256> t{};
        for (long k = 1; k < 256; ++k) {
            uint32_t lo = 0, hi = one;  // code(lo) < k ≤ code(hi)
            while (hi - lo > 1) {
                const uint32_t mid = lo + (hi - lo) / 2;
                (code(mid) >= k ? hi : lo) = mid;
            }
            std::memcpy(&t[k], &hi, sizeof(float));
        }
        return t;
    }();
    return table;
}

namespace {

// The code at the start of each bucket of floats sharing exponent and 8 leading mantissa bits,
// from 2⁻¹⁶ (below the first step, 1.5e-4) to 1: a bucket holds at most a step or two, so the
// code is this start plus the thresholds passed inside the bucket (exact: same table).
constexpr int kMinExponent = -16;
constexpr int kBucketShift = 15;  // 23 mantissa bits − 8
struct Srgb8Buckets {
    uint32_t firstBits;
    std::vector<uint8_t> start;
};
const Srgb8Buckets& srgb8Buckets() {
    static const Srgb8Buckets buckets = [] {
        const std::array<float, 256>& t = srgb8Thresholds();
        Srgb8Buckets b;
        const float first = std::ldexp(1.0f, kMinExponent), one = 1.0f;
        uint32_t lastBits;
        std::memcpy(&b.firstBits, &first, 4);
        std::memcpy(&lastBits, &one, 4);
        b.start.resize(((lastBits - b.firstBits) >> kBucketShift) + 1);
        for (size_t k = 0; k < b.start.size(); ++k) {
            const uint32_t bits = b.firstBits + (uint32_t(k) << kBucketShift);
            float v;
            std::memcpy(&v, &bits, 4);
            b.start[k] = uint8_t(std::upper_bound(t.begin() + 1, t.end(), v) - (t.begin() + 1));
        }
        return b;
    }();
    return buckets;
}

}  // namespace

uint8_t encodeSrgb8(float linear) {
    if (!(linear > 0.0f)) return 0;
    if (linear >= 1.0f) return 255;
    const std::array<float, 256>& t = srgb8Thresholds();
    const Srgb8Buckets& b = srgb8Buckets();
    uint32_t bits;
    std::memcpy(&bits, &linear, 4);
    if (bits < b.firstBits) return linear >= t[1] ? 1 : 0;  // t[1] is above 2⁻¹⁶: never
    uint32_t code = b.start[(bits - b.firstBits) >> kBucketShift];
    while (code < 255 && linear >= t[code + 1]) ++code;
    return uint8_t(code);
}

float reinhardExtendedCurve(float luminance, float maxRadiance, float whiteLuminance) {
    PV_DCHECK(maxRadiance > 0.0f && std::isfinite(maxRadiance));
    PV_DCHECK(whiteLuminance > 0.0f && std::isfinite(whiteLuminance));
    const float lw = std::isfinite(luminance) ? std::max(luminance, 0.0f) : 0.0f;
    return lw * shader::reinhardExtendedRatio(lw, maxRadiance, whiteLuminance);
}

std::array<float, 3> toneMapRgb(const std::array<float, 3>& radiance,
                                const ToneMapSettings& settings) {
    const float scale = std::exp2(settings.exposureStops);
    float rgb[3];
    for (int c = 0; c < 3; ++c)
        rgb[c] = std::isfinite(radiance[c]) ? std::max(radiance[c], 0.0f) * scale : 0.0f;
    tonemap(rgb, settings);
    return {srgbEncode(rgb[0]), srgbEncode(rgb[1]), srgbEncode(rgb[2])};
}

std::vector<uint8_t> toneMapToSrgb8(const ImageF& image, const ToneMapSettings& settings) {
    std::vector<uint8_t> out(size_t(image.width) * image.height * 3);
    const float scale = std::exp2(settings.exposureStops);
    for (size_t i = 0; i < size_t(image.width) * image.height; ++i) {
        // toneMapRgb up to the encode, then the 8-bit code from the threshold table.
        float rgb[3];
        for (int c = 0; c < 3; ++c) {
            const float v =
                image.pixels[i * image.channels + std::min<uint32_t>(c, image.channels - 1)];
            rgb[c] = std::isfinite(v) ? std::max(v, 0.0f) * scale : 0.0f;
        }
        tonemap(rgb, settings);
        for (int c = 0; c < 3; ++c) out[i * 3 + c] = encodeSrgb8(rgb[c]);
    }
    return out;
}

}  // namespace previs
