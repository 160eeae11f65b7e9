#pragma once

// Display-referred 8-bit camera images → linear radiance, the inverse of render/tonemap.h's
// operators (sRGB transfer, optional global Reinhard, exposure), plus the per-camera white-balance
// gains that bring every camera to the scene's radiance units. Used for fisheye frames
// (previs envmap) and for plates, so both end in the same units (docs/radiometric-calibration.md).

#include <array>
#include <optional>
#include <string>

#include <opencv2/core.hpp>

#include "image/image.h"

namespace previs {

enum class InverseToneMapOperator {
    Srgb,      // inverse of render's Clamp: the sRGB transfer function only
    Reinhard,  // inverse of L/(1+L) on Rec.709 luminance (Reinhard et al. 2002, global)
};

std::optional<InverseToneMapOperator> parseInverseToneMapOperator(const std::string& name);

struct InverseToneMapSettings {
    InverseToneMapOperator op = InverseToneMapOperator::Srgb;
    // The exposure the display image was made with, in stops: linear = untonemapped / 2^stops.
    float exposureStops = 0.0f;
    // Per-channel gains (R, G, B) applied last, from the camera's radiometric calibration.
    std::array<float, 3> whiteBalance{1.0f, 1.0f, 1.0f};
    // Reinhard's inverse diverges at display luminance 1; values above this are clamped to it
    // (clipped highlights cannot be recovered anyway), so the largest radiance is finite:
    // 0.99 → 99× the display white.
    float maxDisplayLuminance = 0.99f;
};

// sRGB transfer function, decoding (IEC 61966-2-1): encoded value in [0,1] → linear.
float srgbDecode(float encoded);

// One RGB triple, display-referred sRGB-encoded in [0,1] → linear radiance.
std::array<float, 3> inverseToneMapRgb(const std::array<float, 3>& encoded,
                                       const InverseToneMapSettings& settings);

// ImageF with ldrSrgb = true (1, 3 or 4 channels; alpha is passed through) → linear ImageF
// (ldrSrgb = false). An image that is already linear is returned unchanged. NaN/Inf become 0.
ImageF inverseToneMap(const ImageF& image, const InverseToneMapSettings& settings);

// 8-bit RGB frame (CV_8UC3, channels in R, G, B order) → CV_32FC3 linear RGB, through a 256-entry
// table for the transfer function (camera frames arrive at video rate).
cv::Mat inverseToneMapRgb8(const cv::Mat& rgb8, const InverseToneMapSettings& settings);

}  // namespace previs
