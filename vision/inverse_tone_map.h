#pragma once

// Display-referred 8-bit camera images → linear radiance, the inverse of render/tonemap.h's
// operators (sRGB transfer, optional global Reinhard or extended Reinhard, exposure), plus the
// per-camera white-balance
// gains that bring every camera to the scene's radiance units. Used for fisheye frames
// (previs envmap) and for plates, so both end in the same units (docs/radiometric-calibration.md).

#include <array>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>

#include "colour/ocio_colour.h"
#include "image/image.h"

namespace previs {

// Banterle is the recommended operator for LDR plates and fisheye frames whose camera applied a
// highlight roll-off: it recovers highlights up to a chosen peak radiance and stays finite and
// smooth up to code 255. Srgb is for cameras whose output is linear up to clipping (no
// roll-off); Reinhard only inverts frames made by render's own "reinhard" operator.
enum class InverseToneMapOperator {
    Srgb,      // inverse of render's Clamp: the sRGB transfer function only
    Reinhard,  // inverse of L/(1+L) on Rec.709 luminance (Reinhard et al. 2002, global)
    Banterle,  // inverse of render's ReinhardExtended (Banterle et al., GRAPHITE 2006)
};

// "srgb" (or "clamp"), "reinhard", "banterle" (or "reinhard-extended"): each forward operator
// name of render/tonemap.h also selects its inverse.
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
    // Banterle only (both > 0, finite). maxRadiance is L_max: the luminance, before exposure and
    // white balance, that display white (code 255 on all channels) maps to; there the inverse
    // curve ends with a finite slope. whiteLuminance is Reinhard's L_white, the curve's shape:
    // > 1 compresses highlights (larger = longer shoulder, more of the range kept for shadows),
    // 1 is linear, < 1 expands. Equal values (the defaults) make the forward curve Reinhard's
    // extended operator unscaled (slope 1 at black): within 1 % of the plain Reinhard inverse up
    // to L_d = 0.5, ending at 16, 4 stops above display white, instead of diverging. Set both per
    // camera (docs/camera-calibration.md §2).
    float maxRadiance = 16.0f;
    float whiteLuminance = 16.0f;
    // A camera that sends Rec.709 or a log encoding ([cameras.*.colour], colour/ocio_colour.h):
    // OpenColorIO decodes it to the working space in place of the sRGB decode and `op`;
    // exposure and white balance still apply after it. Null (the demo's, and any camera without
    // the section): the curves above, and OCIO is never touched.
    std::shared_ptr<const CameraColourTransform> colour{};

    bool operator==(const InverseToneMapSettings&) const = default;
};

// sRGB transfer function, decoding (IEC 61966-2-1): encoded value in [0,1] → linear.
float srgbDecode(float encoded);

// Banterle et al., "Inverse Tone Mapping", GRAPHITE 2006: linear display luminance L_d →
// luminance L_w,
//   L_w = ½ · L_max · L_white · (L_d − 1 + √((1 − L_d)² + 4·L_d / L_white²)),
// the exact inverse of render/tonemap.h's reinhardExtendedCurve with the same parameters.
// L_d is clamped to [0, 1]; L_w(0) = 0, L_w(1) = L_max, and the slope is finite everywhere
// (at most L_max · max((1 + L_white)/2, 1/L_white)), unlike L_d/(1 − L_d).
float banterleInverseCurve(float displayLuminance, float maxRadiance, float whiteLuminance);

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
