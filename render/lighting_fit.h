#pragma once

// Lighting fitted to the plate (DESIGN.md §4, "The lighting is right when the real-only render
// explains the plate"): where the captured environment map holds light that clipped (a lower
// bound) or the plate-consistency ratio is off, solve a few parameters — one gain per clipped
// light cluster, one global RGB gain — so that the real-only render L_or matches the plate on
// the real surfaces the camera sees.
//
// The model, per real surface sample p and channel c:
//     L_or'(p)_c = G_c · L_or(p)_c · (1 + Σ_k (g_k − 1) · f_k(p)),
// L_or the box's render with the map as captured, f_k(p) the share of p's direct irradiance that
// cluster k gives (cast here on the CPU against the real geometry: lit and shadowed samples both
// say how bright k is), g_k ≥ 1 (a clipped value is a lower bound) and G_c the global gain. It
// is fitted in the log domain (relative error, so shadows count as much as lit surfaces) with a
// Huber loss (specular highlights and edges the model does not hold are outliers) and a prior
// holding log G near 0. The extra light's own interreflections are left out: second order.

#include <array>
#include <glm/glm.hpp>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "render/cpu_tracer.h"

namespace previs {

// One real surface point the camera sees with a trusted pose, away from the virtual objects.
struct PlateSample {
    glm::vec3 plate{0.0f};     // the plate, linear radiance
    glm::vec3 real{0.0f};      // L_or there, rendered with the map as captured
    glm::vec3 position{0.0f};  // world (the tracer's frame)
    glm::vec3 normal{0.0f};    // world, unit, facing the camera
};

// Groups of texels (index y·W + x of an equirectangular map) that are one clipped light:
// 8-connected components of `clippedTexels` (CV_8U, non-zero = clipped), joined across the u seam.
std::vector<std::vector<int>> clippedClusters(const cv::Mat& clippedTexels);

struct LightingFitSettings {
    // The map without its clusters is integrated at this width (its irradiance is smooth).
    int coarseMapWidth = 32;
    // Each cluster's irradiance from at most this many of its texels (the brightest).
    int maxTexelsPerCluster = 48;
    // Huber's threshold on the log residual: within it, least squares; beyond, linear.
    double huberLog = 0.1;
    // Prior on the global gain: log2 G_c ~ N(0, sigma²).
    double globalGainSigmaStops = 1.0;
    double maxClusterGain = 1e5;
    int iterations = 30;
    size_t minSamples = 64;
};

struct LightingFit {
    std::vector<double> clusterGains;           // g_k, one per cluster
    std::array<double, 3> globalGain{1, 1, 1};  // G_c
    // The median over the samples used and their channels of |log(L_or' / plate)|, before the
    // fit (all gains 1) and after: how well the fitted lighting explains the plate (0.01 ≈ 1 %).
    double residualBefore = 0.0;
    double residualAfter = 0.0;
    size_t samples = 0;
};

// Solves the gains. Fails (the caller keeps its lighting) with too few usable samples, a
// singular system or a fit that explains the plate no better than the lighting as captured.
// `map`: the captured equirectangular map (CV_32FC3, linear, world frame as DESIGN.md §4 in the
// tracer's frame); `tracer`: the real geometry (occlusion uses real triangles only).
Result<LightingFit> fitLightingToPlate(const CpuTracer& tracer, const cv::Mat& map,
                                       const std::vector<std::vector<int>>& clusters,
                                       const std::vector<PlateSample>& samples,
                                       const LightingFitSettings& settings = {});

// A fit as it carries over to later snapshots of the same set, whose clusters are found anew:
// each fitted cluster's gain at its direction, and the global gain.
struct LightingCorrection {
    struct Cluster {
        glm::vec3 direction{0.0f, 1.0f, 0.0f};  // world, unit: its power-weighted mean direction
        double gain = 1.0;
    };
    std::vector<Cluster> clusters;
    std::array<double, 3> globalGain{1, 1, 1};
};

LightingCorrection correctionFromFit(const cv::Mat& map,
                                     const std::vector<std::vector<int>>& clusters,
                                     const LightingFit& fit);

// `later` applied after `earlier` (a fit on the map `earlier` had corrected): gains multiply.
LightingCorrection composeCorrections(const LightingCorrection& earlier,
                                      const LightingCorrection& later);

// Clusters of a later snapshot take the gain of the corrected cluster within this angle.
constexpr double kCorrectionMatchDeg = 5.0;

// `map` corrected: each of its clusters times the gain of the correction's cluster nearest in
// direction within kCorrectionMatchDeg (none: left as it is, and `unmatched` counts it), every
// texel times the global gain.
cv::Mat applyCorrection(const cv::Mat& map, const std::vector<std::vector<int>>& clusters,
                        const LightingCorrection& correction, size_t* unmatched = nullptr);

// The power-weighted mean direction of a cluster's texels (world, unit).
glm::vec3 clusterDirection(const cv::Mat& map, const std::vector<int>& texels);

// The real surface each camera ray first meets (origin and unit directions in the tracer's
// world): its position and the geometric normal facing the camera; nullopt for a ray that
// meets none. For plate samples from the meter's cells.
std::vector<std::optional<PlateSample>> realSurfacesAlongRays(
    const CpuTracer& tracer, const glm::vec3& origin, const std::vector<glm::vec3>& directions);

}  // namespace previs
