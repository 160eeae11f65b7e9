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

// The error of `a` against the picture that two independent renders of it, `b` and `twin`, both
// estimate. A reference whose own noise is not small (a path-traced one's, at any affordable
// samples) puts that noise into relMSE against it: a floor no image under test goes below, which
// hides the image's own error. With b and twin independent, E[(a − b)(a − twin)] = (a − truth)²
// exactly, so the mean of (a − b)(a − twin)/(m² + 0.01) estimates DESIGN.md §4's relMSE
// against the truth without the references' noise. m is the references' mean over the 5×5
// pixels around (clipped at the border): their mean at the pixel alone is correlated with the
// numerator's noise, which biases the estimate (2.3× at a reference noise of 20 %, 80× at 50 %,
// in a simulation; the 5×5 mean 1.02× and 1.25×). The estimate is noisy itself and can come out
// below 0: the figures are then 0.
struct PairedDifference {
    double netRelMse = 0.0;
    // The same, the pixels where b and twin disagree most (kTrimmedFraction of them, the
    // references' fireflies) left out.
    double netRelMseTrimmed = 0.0;
};
Result<PairedDifference> compareWithPairedReference(const ImageF& a, const ImageF& b,
                                                    const ImageF& twin);

// Per pixel of `a`: its term of compareWithPairedReference's sum (over its channels), how far
// the two references disagree there on the same scale, and the references' 5×5 mean (over the
// channels): where an image's error lies.
struct PairedPixel {
    double error = 0.0;
    double disagreement = 0.0;
    double localMean = 0.0;
};
Result<std::vector<PairedPixel>> pairedPixelErrors(const ImageF& a, const ImageF& b,
                                                   const ImageF& twin);

}  // namespace previs
