#pragma once

// Caustics by progressive photon mapping (gpu/shaders/shared/photon_records.h has the rule that
// splits light paths between the photon map and the path tracer): what the scene needs (whether
// photons run at all, where they are aimed, which lights emit them) and the GPU passes of one
// iteration — trace_photons.comp, then photon_grid.comp's radix sort into the hashed grid that
// trace_paths.comp gathers from.

#include <array>
#include <atomic>
#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/compute_pipeline.h"
#include "gpu/context.h"
#include "gpu/interruptible_dispatch.h"
#include "gpu/shaders/shared/photon_records.h"
#include "gpu/shaders/shared/scene_types.h"
#include "render/render_settings.h"
#include "scene/environment_map.h"
#include "scene/scene.h"

namespace previs {

// Chosen on bench/scenes/caustics_glass.gltf (BENCHMARKS.md, issue 9): at 16 iterations the
// caustic's relative RMSE against a long render fell from 0.25 (5 % of the 0.21 m aim radius:
// blur dominated) to 0.13 (2.5 %); below that the path tracer's noise dominates. It holds at
// kDefaultRadiusPhotons photons per iteration (defaultPhotonRadius).
inline constexpr float kDefaultRadiusFraction = 0.025f;
inline constexpr uint32_t kDefaultRadiusPhotons = 1u << 15;

// The first gather radius when none is given: kDefaultRadiusFraction of the aim sphere's radius
// at kDefaultRadiusPhotons per iteration, scaled by √(kDefaultRadiusPhotons / photons). A
// surface's photon density grows with the photons per iteration, so the first disc then holds
// the same expected count whatever that number: the same noise per iteration, and a blur (∝ r²)
// that falls as photons are added instead of staying what the fewer photons needed
// (docs/caustics.md, "Progressive radius"; BENCHMARKS.md, issue 9, ninth pass).
float defaultPhotonRadius(float aimRadius, uint32_t photonsPerIteration);

// A material that may carry caustics (shader::bsdfCarriesCaustics: purely specular, or polished
// without a diffuse base) on some texel: the photons' aim must include it. Errs on the side of
// yes — a larger aim costs photons, a smaller one bias.
bool mayCarryCaustics(const Material& m);

// The sphere photons are aimed at: it holds every triangle that may carry caustics.
struct PhotonAim {
    bool any = false;  // the scene has such a triangle
    glm::vec3 center{0.0f};
    float radius = 0.0f;
    float sceneRadius = 0.0f;  // from center, a sphere that holds the whole scene
};

PhotonAim photonAimFor(const Geometry& geometry, std::span<const Material> materials);

// An emissive triangle as a photon light (BVH order index, as the shaders see it).
struct EmissivePhotonSource {
    uint32_t triangle;
    float luminance;  // of the emitted radiance
    float area;
    glm::vec3 centroid;
    bool real;
};

// How much brighter than the map's mean radiance a texel must be for the environment to send
// photons: a lamp in it (the set's softbox, the sun) whose caustics the path tracer meets as
// speckles. A sky without one (overcast, a uniform furnace) lights glass and mirrors smoothly
// for the path tracer, and its photons would cost a pass every sample for nothing.
inline constexpr double kEnvironmentLampRatio = 16.0;

// ∫ Le dω of `map` in luminance (scale included) where a texel is kEnvironmentLampRatio times
// its mean radiance or more; 0 otherwise (buildPhotonLights' environmentLuminance). From the
// sums its sampling tables `dist` already hold.
double environmentPhotonLuminance(const EnvironmentMap& map, const EnvironmentDistribution& dist);

// The photon light table (PV_BINDING_PHOTON_LIGHTS texels): every light that can send photons,
// picked in proportion to an estimate of the flux it sends toward the aim sphere.
// `environmentLuminance`: ∫ Le dω of the environment map in luminance (0: none), which then
// comes first (PV_PHOTON_LIGHT_ENVIRONMENT).
std::vector<glm::uvec4> buildPhotonLights(const PhotonAim& aim,
                                          std::span<const EmissivePhotonSource> emissive,
                                          std::span<const shader::GpuLight> lights,
                                          double environmentLuminance = 0.0);

// The GPU passes of one photon iteration. Uses the renderer's buffers, indexed by PV_BINDING_*.
class PhotonPasses {
public:
    // trace_photons and photon_grid.comp's stages.
    static constexpr size_t kPipelineCount = 7;
    // `bindings` and `sceneConstants` are trace_paths'; trace_photons shares its scene layout.
    static Result<PhotonPasses> create(GpuContext& ctx, std::span<const BindingKind> bindings,
                                       std::span<const uint32_t> sceneConstants,
                                       Specialise specialise = Specialise::OnHost);

    // Binds the renderer's buffers (after any of them was replaced).
    Status bind(std::span<const GpuBuffer* const> buffers,
                std::span<const BufferRange> ranges = {});

    // Traces params.photonCount photons for params.photonIteration at params.photonRadius and
    // builds the grid. Uploads params (the sort passes change photonSortShift). Returns GPU ms.
    // With `stop`, the tracing (most of the time) runs in parts and ends early once it is set.
    Result<double> run(shader::FrameParams& params, std::span<GpuBuffer* const> buffers,
                       const std::atomic<bool>* stop = nullptr);

private:
    PhotonPasses() = default;
    std::optional<ComputePipeline> trace_;
    InterruptibleDispatch traceParts_{kInterruptiblePartMs};
    std::array<std::optional<ComputePipeline>, 6> grid_;  // photon_grid.comp's stages
};

// Bytes of the photon buffers for `photons` per iteration, by binding.
size_t photonBufferBytes(int binding, uint32_t photons);

}  // namespace previs
