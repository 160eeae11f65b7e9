#include "render/tonemap.h"

#include <algorithm>
#include <cmath>

namespace previs {

std::optional<ToneMapOperator> parseToneMapOperator(const std::string& name) {
    if (name == "clamp") return ToneMapOperator::Clamp;
    if (name == "reinhard") return ToneMapOperator::Reinhard;
    return std::nullopt;
}

float srgbEncode(float linear) {
    if (!(linear > 0.0f)) return 0.0f;
    if (linear >= 1.0f) return 1.0f;
    return linear <= 0.0031308f ? 12.92f * linear : 1.055f * std::pow(linear, 1.0f / 2.4f) - 0.055f;
}

std::vector<uint8_t> toneMapToSrgb8(const ImageF& image, const ToneMapSettings& settings) {
    std::vector<uint8_t> out(size_t(image.width) * image.height * 3);
    float scale = std::exp2(settings.exposureStops);
    for (size_t i = 0; i < size_t(image.width) * image.height; ++i) {
        float rgb[3];
        for (int c = 0; c < 3; ++c) {
            float v = image.pixels[i * image.channels + std::min<uint32_t>(c, image.channels - 1)];
            rgb[c] = std::isfinite(v) ? std::max(v, 0.0f) * scale : 0.0f;
        }
        if (settings.op == ToneMapOperator::Reinhard) {
            float lum = 0.2126f * rgb[0] + 0.7152f * rgb[1] + 0.0722f * rgb[2];
            float k = lum > 0.0f ? 1.0f / (1.0f + lum) : 1.0f;
            for (float& v : rgb) v *= k;
        }
        for (int c = 0; c < 3; ++c)
            out[i * 3 + c] = static_cast<uint8_t>(std::lround(srgbEncode(rgb[c]) * 255.0f));
    }
    return out;
}

}  // namespace previs
