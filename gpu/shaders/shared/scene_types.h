// GPU scene data: struct layouts (scalar block layout) and binding numbers shared by the
// shaders and the C++ code that uploads them. C++ checks sizes and offsets in gpu_layout.cpp.
#ifndef PREVIS_SHARED_SCENE_TYPES_H
#define PREVIS_SHARED_SCENE_TYPES_H

#include "gpu/shaders/shared/prelude.h"

PV_BEGIN

// Descriptor set 0 bindings of trace_paths.comp.
#define PV_BINDING_PARAMS 0
// The three vertex positions of each triangle in BVH order, one 16-byte texel each (xyz, w
// unused): traversal reads a triangle with three fetches and no index indirection.
#define PV_BINDING_TRIANGLE_VERTICES 1
#define PV_BINDING_NORMALS 2
#define PV_BINDING_UVS 3
#define PV_BINDING_TRIANGLES 4
#define PV_BINDING_TRIANGLE_MATERIALS 5
// WideBvhNode array as a texel buffer of seven uint4 texels per node.
#define PV_BINDING_BVH_NODES 6
#define PV_BINDING_MATERIALS 7
#define PV_BINDING_TEXTURES 8
#define PV_BINDING_TEXELS 9
#define PV_BINDING_LIGHTS 10
#define PV_BINDING_EMISSIVE_TRIANGLES 11
#define PV_BINDING_ENV_RADIANCE 12
#define PV_BINDING_ENV_MARGINAL_CDF 13
#define PV_BINDING_ENV_CONDITIONAL_CDF 14
// Accumulations: 6 vec4 per pixel, [composite | mask], [mixed L_om | samples that count],
// [real L_or | 1 where the camera ray's first hit is phantom geometry, else 0]; composite =
// M ? L_om : L_om − L_or per sample (the plate is added on readback). Dropped (NaN/Inf)
// samples are in none of them: means divide by the count.
// Then the same three over replicate 1's samples only (odd sample indices; sampler.h), for the
// convergence meter (render/convergence.h): replicate 0's are the totals minus these.
#define PV_BINDING_ACCUM_SUM 15
#define PV_BINDING_ACCUM_COMPENSATION 16
#define PV_ACCUM_COMPOSITE 0u
#define PV_ACCUM_MIXED 1u
#define PV_ACCUM_REAL 2u
#define PV_ACCUM_REPLICATE_1 3u  // + PV_ACCUM_COMPOSITE, _MIXED or _REAL
#define PV_ACCUM_COUNT 6u
#define PV_BINDING_STATS 17
#define PV_BINDING_TRIANGLE_LIGHT_PDF 18
// (width+1)×(height+1) vec2: normalised OpenCV camera coordinates of each pixel corner
// (vision/lens_grid.h), when the camera has a calibrated lens.
#define PV_BINDING_LENS_GRID 19
// Photon mapping (shared/photon_records.h). Lights photons leave from, one texel each.
#define PV_BINDING_PHOTON_LIGHTS 20
// The iteration's photon records in photon order (PhotonRecord, 2 per photon) as traced, and the
// same records sorted by grid bucket, which the gather reads.
#define PV_BINDING_PHOTON_RECORDS 21
#define PV_BINDING_PHOTON_SORTED 22
// Radix sort ping-pong arrays of (bucket key, record index) pairs.
#define PV_BINDING_PHOTON_SORT_A 23
#define PV_BINDING_PHOTON_SORT_B 24
// Per sort block, the count (then the scanned offset) of each 8-bit digit, digit-major.
#define PV_BINDING_PHOTON_BLOCK_COUNTS 25
// Per bucket, the [begin, end) range of its records in the sorted array (2 words).
#define PV_BINDING_PHOTON_CELLS 26
// The denoiser's guides (shared/denoise.h): first-hit albedo, normal, depth and luminance
// moments per pixel; a 16-byte placeholder when the renderer has no denoiser.
#define PV_BINDING_GUIDES 27
// The photons' light seen directly by the camera, splatted onto the pixels they land in
// (trace_photons.comp's splatToCamera): per sum PV_SPLAT_*, per pixel, per channel two words of
// 32.32 fixed point (fraction, whole), so the sums do not depend on the order of the atomic
// additions. Cleared by every photon pass, read by the camera pass; a 16-byte placeholder where
// the renderer does not splat.
#define PV_BINDING_PHOTON_SPLATS 28
// The held view's samples at the output's resolution (FrameParams::heldWidth): per output pixel
// two vec4, (Σ of Eq. 1's plate-free part, Σ M) and (the samples, Σ their first hit's distance in
// metres, the last one's normal, whether they were moved: shared/held_reprojection_params.h),
// summed over the frames the view holds. Each output pixel is written only by the traced pixel
// whose footprint holds its centre: no atomics. A 16-byte placeholder where no held view is
// possible.
#define PV_BINDING_HELD_SAMPLES 29
// The held view's clamp of a whole sample over its clamp of the indirect light
// (FrameParams::heldClamp).
#define PV_HELD_DIRECT_CLAMP_RATIO 16.0f
// The preview's reservoirs of the first vertex's distant light (ReSTIR; FrameParams::resampling,
// gpu/shaders/distant_light_resampling.glsl): two halves, the frame that wrote last and the one
// being traced (FrameParams::reservoirHalf), each per traced pixel PV_RESERVOIR_VEC4S vec4. A
// 16-byte placeholder until a preview frame resamples.
#define PV_BINDING_RESERVOIRS 30
#define PV_RESERVOIR_VEC4S 3u
#define PV_BINDING_COUNT 31
#define PV_SPLAT_MIXED 0u          // photons of the mixed solution the camera sees
#define PV_SPLAT_REAL 1u           // photons of the real solution the real camera ray sees
#define PV_SPLAT_REAL_UNHIDDEN 2u  // ... of which no virtual object hides in the mixed solution
#define PV_SPLAT_WORDS 6u          // per sum and pixel: three channels × (fraction, whole)

// Specialization constant ids: scene features that select pipeline variants, so a scene runs
// none of the code it does not need ("model only what the scene requires").
#define PV_SPEC_HAS_ENV 0
#define PV_SPEC_HAS_EMISSIVE 1
#define PV_SPEC_HAS_PUNCTUAL 2
#define PV_SPEC_HAS_SPECULAR 3
#define PV_SPEC_HAS_TRANSMISSION 4
#define PV_SPEC_HAS_THIN_LENS 5
#define PV_SPEC_HAS_TEXTURES 6
// Differential rendering: also the real-only solution L_or (paper's four ray types). Off for a
// plain CG render, which then runs none of it.
#define PV_SPEC_DIFFERENTIAL 7
// Primary rays through the calibrated lens grid instead of the pinhole field of view.
#define PV_SPEC_HAS_LENS_GRID 8
// Cone lights (estimated from the captured environment, Renderer::setEstimatedLights): their
// sampling branch and the test of escaped rays against them.
#define PV_SPEC_HAS_CONE_LIGHTS 9
// The sample generator, PV_SAMPLER_SOBOL or PV_SAMPLER_INDEPENDENT (shared/sampler.h): a
// constant, so a pipeline compiles only the generator it uses.
#define PV_SPEC_SAMPLER 10
// Count loop iterations for the renderer's dispatch sizing (shared/prelude.h): only on a CPU
// device, the one with llvmpipe's loop budget; a GPU compiles the counter out.
#define PV_SPEC_COUNT_LOOPS 11
// Emissive triangles sampled uniformly in the solid angle they subtend (where float precision
// allows, shared/triangle_light.h); off: uniformly in area, the baseline for ablations.
#define PV_SPEC_LIGHT_SOLID_ANGLE 12
// Caustics from a photon map (shared/photon_records.h): the gather at the path's first non-specular
// vertex and the exclusion of the paths the photons carry. Off: the path tracer alone.
#define PV_SPEC_PHOTONS 13
// The denoiser's guide buffers (PV_BINDING_GUIDES): written only by renders that may denoise.
#define PV_SPEC_DENOISE_GUIDES 14
// A material neither Lambertian nor purely specular (a rough metal or glass, a specular layer
// over a diffuse base). Off, every vertex that is not a delta is Lambertian: BSDF evaluations
// (light samples, MIS) are baseColor/π, and the photon gather sums the photons' power and applies
// baseColor/π once, instead of a BSDF evaluation per photon.
#define PV_SPEC_HAS_GLOSSY 15
// The photon map's light seen directly (at the camera path's first vertex) is splatted onto the
// pixels by the photon pass instead of gathered there (docs/caustics.md, "The caustic seen
// directly"): where the host allows it (the setting, and the splat buffer fits one binding).
// The shaders also need a pinhole camera (no lens grid, no aperture): photonSplatsActive.
#define PV_SPEC_PHOTON_SPLAT 16
// The preview may resample the first vertex's distant light (RenderSettings::previewResampling):
// off, none of its code is compiled in; on, it still runs only in preview frames
// (FrameParams::resampling).
#define PV_SPEC_RESAMPLING 17
#define PV_SPEC_COUNT 18
#define PV_SAMPLER_SOBOL 0u
#define PV_SAMPLER_INDEPENDENT 1u

#define PV_WORKGROUP_SIZE_X 8
#define PV_WORKGROUP_SIZE_Y 8

#define PV_NO_TEXTURE 0xffffffffu

// A node of the binary BVH the host builds (32 bytes; render/bvh.cpp), which it collapses into
// the WideBvhNode tree the shaders traverse. Interior: count == 0, children at leftOrFirst and
// leftOrFirst + 1. Leaf: count triangles starting at leftOrFirst in the triangle arrays.
struct BvhNode {
    vec3 boundsMin;
    uint leftOrFirst;
    vec3 boundsMax;
    uint count;
};

// A node of the 4-wide BVH the shaders traverse (render/bvh.cpp collapses the binary SAH tree
// into it): the boxes of its up to four children side by side, so one visit tests four boxes with
// seven 16-byte texel fetches. child[i] is a reference (PV_WIDE_*): another node, a leaf's
// triangle range, or PV_BVH_NO_ROOT for an empty slot, whose box is inverted (lo = +max,
// hi = −max) so that no ray enters it.
struct WideBvhNode {
    vec4 loX;
    vec4 loY;
    vec4 loZ;
    vec4 hiX;
    vec4 hiY;
    vec4 hiZ;
    uvec4 child;
};

// A child reference with PV_WIDE_LEAF set is a leaf: triangles [first, first + count) in BVH
// order, first in the low 24 bits and count − 1 in the 7 bits above; otherwise a node index.
#define PV_WIDE_LEAF 0x80000000u
#define PV_WIDE_LEAF_FIRST_BITS 24u
#define PV_WIDE_LEAF_MAX_COUNT 128u

// The leaf reference of triangles [first, first + count), and its first triangle and count back:
// the one encoding render/bvh.cpp writes and the traversal (ray_tracing.h) reads.
PV_INLINE uint wideLeafReference(uint first, uint count) {
    return PV_WIDE_LEAF | ((count - 1u) << PV_WIDE_LEAF_FIRST_BITS) | first;
}
PV_INLINE uint wideLeafFirst(uint ref) { return ref & ((1u << PV_WIDE_LEAF_FIRST_BITS) - 1u); }
PV_INLINE uint wideLeafCount(uint ref) {
    return ((ref & ~PV_WIDE_LEAF) >> PV_WIDE_LEAF_FIRST_BITS) + 1u;
}

// glTF 2.0 metallic-roughness material with the transmission, ior, specular and
// emissive_strength extensions. Texture fields index TextureInfo or are PV_NO_TEXTURE.
struct GpuMaterial {
    vec4 baseColor;  // linear RGB + alpha
    vec3 emission;   // emissiveFactor * emissive_strength (radiance)
    float metallic;
    vec3 specularColor;  // KHR_materials_specular specularColorFactor
    float roughness;     // perceptual; alpha = roughness^2
    float transmission;
    float ior;
    float specular;  // KHR_materials_specular specularFactor
    uint baseColorTexture;
    uint metallicRoughnessTexture;
    uint normalTexture;
    uint emissiveTexture;
    uint flags;        // PV_MATERIAL_* bits
    vec3 attenuation;  // KHR_materials_volume absorption coefficient inside, 1/m
    uint reserved;     // keeps the struct a whole number of 16-byte texels
};

#define PV_MATERIAL_DOUBLE_SIDED 1u
// Transmission through a thin wall, not into a volume (KHR_materials_volume absent).
#define PV_MATERIAL_THIN_WALLED 2u

// A texture stored as packed RGBA8 texels at `offset` in the texel buffer.
struct TextureInfo {
    uint offset;
    uint width;
    uint height;
    uint flags;  // PV_TEXTURE_* (shared/texture_sampling.h): sRGB, wrap modes, filter
};

#define PV_LIGHT_POINT 0u
#define PV_LIGHT_SPOT 1u
#define PV_LIGHT_DIRECTIONAL 2u
// A distant light of finite size: uniform radiance over the cone of directions around
// −direction (an estimated light of the captured environment; soft shadows, seen by escaping rays).
#define PV_LIGHT_CONE 3u
#define PV_LIGHT_TYPE_MASK 0xffu
// Set in GpuLight::type for a light that exists in the real scene (lights both solutions);
// a light without it is a virtual (artistic) light and only lights the mixed solution.
#define PV_LIGHT_REAL 0x100u

// KHR_lights_punctual light in world space. intensity = colour * intensity (candela for point
// and spot, lux for directional). A cone light keeps its radiance in `intensity`, cos θmax of its
// half-angle in `cosOuterCone` and 1 − cos θmax in `cosInnerCone` (a small cone's cos θmax rounds
// to 1 in float; its solid angle 2π(1 − cos θmax) must not).
struct GpuLight {
    vec3 position;
    uint type;
    vec3 direction;  // unit, the direction the light points (spot, directional)
    float cosOuterCone;
    vec3 intensity;
    float cosInnerCone;
};

// An emissive triangle for light sampling; chosen with probability proportional to its power
// (area * mean emitted radiance) through the cumulative distribution `cdf`.
struct EmissiveTriangle {
    uint triangle;
    float area;
    float cdf;  // inclusive cumulative probability
    float pdf;  // probability of choosing this triangle
};

// Counters the shader raises; the host checks them after a render.
struct RenderStats {
    uint nonFiniteSamples;   // samples dropped because they were NaN or infinite
    uint raysTraced;         // closest-hit and shadow rays (wraps at 2^32; benchmarks only)
    uint maxLoopIterations;  // the most loop iterations one invocation ran in a dispatch
    uint nonFiniteRays;      // rays with a NaN/Inf origin or direction: culled, sample dropped
};

// Per-dispatch parameters (binding PV_BINDING_PARAMS).
struct FrameParams {
    mat4 worldFromCamera;   // camera looks along -Z, +Y up
    vec2 tanHalfFov;        // tan of the half field of view, x and y
    float apertureRadiusM;  // thin lens; 0 = pinhole
    float focusDistanceM;
    uint width;
    uint height;
    uint sampleBase;  // index of the first sample of this dispatch
    uint samplesPerDispatch;
    uint seed;
    // 2: samples alternate between two independently randomised sequences, which the
    // convergence meter compares (shared/sampler.h); 1: one sequence, no meter.
    uint replicates;
    // The dispatch covers rows [bandFirstRow, bandFirstRow + rows dispatched): the renderer
    // splits a frame whose accumulation exceeds the device's storage-buffer range into bands,
    // binding each band's part of the accumulation (Renderer::render).
    uint bandFirstRow;
    uint maxDepth;  // most scattering events on a path (pbrt's maxdepth)
    uint lightCount;
    uint emissiveTriangleCount;
    uint realRoot;     // BVH root over real (phantom) geometry, or 0xffffffff
    uint virtualRoot;  // BVH root over virtual geometry, or 0xffffffff
    uint envWidth;
    uint envHeight;
    float envScale;           // multiplies the map's radiance
    float envRotationCos;     // the map's rotation about +Y (counter-clockwise seen from
    float envRotationSin;     // above) as cos and sin, computed once (envRotationCosSin)
    float envIntegral;        // mean luminance·sinθ weight of the map (EnvironmentDistribution)
    float fireflyClamp;       // 0 = off (default); else the largest sample luminance kept
    uint rouletteStartDepth;  // Russian roulette from this depth on
    uint realTriangleCount;   // triangles [0, this) in BVH order are real (phantoms)
    uint coneLightFirst;      // lights [this, lightCount) are cone lights (PV_LIGHT_CONE)
    // Photon mapping (shared/photon_records.h); unused when the pipeline has no photons.
    uint photonCount;      // photons traced this iteration (a multiple of 128)
    uint photonIteration;  // the iteration: seeds its photons (the sample index it serves)
    float photonRadius;    // this iteration's gather radius (metres)
    uint photonLightCount;
    vec3 photonAimCenter;     // photons are aimed at this sphere, which holds every purely
    float photonAimRadius;    // specular triangle (so none is wasted on the rest of the scene)
    float photonSceneRadius;  // from photonAimCenter, a sphere holding the scene: distant lights'
                              // photons start on it
    uint photonMaxBounces;    // specular bounces a photon follows at most (≤ maxDepth − 1)
    uint photonSortShift;     // the radix pass photon_grid.comp runs: 0, 8 or 16 (bits of the key)
    uint photonGatherCap;     // records examined per bucket at most; a fuller bucket is subsampled
    // A gather that finds more records than this within the radius takes its estimate again at
    // the radius that holds about this many (trace_paths.comp's gatherPhotons); 0: never.
    uint photonGatherNeighbours;
    // Sort pairs photon_grid.comp's radix passes sort: the iteration's stored records (the
    // compaction's count), rounded up to whole sort blocks.
    uint photonSortRecords;
    // The held view (render/held_view.h): 0, off; else the output's size, larger than the
    // traced one (width, height), and each sample is also added to the output pixel its jitter
    // landed in (PV_BINDING_HELD_SAMPLES).
    uint heldWidth;
    uint heldHeight;
    // The dispatch traces columns [columnFirst, columnEnd) of rows [rowFirst, rowEnd), within
    // its band: the band's rows, or the virtual objects' part of them where the renderer adds
    // samples there (Renderer::traceObjectRegion).
    uint columnFirst;
    uint rowFirst;
    uint columnEnd;
    uint rowEnd;
    // 1: such a dispatch of added samples. The photon splats, which the frame's own dispatch adds
    // once per pixel, are not added again: its first vertex gathers instead, as without splats.
    uint objectSamples;
    // Preview: a sample whose luminance is above this is scaled down to it in the accumulation
    // (the frame's estimate); 0 = off (refinement). RenderSettings::previewSampleClamp.
    float estimateClamp;
    // The held view's samples: their indirect light the same way at this, and the whole sample
    // at PV_HELD_DIRECT_CLAMP_RATIO times it; 0 = off.
    float heldClamp;
    // The photon light table holds the environment (PV_PHOTON_LIGHT_ENVIRONMENT): its caustics
    // are the photons', so the path tracer leaves them out (shared/photon_records.h).
    uint photonEnvironment;
    // Preview frames (0 = off: refinement, or RenderSettings::previewResampling off): the first
    // vertex's environment and cone lights come from reservoirs resampled across candidates, the
    // last frame and the pixel's neighbours (PV_BINDING_RESERVOIRS).
    uint resampling;
    // The other half of PV_BINDING_RESERVOIRS holds the last preview frame's reservoirs at this
    // traced size (0: none to reuse).
    uint reservoirHistory;
    uint reservoirHalf;  // the half this frame writes (0 or 1)
    // Preview frames with a held view: a traced pixel's samples follow the phase schedule over
    // the k × k cells of its footprint (shared/sampler.h's heldPhaseJitter), k = heldPhaseCells;
    // 0: the sampler's jitter (refinement, or RenderSettings::previewPhases off). Sample i of the
    // frame has phase heldPhase + i; heldPhaseSeed seeds each traced pixel's offset.
    uint heldPhaseCells;
    uint heldPhase;
    uint heldPhaseSeed;
};

PV_END

#endif
