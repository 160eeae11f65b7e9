#pragma once

// The renderer's settings as plain values: what a config file, the command line and the
// service's config parse into, without the Vulkan headers of the classes that use them
// (render/renderer.h, render/photon_map.h, render/denoiser.h).

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

enum class PhotonMode {
    Auto,  // when the scene has a purely specular object and a light that photons leave from
    On,
    Off,
};

struct PhotonSettings {
    PhotonMode mode = PhotonMode::Auto;
    // Photons per iteration (rounded up to a multiple of 128). Where a gather finds more than
    // gatherNeighbours, its radius holds about that many whatever the iteration, so the blur
    // there falls only as the photons per iteration grow (docs/caustics.md). On the caustics
    // benchmark, against a bias-free reference (BENCHMARKS.md, issue 9, eighth pass), 65536
    // reached 5 % sooner than 32768 and 131072 (each iteration costs more with more photons);
    // with the first radius following the count (ninth pass) 131072 still lose.
    uint32_t perIteration = 1u << 16;
    // Preview frames (Renderer::renderPreviewFrame) trace at most this many: a fixed budget for
    // speed; the radius of a preview frame is the first iterations' (it restarts every frame).
    uint32_t previewPerIteration = 1u << 14;
    // Gather radius of the first iteration (metres); 0: defaultPhotonRadius (from the sphere
    // that holds the specular objects and the photons per iteration).
    float initialRadius = 0.0f;
    // Progressive photon mapping's α in (0, 1): the radius shrinks as (i + 1)^((α − 1)/2).
    // 1 keeps the radius fixed (preview: a fixed, biased but steady estimate).
    float alpha = 2.0f / 3.0f;
    // Records examined per grid bucket at most; fuller buckets are subsampled without bias. A
    // bucket is a cell of edge 2r (photonCellSize): a smaller window subsamples a focus's cells
    // and adds noise (BENCHMARKS.md, issue 9, eleventh pass).
    uint32_t gatherCap = 1024;
    // A gather that finds more than this many photons within the iteration's radius takes its
    // estimate again at the radius that holds about this many: the blur shrinks where photons are
    // dense (at a focus). 0 keeps every gather at the iteration's radius.
    uint32_t gatherNeighbours = 128;
    // The photons the camera sees directly go to the pixels they land in (light tracing's last
    // step, trace_photons.comp's splatToCamera) instead of a gather at the camera path's first
    // vertex: every photon in a pixel counts and no radius blurs them. Needs a pinhole camera
    // (no aperture, no lens grid) and the splat sums within one storage-buffer binding
    // (Renderer::photonSplatBytes); elsewhere, or off, the first vertex gathers.
    bool splatToCamera = true;

    bool operator==(const PhotonSettings&) const = default;
};

// Applies a `--photons` / config value: "auto", "on", "off", or a photon count per iteration
// (which also turns photons on). The error names the accepted values.
Status applyPhotonSpec(const std::string& spec, PhotonSettings& settings);
inline constexpr uint32_t kMaxPhotonsPerIteration = 1u << 20;

struct DenoiseSettings {
    // The strength: à-trous levels, taps 1, 2, 4, ... 2^(n−1) pixels apart; 0 = no spatial
    // filter (apply() returns its input; applyTemporal() only accumulates).
    uint32_t iterations = 5;
    // 2: SVGF's 5×5 B3-spline taps; 1: a 3×3 kernel (8 taps instead of 24 per level).
    uint32_t kernelRadius = 2;
    // SVGF's σ_n and σ_z (Schied et al. 2017, §4.4). Its σ_l = 4 suits its few-frame variance;
    // with the accumulation's own variance it blurs converged gradients (the soft occlusion
    // around a virtual object's contact): measured on tests/integrator/denoise_test.cpp's set,
    // the 256-spp change was 3.1× the noise bound at 4, 1.5× at 2, 0.9× at 1, 0.5× at 0.5, while
    // the 4-spp RMSE gain was 1.39×, 1.55×, 1.55×, 1.28×: 1 keeps both.
    float sigmaLuminance = 1.0f;
    float sigmaNormal = 128.0f;
    float sigmaDepth = 1.0f;
    // Ours (shared/denoise.h). Only pixels of a silhouette have a fractional mask, and their
    // signal is M·L_om + (1 − M)(L_om − L_or): mixing two whose M differs by ΔM moves the
    // result by ΔM times the jump, a bias that shrinks only as fast as the noise. So the
    // weight is nearly a partition: ΔM = 1/64 weighs e^−4, 1/16 e^−16.
    float sigmaMask = 256.0f;
    // Temporal accumulation (applyTemporal): SVGF's α, the smallest weight of the new frame in
    // the exponential moving average (a mean over the first 1/α frames), and the cap of the
    // history length the validation carries (frames).
    float temporalAlpha = 0.2f;
    float maxHistoryFrames = 32.0f;
};

// `--denoise auto`: the denoiser runs while the convergence meter's relative RMSE estimate
// (render/convergence.h) is above the target noise — above kAutoDenoiseAboveNoise without a
// target — and is off once the image has reached it (its bias then costs more than its gain).
// Without an estimate (below 2 spp, or the meter off) it runs below kAutoDenoiseBelowSpp
// samples per pixel (render/denoiser.cpp gives the measurement behind it).
constexpr double kAutoDenoiseAboveNoise = 0.01;
constexpr uint64_t kAutoDenoiseBelowSpp = 64;
inline bool autoDenoise(std::optional<double> noiseEstimate, double targetNoise,
                        uint64_t samplesPerPixel) {
    if (!noiseEstimate) return samplesPerPixel < kAutoDenoiseBelowSpp;
    return *noiseEstimate > (targetNoise > 0.0 ? targetNoise : kAutoDenoiseAboveNoise);
}

// Where a path's random numbers come from (gpu/shaders/shared/sampler.h). Both address every
// number by (pixel, sample, dimension), so both keep preview's fixed sequence and the
// differential identities; Independent is the baseline for ablations.
enum class Sampler {
    Sobol,        // Owen-scrambled Sobol' with per-pixel shuffles (Burley 2020): stratified
    Independent,  // one PCG stream per (pixel, sample, dimension set)
};

// How a chosen emissive triangle is sampled (gpu/shaders/shared/triangle_light.h).
enum class LightSampling {
    SolidAngle,  // uniform in the solid angle it subtends (Arvo 1995), area where it is tiny
    Area,        // uniform in area: the baseline for ablations
};

struct RenderSettings {
    uint32_t width = 640;
    uint32_t height = 480;
    uint32_t maxDepth = 16;           // pbrt's maxdepth: 1 = direct light only
    uint32_t rouletteStartDepth = 3;  // Russian roulette from this many bounces on
    uint32_t seed = 0;
    Sampler sampler = Sampler::Sobol;
    LightSampling lightSampling = LightSampling::SolidAngle;
    int cameraIndex = 0;                   // into Scene::cameras; a default camera if there is none
    std::optional<float> apertureRadiusM;  // override the camera's thin lens
    std::optional<float> focusDistanceM;
    float fireflyClamp = 0.0f;  // 0 = off (default): no hidden clamping
    // Paths per pixel in one GPU dispatch (fewer dispatches, less overhead). On a CPU device
    // the renderer lowers it to stay inside llvmpipe's loop limit (renderer.cpp).
    uint32_t samplesPerDispatch = 1;
    // Differential rendering (the paper): also compute the real-only solution L_or in the same
    // pass, for compositing with the camera image. Off: a plain CG render of the mixed scene.
    bool differential = false;
    // The convergence meter (convergence()): samples alternate between two independently
    // randomised sequences, whose difference measures the error. It costs some stratification
    // (BENCHMARKS.md: about 8 % more RMSE at equal samples); off, one sequence and no meter.
    bool convergenceMeter = true;
    // A calibrated lens (vision/lens_grid.h): (width+1)×(height+1) normalised OpenCV camera
    // coordinates of the pixel corners. Empty: a pinhole with the camera's field of view.
    std::vector<glm::vec2> lensGrid;
    // Caustics from a photon map (render/photon_map.h); Auto runs it only where the scene needs it.
    PhotonSettings photons;
    // Preview speed: the path tracer traces max(1, round(width·s)) × max(1, round(height·s))
    // pixels, each covering 1/s × 1/s output pixels, and image() upsamples them to width ×
    // height guided by the plate (render/upsample.h); the plate is never resampled. In (0, 1];
    // 1 traces every output pixel (and image() is what it was without this setting, bit for bit).
    float resolutionScale = 1.0f;
    // Below full resolution, each preview frame also traces this many samples per output pixel
    // where the virtual objects are (their box projected; Renderer::traceObjectRegion): they are
    // a few per cent of the picture and carry most of its detail finer than a traced pixel,
    // which the held view then gains at the output's resolution. 0: off. Free without virtual
    // objects in view.
    float objectSamplesPerOutputPixel = 1.0f;
    // Preview frames scale a sample whose luminance is above this down to it in the frame's
    // estimate (which the denoiser and the upsampling spread over many output pixels): the rare
    // path to a bright lamp through glass or chrome that one sample in thousands finds would
    // otherwise light a blotch for the whole history. The held view's samples, each kept in its
    // own output pixel, have only their indirect light scaled to it (the light beyond the first
    // rough surface's direct light, and the photons' caustics: trace_paths.comp's
    // gIndirectMixed), and the whole sample to PV_HELD_DIRECT_CLAMP_RATIO times it, so a sunlit
    // floor or a lamp's reflection converges to its level. The preview is biased by it
    // (BENCHMARKS.md measures it); refinement, never clamped, is the picture that converges. A
    // clamp that rises with the frames held was measured worse over 64 frames: the lamps' paths
    // are too rare for a held view to average. 0: off.
    float previewSampleClamp = 0.0f;
    // Preview frames resample the distant light (the environment and the cone lights) at the
    // camera ray's first rough hit across candidates, the last frame and the neighbouring pixels
    // (ReSTIR; gpu/shaders/distant_light_resampling.glsl): far less noise in the soft light and
    // the virtual objects' shadows a frame, for a small bias BENCHMARKS.md measures. Refinement
    // never resamples. Off: none of its code or memory is paid for.
    bool previewResampling = false;
    // Preview frames with a held view (render/held_view.h) place each traced pixel's samples in
    // the k × k output-pixel cells of its footprint by a phase schedule (shared/sampler.h's
    // heldPhaseJitter) instead of at random: a held camera gives every output pixel its samples
    // within k² samples a traced pixel. Off: the sampler's jitter, as refinement's.
    bool previewPhases = true;
    // While the camera holds, the held view tests the frame's estimate's outline against its
    // samples' mask (shared/composite.h's heldEstimateWeight): where they disagree beyond the
    // samples' spread, the estimate counts for less. Off: it counts the same everywhere.
    bool previewOutlineTest = true;
    // The denoiser (render/denoiser.h): the first hit writes its guide buffers and
    // image(aov, true) filters. Off: neither the guides' code nor their memory is paid for.
    bool denoise = false;
    DenoiseSettings denoiseSettings;
};

// A width × height render traced to maxDepth bounces, the rest of RenderSettings as it comes:
// where the tests and the benchmarks start from.
RenderSettings renderSettings(uint32_t width, uint32_t height, uint32_t maxDepth);

// The buffers a render produces (DESIGN.md §3 --aov).
enum class Aov {
    Composite,  // Eq. 1 with the plate; without a plate the mixed scene
    Mixed,      // L_om: real phantoms and virtual objects
    Real,       // L_or: phantoms only (differential renders)
    Mask,       // fraction of camera samples whose first hit is virtual (one channel)
    // Samples that count in each pixel's mean (one channel): samplesPerPixel() less those
    // dropped as NaN/Inf, or lost when a CPU device cut a dispatch short. Not a file AOV.
    SampleCount,
    // The denoiser's guides (RenderSettings::denoise), means over the pixel's samples of the
    // camera ray's first hit: base colour (1 for a miss or an emitter), shading normal facing
    // the camera (RGB = xyz, not normalised), camera distance in metres (one channel; misses
    // PV_GUIDE_MISS_DEPTH_M).
    Albedo,
    Normal,
    Depth,
};

// What the scene uses; each off feature is compiled out of the pipeline.
struct SceneFeatures {
    bool environment = false;
    bool emissive = false;
    bool punctual = false;
    bool specular = false;  // any metal or specular (Fresnel) reflection
    bool transmission = false;
    bool thinLens = false;
    bool textures = false;
    bool coneLights = false;  // estimated lights (Renderer::setEstimatedLights)
    // A material neither Lambertian nor purely specular on every texel (scene/material.h)
    bool glossy = false;
};

// A distant light estimated from the captured environment (vision/light_estimator.h's
// EstimatedLight; the map's residual becomes the environment): uniform radiance over a cone of
// directions of the given solid angle. It belongs to the real set, so it lights both solutions
// of differential rendering, with soft shadows.
struct EstimatedLightSource {
    glm::vec3 direction{0.0f, 1.0f, 0.0f};  // world, toward the light (normalised on upload)
    float solidAngleSr = 0.0f;              // in (0, 4π]
    glm::vec3 radiance{0.0f};               // linear RGB, the environment's units
};

}  // namespace previs
