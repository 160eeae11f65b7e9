#include "image/image_compare.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace previs {

namespace {

Status checkSameShape(const ImageF& a, const ImageF& b) {
    if (a.width != b.width || a.height != b.height || a.channels != b.channels)
        return makeError(
            "images differ in size: {}x{}x{} against {}x{}x{} (render both at the "
            "same resolution and channel count)",
            a.width, a.height, a.channels, b.width, b.height, b.channels);
    return {};
}

}  // namespace

Result<ImageDifference> compareImages(const ImageF& a, const ImageF& b,
                                      const std::optional<PixelRegion>& region) {
    if (Status s = checkSameShape(a, b); !s) return s.error();
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

namespace {

// The mean of (b + twin)/2 over the 5×5 pixels around each value (clipped at the border), per
// channel: compareWithPairedReference's normalisation.
std::vector<double> localPairMean(const ImageF& b, const ImageF& twin) {
    constexpr int kRadius = 2;
    const int w = int(b.width), h = int(b.height), c = int(b.channels);
    std::vector<double> out(b.pixels.size());
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            for (int k = 0; k < c; ++k) {
                double sum = 0.0;
                int n = 0;
                for (int yy = std::max(0, y - kRadius); yy <= std::min(h - 1, y + kRadius); ++yy)
                    for (int xx = std::max(0, x - kRadius); xx <= std::min(w - 1, x + kRadius);
                         ++xx, ++n) {
                        const size_t i = (size_t(yy) * w + xx) * c + k;
                        sum += 0.5 * (double(b.pixels[i]) + twin.pixels[i]);
                    }
                out[(size_t(y) * w + x) * c + k] = sum / n;
            }
    return out;
}

}  // namespace

Result<std::vector<PairedPixel>> pairedPixelErrors(const ImageF& a, const ImageF& b,
                                                   const ImageF& twin) {
    if (Status s = checkSameShape(a, b); !s) return s.error();
    if (Status s = checkSameShape(b, twin); !s) return s.error();
    if (a.pixels.empty()) return makeError("the images are empty");
    for (size_t i = 0; i < a.pixels.size(); ++i)
        if (!std::isfinite(a.pixels[i]) || !std::isfinite(b.pixels[i]) ||
            !std::isfinite(twin.pixels[i]))
            return makeError("value {} (pixel {}, channel {}) is not finite: {} against {}, {}", i,
                             i / a.channels, i % a.channels, a.pixels[i], b.pixels[i],
                             twin.pixels[i]);
    const std::vector<double> m = localPairMean(b, twin);
    std::vector<PairedPixel> pixels(size_t(a.width) * a.height);
    for (size_t p = 0; p < pixels.size(); ++p)
        for (uint32_t c = 0; c < a.channels; ++c) {
            const size_t i = p * a.channels + c;
            const double va = a.pixels[i], vb = b.pixels[i], vt = twin.pixels[i];
            const double weight = 1.0 / (m[i] * m[i] + 0.01);
            pixels[p].error += (va - vb) * (va - vt) * weight;
            pixels[p].disagreement += (vb - vt) * (vb - vt) * weight;
            pixels[p].localMean += m[i] / double(a.channels);
        }
    return pixels;
}

Result<PairedDifference> compareWithPairedReference(const ImageF& a, const ImageF& b,
                                                    const ImageF& twin) {
    Result<std::vector<PairedPixel>> errors = pairedPixelErrors(a, b, twin);
    if (!errors) return errors.error();
    std::vector<PairedPixel>& pixels = *errors;
    const auto mean = [&](auto first, auto last) {
        double sum = 0.0;
        for (auto it = first; it != last; ++it) sum += it->error;
        return std::max(0.0, sum / (double(std::distance(first, last)) * a.channels));
    };
    PairedDifference d;
    d.netRelMse = mean(pixels.begin(), pixels.end());
    const size_t left = size_t(double(pixels.size()) * kTrimmedFraction);
    const auto kept = pixels.end() - std::ptrdiff_t(left);
    std::nth_element(
        pixels.begin(), kept, pixels.end(),
        [](const PairedPixel& x, const PairedPixel& y) { return x.disagreement < y.disagreement; });
    d.netRelMseTrimmed = mean(pixels.begin(), kept);
    return d;
}

}  // namespace previs
