#include "bench/image_compare.h"

#include <cmath>

namespace previs::bench {

Result<ImageDifference> compareImages(const ImageF& a, const ImageF& b) {
    if (a.width != b.width || a.height != b.height || a.channels != b.channels)
        return makeError(
            "images differ in size: {}x{}x{} against {}x{}x{} (render both at the "
            "same resolution and channel count)",
            a.width, a.height, a.channels, b.width, b.height, b.channels);
    if (a.pixels.empty()) return makeError("the images are empty");
    // Sums in double: 1920×1080×3 float values would lose the small differences in float.
    double sumSquared = 0.0, sumRelative = 0.0, sumA = 0.0, sumB = 0.0;
    for (size_t i = 0; i < a.pixels.size(); ++i) {
        double va = a.pixels[i], vb = b.pixels[i];
        if (!std::isfinite(va) || !std::isfinite(vb))
            return makeError("value {} (pixel {}, channel {}) is not finite: {} against {}", i,
                             i / a.channels, i % a.channels, va, vb);
        sumSquared += (va - vb) * (va - vb);
        sumRelative += (va - vb) * (va - vb) / (vb * vb + 0.01);
        sumA += va;
        sumB += vb;
    }
    ImageDifference d;
    d.values = a.pixels.size();
    d.rmse = std::sqrt(sumSquared / double(d.values));
    d.relMse = sumRelative / double(d.values);
    d.meanA = sumA / double(d.values);
    d.meanB = sumB / double(d.values);
    return d;
}

}  // namespace previs::bench
