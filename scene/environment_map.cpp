#include "scene/environment_map.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "base/log.h"
#include "base/strings.h"
#include "image/image.h"

namespace previs {

EnvironmentMap studioEnvironment() {
    EnvironmentMap map;
    map.path = kStudioEnvironment;
    map.width = 256;
    map.height = 128;
    map.radiance.resize(size_t(map.width) * map.height);
    struct Softbox {
        float azimuthRad, elevationRad, halfWidthRad, halfHeightRad, radiance;
    };
    const float deg = float(M_PI / 180.0);
    // Azimuth as DESIGN.md §4's u: 0 along +X, growing toward +Z.
    const Softbox boxes[] = {{45.0f * deg, 45.0f * deg, 20.0f * deg, 12.5f * deg, 8.0f},
                             {-135.0f * deg, 20.0f * deg, 25.0f * deg, 15.0f * deg, 3.0f}};
    for (uint32_t y = 0; y < map.height; ++y) {
        // Texel centres; v = 0.5 − elevation / π, u = 0.5 + azimuth / 2π (DESIGN.md §4).
        const float elevation = (0.5f - (float(y) + 0.5f) / float(map.height)) * float(M_PI);
        for (uint32_t x = 0; x < map.width; ++x) {
            const float azimuth = ((float(x) + 0.5f) / float(map.width) - 0.5f) * float(2.0 * M_PI);
            float value = elevation < 0.0f ? 0.15f : 0.5f + 0.3f * std::sin(elevation);
            for (const Softbox& b : boxes) {
                float da = std::remainder(azimuth - b.azimuthRad, float(2.0 * M_PI));
                if (std::abs(da) < b.halfWidthRad &&
                    std::abs(elevation - b.elevationRad) < b.halfHeightRad)
                    value = b.radiance;
            }
            map.radiance[size_t(y) * map.width + x] = glm::vec3(value);
        }
    }
    return map;
}

Result<EnvironmentMap> loadEnvironmentMap(const std::string& path) {
    if (path == kStudioEnvironment) return studioEnvironment();
    const std::string ext = lowerExtension(path);
    if (ext != ".exr" && ext != ".hdr")
        return makeError(
            "cannot load environment map '{}': unsupported extension '{}' (use a linear HDR "
            "OpenEXR .exr or Radiance .hdr equirectangular map)",
            path, ext);

    Result<ImageF> image = readImage(path);
    if (!image) return Error{"environment map: " + image.message()};
    if (image->width < 2 || image->height < 1)
        return makeError("cannot load environment map '{}': {}x{} is too small", path, image->width,
                         image->height);
    if (image->width != 2 * image->height)
        logWarning("environment map '{}' is {}x{}, not 2:1; it is used as equirectangular anyway",
                   path, image->width, image->height);

    EnvironmentMap map;
    map.path = path;
    map.width = image->width;
    map.height = image->height;
    map.radiance.resize(size_t(map.width) * map.height);
    size_t replaced = 0;
    const uint32_t channels = image->channels;
    for (size_t i = 0; i < map.radiance.size(); ++i) {
        const float* p = image->pixels.data() + i * channels;
        glm::vec3 rgb = channels >= 3 ? glm::vec3(p[0], p[1], p[2]) : glm::vec3(p[0]);
        for (int c = 0; c < 3; ++c) {
            if (!std::isfinite(rgb[c]) || rgb[c] < 0.0f) {
                rgb[c] = 0.0f;
                ++replaced;
            }
        }
        map.radiance[i] = rgb;
    }
    if (replaced > 0)
        logWarning("environment map '{}': {} NaN, Inf or negative channel values replaced by 0",
                   path, replaced);
    return map;
}

EnvironmentDistribution buildEnvironmentDistribution(const EnvironmentMap& map) {
    const uint32_t w = map.width;
    const uint32_t h = map.height;
    EnvironmentDistribution dist;
    if (w == 0 || h == 0 || map.radiance.size() != size_t(w) * h) return dist;

    auto sinThetaRow = [h](uint32_t y) { return std::sin(M_PI * (double(y) + 0.5) / double(h)); };

    std::vector<double> weights(size_t(w) * h);
    double total = 0.0;
    for (uint32_t y = 0; y < h; ++y) {
        const double s = sinThetaRow(y);
        for (uint32_t x = 0; x < w; ++x) {
            const size_t i = size_t(y) * w + x;
            const double lum = std::max(0.0, double(luminance(map.radiance[i])));
            // Non-finite input was cleaned at load; guard against maps built in memory.
            weights[i] = std::isfinite(lum) ? lum * s : 0.0;
            total += weights[i];
            if (std::isfinite(lum)) dist.peakLuminance = std::max(dist.peakLuminance, float(lum));
        }
    }
    dist.integral = float(total / (double(w) * double(h)));
    if (!(total > 0.0) || !std::isfinite(total)) {
        dist.integral = 0.0f;
        total = 0.0;
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x) {
                weights[size_t(y) * w + x] = sinThetaRow(y);
                total += sinThetaRow(y);
            }
    }

    dist.conditionalCdf.resize(size_t(h) * (w + 1));
    dist.marginalCdf.resize(h + 1);
    std::vector<double> rowSums(h, 0.0);
    for (uint32_t y = 0; y < h; ++y) {
        float* cdf = dist.conditionalCdf.data() + size_t(y) * (w + 1);
        double rowSum = 0.0;
        for (uint32_t x = 0; x < w; ++x) rowSum += weights[size_t(y) * w + x];
        rowSums[y] = rowSum;
        double running = 0.0;
        cdf[0] = 0.0f;
        for (uint32_t x = 0; x < w; ++x) {
            running += weights[size_t(y) * w + x];
            cdf[x + 1] = rowSum > 0.0 ? float(running / rowSum) : float(double(x + 1) / w);
        }
        // Exactly 1 so the binary search always finds an interval for x < 1.
        cdf[w] = 1.0f;
    }
    double running = 0.0;
    dist.marginalCdf[0] = 0.0f;
    for (uint32_t y = 0; y < h; ++y) {
        running += rowSums[y];
        dist.marginalCdf[y + 1] = float(running / total);
    }
    dist.marginalCdf[h] = 1.0f;
    return dist;
}

}  // namespace previs
