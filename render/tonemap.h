#pragma once

// HDR → 8-bit display: exposure, then a global operator, then the sRGB transfer function.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "image/image.h"

namespace previs {

enum class ToneMapOperator {
    Clamp,     // linear, clipped at 1 (radiometrically faithful below 1)
    Reinhard,  // L / (1 + L) on luminance (Reinhard et al. 2002, global)
};

std::optional<ToneMapOperator> parseToneMapOperator(const std::string& name);

struct ToneMapSettings {
    float exposureStops = 0.0f;
    ToneMapOperator op = ToneMapOperator::Clamp;
};

float srgbEncode(float linear);

// RGB (3 or 4 channel) float image → interleaved RGB8 in sRGB. NaN maps to 0.
std::vector<uint8_t> toneMapToSrgb8(const ImageF& image, const ToneMapSettings& settings);

}  // namespace previs
