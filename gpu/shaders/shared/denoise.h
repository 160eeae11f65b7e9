// The denoiser's data (denoise.comp, render/denoiser.h): the guide buffers the path tracer's
// first hit writes (trace_paths.comp, PV_BINDING_GUIDES) and the edge-avoiding à-trous filter's
// bindings and parameters (Dammertz et al. 2010, "Edge-Avoiding À-Trous Wavelet Transform for
// fast Global Illumination Filtering"; weights as in Schied et al. 2017, SVGF).
#ifndef PREVIS_SHARED_DENOISE_H
#define PREVIS_SHARED_DENOISE_H

#include "gpu/shaders/shared/prelude.h"

PV_BEGIN

// Guides: PV_GUIDE_COUNT vec4 per pixel, each the running mean over the pixel's kept samples
// (the same samples as the accumulation's means), so antialiased edges get the blend their
// colour has. Means, not sums: a mean updated by (sum − k·mean)/(n + k) stays precise after
// millions of samples in float, where a plain sum of depths would not.
#define PV_GUIDE_ALBEDO_DEPTH \
    0u  // first-hit base colour (1 for a miss or an emitter), camera distance (m)
#define PV_GUIDE_NORMAL 1u  // first-hit shading normal facing the camera; w = samples in the means
// Second moments of the luminance of each accumulated signal per sample: the composite without
// the plate, L_om, L_or. With the means they give each pixel's variance (SVGF's moments). w: the
// mask M (the fraction of samples whose first hit is virtual): Eq. 1 composites two different
// signals on either side of M's edge (L_om on a virtual object, L_om − L_or on the real set),
// which the filter must not mix even where depth and normal would let it.
#define PV_GUIDE_MOMENTS 2u
#define PV_GUIDE_COUNT 3u
// The camera distance recorded for a ray that hits nothing: far beyond any set, finite so that
// means and differences stay finite.
#define PV_GUIDE_MISS_DEPTH_M 1.0e4f
// A history whose surface normal is further than this cosine (about 25°) from the pixel's is
// another surface's: the denoiser's temporal test and the held view's (held_reprojection_params.h).
#define PV_HISTORY_MIN_NORMAL_COS 0.9f

// Descriptor set 0 of denoise.comp.
#define PV_DENOISE_BINDING_PARAMS 0
// Per pixel: the signal to filter (RGB) and the variance of its mean's luminance (w; negative:
// unknown, the prepare stage estimates it spatially). A texel buffer.
#define PV_DENOISE_BINDING_COLOR 1
#define PV_DENOISE_BINDING_GUIDES 2  // PV_GUIDE_COUNT vec4 per pixel, as above (texel buffer)
// PV_DENOISE_WORK_IMAGES images of vec4 (demodulated RGB, its luminance variance): the prepared
// input, the temporally integrated input (preview), then two for the iterations' ping-pong
// (without the temporal stage, images 1 and 2: the buffer holds three until the first temporal
// frame, four from then on).
#define PV_DENOISE_BINDING_WORK 3
// The filtered signal, vec4 per pixel: RGB, and in w the mask M that goes with it (the history's
// mean after a temporal stage, else the frame's own).
#define PV_DENOISE_BINDING_OUTPUT 4
// The work buffer again, as a texel buffer the stages read (on llvmpipe a texel fetch is a
// gather, a storage-buffer load with per-lane addresses a loop over the lanes). A dispatch reads
// only images it does not write.
#define PV_DENOISE_BINDING_WORK_TEXELS 5
// Two images (this frame's and the previous frame's) of what a filter tap needs besides the
// colour, packed by the prepare stage into one uvec4 per pixel (PV_PACKED_*): an à-trous tap
// reads two texels instead of four.
#define PV_DENOISE_BINDING_PACKED 6
#define PV_DENOISE_BINDING_PACKED_TEXELS 7  // the same, read
// Two images (read, written; swapped each frame) of the temporal history, PV_HISTORY_TEXELS
// vec4 per pixel: (integrated demodulated RGB, history length in frames), (EMA of the
// luminance, EMA of its square, EMA of the frames' own variance, Σ of the squared EMA weights),
// (EMA of the signal itself, not demodulated, and of the mask M: where M varies from frame to
// frame, at the virtual objects' outlines, the composite needs the mean of M that goes with the
// signal's mean, and a mean of the signal that does not depend on this frame's albedo).
// Made with the first temporal frame (refinement, which filters without it, never holds them;
// nor the temporal work image: its iterations ping-pong in images 1 and 2).
#define PV_DENOISE_BINDING_HISTORY 8
#define PV_DENOISE_BINDING_HISTORY_TEXELS 9  // the same, read
#define PV_DENOISE_BINDING_COUNT 10

#define PV_DENOISE_WORK_IMAGES 4u
#define PV_DENOISE_WORK_PREPARED 0u
#define PV_DENOISE_WORK_TEMPORAL 1u
#define PV_HISTORY_TEXELS 3u

// The packed guide texel: x depth (float bits, m), y normal (packSnorm2x16 of its octahedral
// map, or PV_PACKED_NO_NORMAL where the guide has none), z mask M (float bits: the mask weight
// needs its full precision), w the depth's slopes per pixel along x and y (packHalf2x16).
#define PV_PACKED_NO_NORMAL 0x80008000u  // −32768 twice: packSnorm2x16 never writes it

// Specialization constant 0 of denoise.comp: which stage the pipeline runs.
#define PV_DENOISE_STAGE_PREPARE 0u
#define PV_DENOISE_STAGE_ATROUS 1u
#define PV_DENOISE_STAGE_FINISH 2u
#define PV_DENOISE_STAGE_TEMPORAL 3u

// Workgroup shape: llvmpipe runs 8 consecutive invocations (along x) as one SIMD batch; 32×2
// and 16×16 measured no faster than 8×8 (bench/results/benchmarks_2026-11-28.md,
// "Issue 10: denoiser").
#define PV_DENOISE_GROUP_X 8
#define PV_DENOISE_GROUP_Y 8

struct DenoiseParams {
    // The temporal stage's reprojection: the previous frame's camera from this frame's (both
    // look along −Z, +Y up), composed on the host in double so that far-from-origin worlds keep
    // their precision.
    mat4 prevCameraFromCamera;
    vec2 tanHalfFov;  // this frame's tan of the half field of view, x and y
    vec2 prevTanHalfFov;
    uint width;
    uint height;
    uint stepPx;           // this iteration's tap spacing: 2^iteration
    uint inImage;          // work image read
    uint outImage;         // work image written
    uint kernelRadius;     // 1: a 3×3 kernel, 2: 5×5
    uint packedImage;      // packed guide image of this frame (the other is the previous frame's)
    uint historyIn;        // history image read (temporal stage); the other is written
    uint historyValid;     // 0: no usable previous frame (reset), every pixel starts afresh
    uint temporal;         // 1: this frame runs the temporal stage (the finish reads its history)
    float temporalAlpha;   // the EMA's smallest weight of the new frame (SVGF's α)
    float maxHistory;      // history length cap (frames)
    float sigmaLuminance;  // SVGF's σ_l: luminance tolerance in standard deviations of the noise
    float sigmaNormal;     // SVGF's σ_n: exponent of the normals' cosine
    float sigmaDepth;      // SVGF's σ_z: depth tolerance in units of the local depth gradient
    float sigmaMask;       // weight exp(−σ_m·|ΔM|) between pixels of different mask
};

PV_END

#endif
