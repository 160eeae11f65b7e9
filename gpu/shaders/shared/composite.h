// The film's math that the host (render/film.cpp, render/held_view.cpp, render/tonemap.cpp) and
// the display pass (film_display.comp) both run, and the display pass's bindings: Eq. 1 of Kán &
// Kaufmann, the held view's blend, and the global tone curves. One definition each, so the
// monitor shows what `previs render` writes.
#ifndef PREVIS_SHARED_COMPOSITE_H
#define PREVIS_SHARED_COMPOSITE_H

#include "gpu/shaders/shared/prelude.h"

PV_BEGIN

// Eq. 1 summed over n samples of a pixel: Σ[M·L_om + (1−M)(L_om − L_or)] (the plate-free sum the
// path tracer accumulates) plus (n − ΣM)·L_oc. A macro, so the host evaluates it in double and
// the shader in float.
#define PV_COMPOSITE_SUM(plateFreeSum, maskSum, samples, plate) \
    ((plateFreeSum) + ((samples) - (maskSum)) * (plate))

// What a held view's frame estimate counts as beside the samples kept per output pixel, for each
// sample a frame traces per traced pixel (render/held_view.h says how it was measured).
#define PV_HELD_ESTIMATE_SAMPLES_PER_SPP 16.0f

// A held camera's test of the estimate's outline (FilmParams::heldOutlineTest): the kept
// samples' mean mask against the estimate's M. The mask is a Bernoulli variable (a sample's
// first hit is virtual or not), so its spread over `count` samples follows from the estimate's
// own M, with no heavy tail to fool the test (radiance has them: render/held_view.h). Beyond
// PV_HELD_MASK_SPREADS spreads the estimate's outline is wrong in this output pixel (one finer
// than a traced pixel, which the upsampling blurred or steered aside), and the estimate counts
// for less by the excess: the kept samples, traced in this very pixel, show the outline. The
// variance has a floor (that of M = 0.05), so an estimate's M of exactly 0 or 1 is not taken
// as certain: one sample alone discounts it to a fifth at most.
#define PV_HELD_MASK_SPREADS 2.0f
#define PV_HELD_MASK_VARIANCE_FLOOR 0.0475f
PV_INLINE float heldEstimateWeight(float maskSum, float count, float estimateMask,
                                   float estimateSamples) {
    float p = clamp(estimateMask, 0.0f, 1.0f);
    float spread = sqrt(max(p * (1.0f - p), PV_HELD_MASK_VARIANCE_FLOOR) / count);
    float excess = clamp(abs(maskSum / count - p) - PV_HELD_MASK_SPREADS * spread, 0.0f, 1.0f);
    return estimateSamples * (1.0f - excess) * (1.0f - excess);
}

// The held view's pixel: `estimate` (RGB the mean of Eq. 1's plate-free part, A the mask M),
// counted as `estimateSamples` samples, averaged with `count` kept samples whose sum is `sum`;
// `testOutline`: the estimate's weight after heldEstimateWeight's test.
PV_INLINE vec4 heldBlend(vec4 sum, float count, vec4 estimate, float estimateSamples,
                         bool testOutline) {
    if (count == 0.0f) return estimate;
    float w = testOutline ? heldEstimateWeight(sum.w, count, estimate.w, estimateSamples)
                          : estimateSamples;
    return (sum + w * estimate) / (count + w);
}

// The joint bilateral upsampling's range kernel (render/upsample.h), as both sides evaluate it:
// log2 to 1.3e-3 (a cubic on the mantissa: a guide needs relative colour, not digits, and a log
// per channel and pixel costs the host more than the rest of the upsampling), and exp(−t) on t
// rounded down to steps of 1/PV_RANGE_STEPS (a weight changes by < 1.6 %: the host reads it from
// a table), 0 from t = PV_RANGE_CUT on (below e^-16, 1e-7).
#define PV_RANGE_CUT 16.0f
#define PV_RANGE_STEPS 64.0f

// The virtual objects' outline at the output's resolution (render/upsample.h). The mask M
// traced at a fraction of the output is each traced pixel's coverage, and its B-spline-weighted
// mean around an output pixel (`mean`) crosses ½ within 0.05 traced pixels of a straight outline,
// but over a ramp 1.3–2 traced pixels wide: the upsampled objects look blurred by it. Where the
// taps hold a pixel mostly on an object and one mostly off it (`highest`, `lowest`), the outline
// is one the trace resolves, and the ramp is steepened by `sharpness` to about one output pixel,
// the box-filtered full-resolution mask's; finer detail (a wire narrower than a traced pixel) is
// left as traced (−1: no outline to steer to), unless a solid part of an object is among the
// taps (within two traced pixels): such a wire is steered too, and thinned. The result is the
// mask the upsampled estimate is steered to (the mask's range kernel).
#define PV_OUTLINE_SOLID 0.75f
PV_INLINE float outlineMask(float mean, float lowest, float highest, float sharpness) {
    if (!(sharpness > 1.0f) || highest < PV_OUTLINE_SOLID || lowest > 1.0f - PV_OUTLINE_SOLID)
        return -1.0f;
    return clamp(0.5f + (mean - 0.5f) * sharpness, 0.0f, 1.0f);
}

PV_INLINE float fastLog2(float v) {
    uint bits = floatBitsToUint(v);
    float exponent = float(int((bits >> 23) & 0xffu) - 127);
    float m = uintBitsToFloat((bits & 0x007fffffu) | 0x3f800000u);  // [1, 2)
    // Minimax-style cubic for log2(m) on [1, 2), exact at both ends.
    return exponent + (((0.15824871f * m - 1.05187502f) * m + 3.04788415f) * m - 2.15425784f);
}

// Global tone curves (render/tonemap.h's ToneMapOperator, in its order).
#define PV_TONE_CLAMP 0u
#define PV_TONE_REINHARD 1u
#define PV_TONE_REINHARD_EXTENDED 2u

// L_d / L_w of Reinhard's extended curve (render/tonemap.h's reinhardExtendedCurve), finite at
// L_w = 0 (where it is the slope L_white/L_max), so colour ratios are kept without a 0/0 at black.
PV_INLINE float reinhardExtendedRatio(float lw, float maxRadiance, float whiteLuminance) {
    float scale = whiteLuminance / maxRadiance;
    float l = lw * scale;
    return scale * (1.0f + l / (whiteLuminance * whiteLuminance)) / (1.0f + l);
}

// Exposed radiance (finite, ≥ 0) → linear display values (not yet sRGB-encoded). Reinhard's
// curves act on luminance and scale the colour by the luminance's ratio, so hues are kept.
PV_INLINE vec3 toneCurve(vec3 rgb, uint op, float maxRadiance, float whiteLuminance) {
    if (op == PV_TONE_CLAMP) return rgb;
    float lum = 0.2126f * rgb.r + 0.7152f * rgb.g + 0.0722f * rgb.b;
    if (op == PV_TONE_REINHARD) return rgb * (lum > 0.0f ? 1.0f / (1.0f + lum) : 1.0f);
    return rgb * reinhardExtendedRatio(lum, maxRadiance, whiteLuminance);
}

// film_display.comp: descriptor set 0.
#define PV_FILM_BINDING_PARAMS 0
// The plate L_oc, linear RGB at the output size (3 floats per pixel; texel buffer of words).
#define PV_FILM_BINDING_PLATE 1
// The frame's estimate at the traced size: RGB the mean of Eq. 1's plate-free part (denoised or
// not), A the mask M (vec4 per pixel; texel buffer). The estimate stage writes it through
// PV_FILM_BINDING_ESTIMATE_OUT.
#define PV_FILM_BINDING_ESTIMATE 2
// The upsampling's low-resolution guide: per traced pixel, log2 of the plate's area mean over
// its footprint plus ε (vec4, w unused), written by the guide stage.
#define PV_FILM_BINDING_LOW_GUIDE 3
#define PV_FILM_BINDING_LOW_GUIDE_TEXELS 4
// The held view's samples kept per output pixel (PV_BINDING_HELD_SAMPLES: Σ(RGB, M), then the
// count in x; texel buffer). Any buffer while FilmParams::held is 0.
#define PV_FILM_BINDING_HELD 5
// The 8-bit sRGB code's thresholds: [k] the smallest display-linear value whose code is ≥ k
// (k = 1 … 255; [0] unused), render/tonemap.cpp's table, so both sides round alike.
#define PV_FILM_BINDING_SRGB_THRESHOLDS 6
// The display frame: one uint per output pixel, R | G << 8 | B << 16.
#define PV_FILM_BINDING_OUTPUT 7
#define PV_FILM_BINDING_ESTIMATE_OUT 8
// The path tracer's accumulation (PV_BINDING_ACCUM_SUM and _COMPENSATION: PV_ACCUM_COUNT vec4 per
// traced pixel), read by the estimate stage. Any buffer when the host uploads the estimate.
#define PV_FILM_BINDING_ACCUM_SUM 9
#define PV_FILM_BINDING_ACCUM_COMPENSATION 10
// The denoised path: the path tracer's guides (PV_BINDING_GUIDES, for the luminance moments),
// the denoiser's input it writes (PV_DENOISE_BINDING_COLOR: the mean's RGB, the variance of its
// luminance in w) and the denoiser's output it reads (PV_DENOISE_BINDING_OUTPUT). Any buffer
// while FilmParams::denoised is 0.
#define PV_FILM_BINDING_GUIDES 11
#define PV_FILM_BINDING_SIGNAL_OUT 12
#define PV_FILM_BINDING_DENOISED 13
// The display's view baked to a table (FilmParams::viewLutSize³ RGB, red fastest; colour/
// ocio_colour.h's DisplayColourTransform::lut). Any buffer while viewLutSize is 0.
#define PV_FILM_BINDING_VIEW_LUT 14
#define PV_FILM_BINDING_COUNT 15

// The denoiser's input from the accumulation (denoised frames only; the denoiser runs between
// it and the estimate), the estimate (the means, or the denoiser's output),
// the low-resolution guide (skipped at full resolution), then the output pixels.
#define PV_FILM_STAGE_SIGNAL 0u
#define PV_FILM_STAGE_ESTIMATE 1u
#define PV_FILM_STAGE_GUIDE 2u
#define PV_FILM_STAGE_RESOLVE 3u

// Below this many samples a pixel's own variance is not trusted (SVGF switches to its spatial
// estimate below 4 frames of history); the denoiser then estimates it from the neighbourhood.
#define PV_MIN_SAMPLES_FOR_VARIANCE 4.0f

// The variance of a pixel mean's luminance from n samples: their unbiased variance over n, from
// the mean luminance y and the mean of the squared luminance y2 (never below 0); −1 (unknown)
// below PV_MIN_SAMPLES_FOR_VARIANCE samples. A macro: the host evaluates it in double.
#define PV_MEAN_LUMINANCE_VARIANCE(y, y2, n)                           \
    ((n) >= PV_MIN_SAMPLES_FOR_VARIANCE                                \
         ? ((y2) > (y) * (y) ? ((y2) - (y) * (y)) / ((n)-1.0f) : 0.0f) \
         : -1.0f)

#define PV_FILM_GROUP_X 8
#define PV_FILM_GROUP_Y 8

struct FilmParams {
    uint width;  // the output's
    uint height;
    uint traceWidth;
    uint traceHeight;
    // The range kernel exp(−d²/(2σ²)) of render/upsample.h as exp(−rangeScale·d²), d the
    // distance of the guide's log2 colours; 0: the spatial kernel alone.
    float rangeScale;
    float logEpsilon;  // ε added before the log (render/upsample.h)
    // The outline's steepening (outlineMask's `sharpness`; ≤ 1: none) and the mask's range
    // kernel exp(−maskRangeScale·(M_outline − M_traced)²) (0: none).
    float maskSharpness;
    float maskRangeScale;
    uint held;      // 1: blend the held view's samples (PV_FILM_BINDING_HELD)
    float heldEstimateSamples;  // ... counting the estimate as this many (heldEstimateSamples)
    uint heldOutlineTest;       // 1: ... after the test of its outline (heldEstimateWeight)
    // 1: the estimate is the denoiser's output (PV_FILM_BINDING_DENOISED): the filtered signal
    // and the mask's mean that goes with it (Denoiser::lastMask).
    uint denoised;
    uint toneOp;    // PV_TONE_*
    // Multiplies the composite before the curve: the exposure's 2^stops over the white balance
    // the plate's inverse applied (undone here, as PipelineRenderer's display does).
    vec3 exposure;
    float maxRadiance;
    float whiteLuminance;
    // 0: the tone curve and the sRGB encode; else the display's view (PV_FILM_BINDING_VIEW_LUT)
    // in their place, this many nodes an axis.
    uint viewLutSize;
};

PV_END

#endif
