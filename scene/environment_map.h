#pragma once

// Loading equirectangular HDR environment maps and building their importance-sampling tables
// (piecewise-constant 2D distribution, pbrt-v4 PiecewiseConstant2D). The tables feed
// gpu/shaders/shared/env_sampling.h on both CPU and GPU.

#include <string>
#include <vector>

#include "base/luminance.h"
#include "base/result.h"
#include "scene/scene.h"

namespace previs {

// OpenEXR or Radiance .hdr, linear RGB. NaN, Inf and negative texels become 0 (one warning with
// their count): lossy EXR codecs leave small negatives, and one NaN would poison every pixel that
// samples it.
// The name "studio" (kStudioEnvironment) is not a file: it gives studioEnvironment().
Result<EnvironmentMap> loadEnvironmentMap(const std::string& path);

// The bundled neutral environment `--env studio`, for looking at a model that brings no light of
// its own, as glTF viewers do: generated here (nothing to install or find), 256×128, grey and
// colourless — a floor of radiance 0.15, a sky rising from 0.5 at the horizon to 0.8 at the
// zenith, a key softbox (radiance 8, 40°×25°, 45° up, front right) and a fill softbox (radiance
// 3, 50°×30°, 20° up, back left), so shapes read with soft shadows from above.
inline constexpr const char* kStudioEnvironment = "studio";
EnvironmentMap studioEnvironment();

// Tables over (u, v) in [0,1)^2 with weights luminance(texel) * sin(θ_row_centre), θ = πv: the
// sin θ makes the density in solid angle follow the luminance (dω = 2π² sinθ du dv).
struct EnvironmentDistribution {
    std::vector<float> marginalCdf;     // height + 1 entries, [0] = 0, [height] = 1
    std::vector<float> conditionalCdf;  // height * (width + 1): row r at r * (width + 1)
    // ∫∫ weight du dv = sum of the weights / (width * height), in luminance units. 0 when the map
    // is black (the tables then sample the sphere uniformly).
    float integral = 0.0f;
    // The brightest texel's luminance (photons take a map with a lamp: render/photon_map.h).
    float peakLuminance = 0.0f;
};

// Sums run in double so a 1e5 sun next to 1e-3 sky keeps the small texels' probabilities. A row
// of zero weight gets a uniform conditional (it is never chosen anyway); a map of zero weight
// everywhere gets weights sin θ, i.e. uniform directions on the sphere, so the tables stay valid.
EnvironmentDistribution buildEnvironmentDistribution(const EnvironmentMap& map);

// Rec. 709 luminance of linear RGB (base/luminance.h).
inline float luminance(const glm::vec3& rgb) { return luminance(rgb.r, rgb.g, rgb.b); }

}  // namespace previs
