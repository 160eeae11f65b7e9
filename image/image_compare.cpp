#include "image/image_compare.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace previs {

Result<ImageDifference> compareImages(const ImageF& a, const ImageF& b,
                                      const std::optional<PixelRegion>& region) {
    if (a.width != b.width || a.height != b.height || a.channels != b.channels)
        return makeError(
            "images differ in size: {}x{}x{} against {}x{}x{} (render both at the "
            "same resolution and channel count)",
            a.width, a.height, a.channels, b.width, b.height, b.channels);
    if (a.pixels.empty()) return makeError("the images are empty");
    PixelRegion r = region.value_or(PixelRegion{0, 0, a.width, a.height});
    if (r.x0 >= r.x1 || r.y0 >= r.y1 || r.x1 > a.width || r.y1 > a.height)
        return makeError(
            "region {},{},{},{} is empty or outside the {}x{} image (x0,y0,x1,y1 "
            "with x0 < x1 <= width, y0 < y1 <= height)",
            r.x0, r.y0, r.x1, r.y1, a.width, a.height);
    // Sums in double: 1920×1080×3 float values would lose the small differences in float.
    double sumSquared = 0.0, sumRelative = 0.0, sumA = 0.0, sumB = 0.0;
    size_t values = 0;
    std::vector<double> pixelRelative;  // per pixel, over its channels
    pixelRelative.reserve(size_t(r.x1 - r.x0) * (r.y1 - r.y0));
    for (uint32_t y = r.y0; y < r.y1; ++y)
        for (uint32_t x = r.x0; x < r.x1; ++x) {
            double pixel = 0.0;
            for (uint32_t c = 0; c < a.channels; ++c) {
                const size_t i = (size_t(y) * a.width + x) * a.channels + c;
                ++values;
                double va = a.pixels[i], vb = b.pixels[i];
                if (!std::isfinite(va) || !std::isfinite(vb))
                    return makeError("value {} (pixel {}, channel {}) is not finite: {} against {}",
                                     i, i / a.channels, i % a.channels, va, vb);
                sumSquared += (va - vb) * (va - vb);
                pixel += (va - vb) * (va - vb) / (vb * vb + 0.01);
                sumA += va;
                sumB += vb;
            }
            sumRelative += pixel;
            pixelRelative.push_back(pixel);
        }
    ImageDifference d;
    d.values = values;
    d.rmse = std::sqrt(sumSquared / double(d.values));
    d.relMse = sumRelative / double(d.values);
    const size_t left = size_t(double(pixelRelative.size()) * kTrimmedFraction);
    const auto kept = pixelRelative.end() - std::ptrdiff_t(left);
    std::nth_element(pixelRelative.begin(), kept, pixelRelative.end());
    double sumKept = 0.0;
    for (auto it = pixelRelative.begin(); it != kept; ++it) sumKept += *it;
    d.relMseTrimmed = sumKept / double((pixelRelative.size() - left) * a.channels);
    d.meanA = sumA / double(d.values);
    d.meanB = sumB / double(d.values);
    return d;
}

}  // namespace previs
