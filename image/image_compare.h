#pragma once

// The error of a rendered image against a reference, for bench/compare_blender.sh's time to equal
// error (`previs compare`).

#include <cstddef>
#include <cstdint>
#include <optional>

#include "base/result.h"
#include "image/image.h"

namespace previs {

struct ImageDifference {
    double rmse = 0.0;    // sqrt(mean over every pixel and channel of (a − b)²)
    double relMse = 0.0;  // mean of (a − b)² / (b² + 0.01): DESIGN.md §4, b the reference
    // relMse with the pixels of the largest error left out (kTrimmedFraction of them): a path
    // tracer's heavy tail (a lamp of radiance ~1900 seen through glass by one sample in a few
    // thousand) puts most of relMse in a few pixels that any other run puts elsewhere, so relMse
    // alone compares where the fireflies fell more than how the pictures differ.
    double relMseTrimmed = 0.0;
    double meanA = 0.0;  // mean over every pixel and channel
    double meanB = 0.0;
    size_t values = 0;  // pixels × channels compared
};

// The fraction of pixels relMseTrimmed leaves out: one in a thousand.
inline constexpr double kTrimmedFraction = 0.001;

// Pixels [x0, x1) × [y0, y1): a part of the image, e.g. the caustic of bench/caustics.sh.
struct PixelRegion {
    uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

// Every channel of every pixel (of `region`, if given); the two must have the same size and
// channel count and hold finite values (a NaN would make the error meaningless, so it is an
// error, not skipped).
Result<ImageDifference> compareImages(const ImageF& a, const ImageF& b,
                                      const std::optional<PixelRegion>& region = std::nullopt);

}  // namespace previs
