#include "vision/inverse_tone_map.h"

#include <algorithm>
#include <cmath>

#include "base/log.h"
#include "base/luminance.h"

namespace previs {

namespace {

// L_w / L_d of banterleInverseCurve. The paper's form L_d − 1 + √((1 − L_d)² + 4·L_d/L_white²)
// cancels catastrophically for small L_d (two terms ≈ ±1; in float the relative error is
// ~1e-7/L_d, 1e-3 at L_d = 1e-4); multiplying by the conjugate gives
//   L_w / L_d = 2·L_max / (L_white · (√((1 − L_d)² + 4·L_d/L_white²) + 1 − L_d)),
// a sum of non-negative terms, accurate to a few ulp everywhere and finite at L_d = 0 (slope
// L_max/L_white) and L_d = 1 (ratio L_max), so colour ratios are kept without a 0/0 at black.
inline float banterleRatio(float ld, float maxRadiance, float whiteLuminance) {
    const float a = 1.0f - ld;
    const float root = std::sqrt(a * a + 4.0f * ld / (whiteLuminance * whiteLuminance));
    return 2.0f * maxRadiance / (whiteLuminance * (root + a));
}

// The camera's calibration, last: exposure and white balance.
inline void scale(float rgb[3], const InverseToneMapSettings& s, float exposureScale) {
    for (int c = 0; c < 3; ++c) rgb[c] *= exposureScale * s.whiteBalance[c];
}

// Linear display values (after the sRGB decode) → radiance.
inline void untonemap(float rgb[3], const InverseToneMapSettings& s, float exposureScale) {
    if (s.op == InverseToneMapOperator::Banterle) {
        // On luminance, colour ratios kept: rgb = rgb_d · L_w/L_d. Rec.709 weights sum to 1, so
        // L_d ≤ 1 for decoded values; the clamp only absorbs rounding.
        const float ld = std::clamp(luminance(rgb[0], rgb[1], rgb[2]), 0.0f, 1.0f);
        const float k = banterleRatio(ld, s.maxRadiance, s.whiteLuminance);
        for (int c = 0; c < 3; ++c) rgb[c] *= k;
    } else if (s.op == InverseToneMapOperator::Reinhard) {
        // Forward: rgb_d = rgb / (1 + L) with L the luminance of rgb, so L_d = L / (1 + L) and
        // rgb = rgb_d / (1 − L_d).
        float ld = luminance(rgb[0], rgb[1], rgb[2]);
        ld = std::clamp(ld, 0.0f, s.maxDisplayLuminance);
        const float k = 1.0f / (1.0f - ld);
        for (int c = 0; c < 3; ++c) rgb[c] *= k;
    }
    scale(rgb, s, exposureScale);
}

inline float sanitize(float v) { return std::isfinite(v) ? std::clamp(v, 0.0f, 1.0f) : 0.0f; }

}  // namespace

std::optional<InverseToneMapOperator> parseInverseToneMapOperator(const std::string& name) {
    // "clamp" is the forward operator's name in render/tonemap.h: its inverse is the sRGB decode.
    if (name == "srgb" || name == "clamp") return InverseToneMapOperator::Srgb;
    if (name == "reinhard") return InverseToneMapOperator::Reinhard;
    if (name == "banterle" || name == "reinhard-extended") return InverseToneMapOperator::Banterle;
    return std::nullopt;
}

float srgbDecode(float encoded) {
    if (!(encoded > 0.0f)) return 0.0f;
    if (encoded <= 0.04045f) return encoded / 12.92f;
    return std::pow((std::min(encoded, 1.0f) + 0.055f) / 1.055f, 2.4f);
}

float banterleInverseCurve(float displayLuminance, float maxRadiance, float whiteLuminance) {
    PV_DCHECK(maxRadiance > 0.0f && std::isfinite(maxRadiance));
    PV_DCHECK(whiteLuminance > 0.0f && std::isfinite(whiteLuminance));
    const float ld =
        std::isfinite(displayLuminance) ? std::clamp(displayLuminance, 0.0f, 1.0f) : 0.0f;
    return ld * banterleRatio(ld, maxRadiance, whiteLuminance);
}

std::array<float, 3> inverseToneMapRgb(const std::array<float, 3>& encoded,
                                       const InverseToneMapSettings& settings) {
    float rgb[3];
    for (int c = 0; c < 3; ++c) rgb[c] = sanitize(encoded[c]);
    if (settings.colour) {
        settings.colour->applyFloat(rgb, 1, 1, sizeof rgb);
        scale(rgb, settings, std::exp2(-settings.exposureStops));
    } else {
        for (float& v : rgb) v = srgbDecode(v);
        untonemap(rgb, settings, std::exp2(-settings.exposureStops));
    }
    return {rgb[0], rgb[1], rgb[2]};
}

ImageF inverseToneMap(const ImageF& image, const InverseToneMapSettings& settings) {
    if (!image.ldrSrgb) return image;
    ImageF out;
    out.width = image.width;
    out.height = image.height;
    out.channels = image.channels == 4 ? 4 : 3;
    out.ldrSrgb = false;
    const size_t n = size_t(image.width) * image.height;
    out.pixels.resize(n * out.channels);
    const float exposureScale = std::exp2(-settings.exposureStops);
    for (size_t i = 0; i < n; ++i) {
        const float* p = image.pixels.data() + i * image.channels;
        float rgb[3];
        for (int c = 0; c < 3; ++c) rgb[c] = sanitize(p[image.channels >= 3 ? c : 0]);
        if (settings.colour) {
            // One pixel at a time keeps this path short; it serves stills (previs envmap and
            // render), not video: frames go through inverseToneMapRgb8.
            settings.colour->applyFloat(rgb, 1, 1, sizeof rgb);
            scale(rgb, settings, exposureScale);
        } else {
            for (float& v : rgb) v = srgbDecode(v);
            untonemap(rgb, settings, exposureScale);
        }
        float* q = out.pixels.data() + i * out.channels;
        q[0] = rgb[0];
        q[1] = rgb[1];
        q[2] = rgb[2];
        if (out.channels == 4) q[3] = sanitize(p[3]);
    }
    return out;
}

namespace {

// The camera's own encoding through OpenColorIO (a table for the curve, then the gamut matrix),
// then its calibration's gains.
cv::Mat colourToLinear(const cv::Mat& rgb8, const InverseToneMapSettings& settings) {
    cv::Mat out(rgb8.size(), CV_32FC3);
    if (rgb8.empty()) return out;
    settings.colour->apply8(rgb8.ptr<uint8_t>(0), std::ptrdiff_t(rgb8.step[0]), out.ptr<float>(0),
                            std::ptrdiff_t(out.step[0]), rgb8.cols, rgb8.rows);
    const float exposureScale = std::exp2(-settings.exposureStops);
    const cv::Scalar gains(exposureScale * settings.whiteBalance[0],
                           exposureScale * settings.whiteBalance[1],
                           exposureScale * settings.whiteBalance[2]);
    if (gains != cv::Scalar(1.0, 1.0, 1.0)) cv::multiply(out, gains, out);
    return out;
}

}  // namespace

cv::Mat inverseToneMapRgb8(const cv::Mat& rgb8, const InverseToneMapSettings& settings) {
    PV_ASSERT(rgb8.type() == CV_8UC3);
    if (settings.colour) return colourToLinear(rgb8, settings);
    float table[256];
    for (int i = 0; i < 256; ++i) table[i] = srgbDecode(float(i) / 255.0f);
    const float exposureScale = std::exp2(-settings.exposureStops);
    cv::Mat out(rgb8.size(), CV_32FC3);
    for (int y = 0; y < rgb8.rows; ++y) {
        const uint8_t* in = rgb8.ptr<uint8_t>(y);
        float* o = out.ptr<float>(y);
        for (int x = 0; x < rgb8.cols; ++x) {
            float rgb[3] = {table[in[3 * x]], table[in[3 * x + 1]], table[in[3 * x + 2]]};
            untonemap(rgb, settings, exposureScale);
            o[3 * x] = rgb[0];
            o[3 * x + 1] = rgb[1];
            o[3 * x + 2] = rgb[2];
        }
    }
    return out;
}

}  // namespace previs
