#pragma once

// Joint bilateral upsampling (Kopf, Cohen, Lischinski, Uyttendaele 2007, "Joint Bilateral
// Upsampling"): a buffer the path tracer rendered at a fraction of the output resolution is
// brought to the output resolution with weights that are a spatial kernel on the low-resolution
// grid times a range kernel on a full-resolution guide (the plate), so that an edge in the
// camera picture keeps what was rendered on either side of it from bleeding across.
//
// Preview uses it on the terms of Eq. 1 that do not contain the plate (RenderSettings::
// resolutionScale, Renderer::image): the plate itself is never resampled or filtered.

#include <cstdint>

#include "image/image.h"

namespace previs {

struct UpsampleSettings {
    // Range kernel: exp(−d²/(2σ²)), d the Euclidean distance of the two guide colours in
    // natural-log units (log(rgb + ε) per channel), so σ is relative: at 0.5 a neighbour 1.5×
    // brighter in every channel weighs 0.37 of an equal one, a 3× brighter one 0.0007.
    // ≤ 0 turns the range kernel off (the spatial kernel alone).
    float rangeSigma = 0.5f;
    // ε of the log, as a fraction of the guide's mean value: keeps black and sensor noise in the
    // dark from looking like edges.
    float logEpsilonFraction = 0.02f;
    // A fourth channel is the mask M of Eq. 1 (the composite's plate-free part): the virtual
    // objects' outline, which the plate does not show, is steered by it instead
    // (shared/composite.h's outlineMask): its ramp, which the B-spline leaves 1.3–2 traced pixels
    // wide, is steepened by this factor times the traced pixel's width in output pixels
    // (outlineKernel; ~1/0.6 brings it to one output pixel), and each tap weighs exp(−(M_outline −
    // M_tap)²/(2σ²)) with σ = maskRangeSigma. ≤ 0 turns both off.
    float outlineSharpening = 1.6f;
    float maskRangeSigma = 0.2f;
    // Worker threads (the render thread waits for the result; the GPU is idle meanwhile).
    // 0 = std::thread::hardware_concurrency().
    uint32_t threads = 0;
};

// What outlineMask and the mask's range kernel use for an output of width × height traced at
// traceWidth × traceHeight (the device's FilmParams::maskSharpness and maskRangeScale).
struct OutlineKernel {
    float sharpness = 0.0f;   // ≤ 1: none
    float rangeScale = 0.0f;  // 1/(2σ²); 0: no mask range kernel
};
OutlineKernel outlineKernel(const UpsampleSettings& settings, uint32_t width, uint32_t height,
                            uint32_t traceWidth, uint32_t traceHeight);

// The low-resolution pixel (i, j) of a `low.width` × `low.height` buffer covers the output's
// [i·W/w, (i+1)·W/w) × [j·H/h, (j+1)·H/h) (W × H = width × height): the traced pixels tile the
// output exactly, whatever the fraction. Output pixel p gets
//   Σ_q low_q · B(u_p − i_q) B(v_p − j_q) · r(p, q) / Σ_q B B r,
// over the 4 × 4 low-resolution pixels q around p's position (u_p, v_p) on the low grid, with B
// the uniform cubic B-spline (a partition of unity that reproduces linear functions exactly) and
// r the range kernel between the guide at p and the guide's area mean over q's footprint, times,
// for 4 channels, the mask's between the outline at p and q's M (OutlineKernel).
// Neighbours outside the low grid are left out (the weights renormalise).
//
// Exact cases (tests/render/upsample_test.cpp): a constant comes out as that constant, a
// linear ramp under a constant guide as the ramp (away from the border), and a pixel whose
// 4 × 4 neighbours are all exactly 0 as exactly 0.
//
// `guide`: width × height, ≥ 3 channels (RGB used), linear, non-negative; null: spatial only.
// Returns width × height × low.channels.
ImageF jointBilateralUpsample(const ImageF& low, uint32_t width, uint32_t height,
                              const ImageF* guide, const UpsampleSettings& settings = {});

}  // namespace previs
