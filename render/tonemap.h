#pragma once

// HDR → 8-bit display: exposure, then a global operator, then the sRGB transfer function.

#include <array>
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
    // L(1 + L/L_white²)/(1 + L) on luminance, L = luminance · L_white/L_max (Reinhard et al. 2002
    // Eq. 4, scaled as in Banterle et al. 2006): L_max maps to display white, and
    // vision/inverse_tone_map.h's Banterle operator inverts it exactly.
    ReinhardExtended,
};

// "srgb" (or "clamp"), "reinhard", "banterle" (or "reinhard-extended").
std::optional<ToneMapOperator> parseToneMapOperator(const std::string& name);

struct ToneMapSettings {
    float exposureStops = 0.0f;
    ToneMapOperator op = ToneMapOperator::Clamp;
    // ReinhardExtended only (both > 0, finite), the same parameters as the inverse's: maxRadiance
    // (L_max) is the luminance after exposure that maps to display white 1; whiteLuminance is
    // L_white, the shape (> 1 compresses, 1 is linear). Equal values give slope 1 at black.
    float maxRadiance = 16.0f;
    float whiteLuminance = 16.0f;
};

float srgbEncode(float linear);
// lround(255 · srgbEncode(linear)), the 8-bit display code, without the pow (a table of the
// 255 values where the code steps): equal to it for every float.
uint8_t encodeSrgb8(float linear);

// The display code's steps: [k] is the smallest display-linear value whose 8-bit sRGB code is ≥ k
// (k = 1 … 255; [0] is 0). encodeSrgb8 and the device's display pass (render/display_pass.h)
// both count them.
const std::array<float, 256>& srgb8Thresholds();

// Reinhard's extended global curve: luminance L_w ≥ 0 (after exposure) → display luminance
//   L_d = L · (1 + L/L_white²) / (1 + L),  L = L_w · L_white / L_max.
// Strictly increasing; L_d(L_max) = 1, values above L_max exceed 1 and clip at the encode.
float reinhardExtendedCurve(float luminance, float maxRadiance, float whiteLuminance);

// One linear RGB radiance → sRGB-encoded display values in [0,1], not yet quantised: exposure,
// operator, sRGB encode. NaN/Inf/negative channels count as 0. Exposed so the inverse's round trip
// can be tested in float, before 8-bit rounding hides errors.
std::array<float, 3> toneMapRgb(const std::array<float, 3>& radiance,
                                const ToneMapSettings& settings);

// RGB (3 or 4 channel) float image → interleaved RGB8 in sRGB. NaN maps to 0.
std::vector<uint8_t> toneMapToSrgb8(const ImageF& image, const ToneMapSettings& settings);

}  // namespace previs
