// film_display: the preview frame as the monitor shows it, made on the device (render/
// display_pass.h). Four stages:
//   signal:  (denoised frames) per traced pixel, the denoiser's input: the mean of Eq. 1's
//            plate-free part and the variance of its luminance from the path tracer's moments;
//   estimate: per traced pixel, the means of Eq. 1's plate-free part (or the denoiser's output)
//            and of the mask from the path tracer's compensated sums;
//   guide:   per traced pixel, log2 of the plate's area mean over its footprint plus ε: the low-
//            resolution side of the joint bilateral upsampling's range kernel;
//   resolve: per output pixel, the traced estimate upsampled (render/upsample.h's kernel: a
//            cubic B-spline on the traced grid times the range kernel on the plate), blended with
//            the held view's samples, composited with the plate by Eq. 1, tone mapped and
//            encoded as 8-bit sRGB, or shown through a display's view ([output.colour]).
// render/upsample.cpp, render/held_view.cpp and render/tonemap.cpp run the same steps on the
// host for the float images `previs render` writes; tests/integrator/display_frame_test.cpp holds
// the two within one 8-bit code.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

#include "gpu/shaders/shared/denoise.h"
#include "gpu/shaders/shared/composite.h"
#include "gpu/shaders/shared/sampling.h"
#include "gpu/shaders/shared/scene_types.h"

layout(constant_id = 0) const uint kStage = PV_FILM_STAGE_RESOLVE;
layout(local_size_x = PV_FILM_GROUP_X, local_size_y = PV_FILM_GROUP_Y) in;

layout(binding = PV_FILM_BINDING_PARAMS, scalar) readonly buffer Params { FilmParams params; };
layout(binding = PV_FILM_BINDING_PLATE) uniform usamplerBuffer plateTexels;
layout(binding = PV_FILM_BINDING_ESTIMATE) uniform usamplerBuffer estimateTexels;
layout(binding = PV_FILM_BINDING_LOW_GUIDE, scalar) writeonly buffer LowGuide { vec4 lowGuide[]; };
layout(binding = PV_FILM_BINDING_LOW_GUIDE_TEXELS) uniform usamplerBuffer lowGuideTexels;
layout(binding = PV_FILM_BINDING_HELD, scalar) readonly buffer Held { vec4 held[]; };
layout(binding = PV_FILM_BINDING_SRGB_THRESHOLDS) uniform usamplerBuffer srgbThresholds;
layout(binding = PV_FILM_BINDING_OUTPUT, scalar) writeonly buffer Output { uint display[]; };
layout(binding = PV_FILM_BINDING_ESTIMATE_OUT, scalar) writeonly buffer EstimateOut { vec4 estimateOut[]; };
layout(binding = PV_FILM_BINDING_ACCUM_SUM, scalar) readonly buffer AccumSum { vec4 accumSum[]; };
layout(binding = PV_FILM_BINDING_ACCUM_COMPENSATION, scalar) readonly buffer AccumCompensation {
    vec4 accumCompensation[];
};
layout(binding = PV_FILM_BINDING_GUIDES, scalar) readonly buffer Guides { vec4 guides[]; };
layout(binding = PV_FILM_BINDING_SIGNAL_OUT, scalar) writeonly buffer SignalOut { vec4 signalOut[]; };
layout(binding = PV_FILM_BINDING_DENOISED, scalar) readonly buffer Denoised { vec4 denoised[]; };
layout(binding = PV_FILM_BINDING_VIEW_LUT, scalar) readonly buffer ViewLut { vec3 viewLut[]; };

// Range weights summing below this fraction of the spatial ones: the pixel's colour matches no
// neighbour (a detail finer than the traced grid) and the spatial kernel alone is used.
const float kMinRangeWeightFraction = 1e-4;

vec4 fetch(usamplerBuffer b, uint i) { return uintBitsToFloat(texelFetch(b, int(i))); }

vec3 plateAt(uint x, uint y) {
    uint i = y * params.width + x;
    return vec3(uintBitsToFloat(texelFetch(plateTexels, int(3u * i)).x),
                uintBitsToFloat(texelFetch(plateTexels, int(3u * i + 1u)).x),
                uintBitsToFloat(texelFetch(plateTexels, int(3u * i + 2u)).x));
}

vec3 logGuide(vec3 c) {
    c = max(c, vec3(0.0)) + params.logEpsilon;
    return vec3(fastLog2(c.r), fastLog2(c.g), fastLog2(c.b));
}

// The fraction of output pixel `x`'s extent [x, x + 1) inside [a, b).
float overlap(uint x, float a, float b) { return max(0.0, min(b, float(x) + 1.0) - max(a, float(x))); }

// A compensated sum of slot `slot` of traced pixel `i` (render/film.h's Accumulation::value).
vec4 accumulated(uint i, uint slot) {
    uint at = i * PV_ACCUM_COUNT + slot;
    return accumSum[at] - accumCompensation[at];
}

// The samples that count (the mixed sum's w: dropped samples are not in it) divide the sums; a
// pixel without samples is mask 0: the plate.
vec4 compositeMean(uint i) {
    float n = accumulated(i, PV_ACCUM_MIXED).w;
    return n > 0.0 ? accumulated(i, PV_ACCUM_COMPOSITE) / n : vec4(0.0);
}

// The denoiser's input: the mean and the variance of its luminance, from the second moment the
// path tracer keeps per pixel (as render/film.cpp's host version).
void signalStage(uvec2 q) {
    uint i = q.y * params.traceWidth + q.x;
    float n = accumulated(i, PV_ACCUM_MIXED).w;
    vec3 mean = compositeMean(i).rgb;
    float y = luminance(mean);
    float y2 = guides[i * PV_GUIDE_COUNT + PV_GUIDE_MOMENTS][PV_ACCUM_COMPOSITE];
    signalOut[i] = vec4(mean, PV_MEAN_LUMINANCE_VARIANCE(y, y2, n));
}

void estimateStage(uvec2 q) {
    uint i = q.y * params.traceWidth + q.x;
    vec4 mean = compositeMean(i);
    estimateOut[i] = params.denoised != 0u ? denoised[i] : mean;
}

void guideStage(uvec2 q) {
    float stepX = float(params.width) / float(params.traceWidth);
    float stepY = float(params.height) / float(params.traceHeight);
    float ax = float(q.x) * stepX, bx = ax + stepX, ay = float(q.y) * stepY, by = ay + stepY;
    vec3 sum = vec3(0.0);
    for (uint y = uint(ay); y < min(uint(ceil(by)), params.height); ++y) {
        float wy = overlap(y, ay, by);
        for (uint x = uint(ax); x < min(uint(ceil(bx)), params.width); ++x)
            sum += wy * overlap(x, ax, bx) * plateAt(x, y);
    }
    lowGuide[q.y * params.traceWidth + q.x] = vec4(logGuide(sum / (stepX * stepY)), 0.0);
}

// The uniform cubic B-spline's four weights at fraction t past the second tap.
vec4 cubicBSpline(float t) {
    float t2 = t * t, t3 = t2 * t, s = 1.0 - t;
    return vec4(s * s * s, 3.0 * t3 - 6.0 * t2 + 4.0, -3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0, t3) /
           6.0;
}

// The output pixel's centre on the traced grid (whose pixel centres are at integers): the first
// of its four taps and their weights, 0 for taps off the grid.
void taps(uint x, uint full, uint low, out int first, out vec4 w) {
    float u = (float(x) + 0.5) * float(low) / float(full) - 0.5;
    float base = floor(u);
    first = int(base) - 1;
    w = cubicBSpline(u - base);
    for (int k = 0; k < 4; ++k)
        if (first + k < 0 || first + k >= int(low)) w[k] = 0.0;
}

vec4 upsampled(uvec2 p, vec3 plate) {
    if (params.traceWidth == params.width && params.traceHeight == params.height)
        return fetch(estimateTexels, p.y * params.width + p.x);
    int i0, j0;
    vec4 wx, wy;
    taps(p.x, params.width, params.traceWidth, i0, wx);
    taps(p.y, params.height, params.traceHeight, j0, wy);
    vec3 g = logGuide(plate);
    // One fetch per tap: the spatial kernel and the mask's extremes first (the outline needs
    // the spatial mean of the mask), then the range kernel on the kept values.
    vec4 values[16];
    float plateDistance[16], spatialWeights[16];
    vec4 spatial = vec4(0.0);
    float spatialWeight = 0.0, lowest = 1.0, highest = 0.0;
    for (int k = 0; k < 16; ++k) {
        float ws = wx[k & 3] * wy[k >> 2];
        spatialWeights[k] = ws;
        if (ws == 0.0) continue;
        uint q = uint(j0 + (k >> 2)) * params.traceWidth + uint(i0 + (k & 3));
        vec4 v = fetch(estimateTexels, q);
        vec3 d = g - fetch(lowGuideTexels, q).xyz;
        values[k] = v;
        plateDistance[k] = params.rangeScale * dot(d, d);
        spatial += ws * v;
        spatialWeight += ws;
        lowest = min(lowest, v.a);
        highest = max(highest, v.a);
    }
    float outline = params.maskRangeScale > 0.0
                        ? outlineMask(spatial.a / spatialWeight, lowest, highest, params.maskSharpness)
                        : -1.0;
    vec4 ranged = vec4(0.0);
    float rangedWeight = 0.0;
    for (int k = 0; k < 16; ++k) {
        float ws = spatialWeights[k];
        if (ws == 0.0) continue;
        float t = plateDistance[k];
        if (outline >= 0.0) t += params.maskRangeScale * (outline - values[k].a) * (outline - values[k].a);
        float wr = t < PV_RANGE_CUT ? ws * exp(-floor(t * PV_RANGE_STEPS) / PV_RANGE_STEPS) : 0.0;
        ranged += wr * values[k];
        rangedWeight += wr;
    }
    if (rangedWeight > kMinRangeWeightFraction * spatialWeight) return ranged / rangedWeight;
    return spatial / spatialWeight;
}

// lround(255 · sRGB(v)) exactly as the host's encodeSrgb8: the code from the formula, then moved
// to the one whose thresholds bracket v (pow's rounding is far below a code).
uint encodeSrgb8(float v) {
    if (!(v > 0.0)) return 0u;
    if (v >= 1.0) return 255u;
    float e = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
    uint code = uint(clamp(round(e * 255.0), 0.0, 255.0));
    if (code > 0u && v < uintBitsToFloat(texelFetch(srgbThresholds, int(code)).x)) return code - 1u;
    if (code < 255u && v >= uintBitsToFloat(texelFetch(srgbThresholds, int(code + 1u)).x))
        return code + 1u;
    return code;
}

// The display's view in place of the curve and the sRGB encode, as OCIO's processor runs it on
// the host (colour/ocio_colour.h's DisplayColourTransform::lut): ACEScct per channel, clamped to
// the table's domain, then tetrahedral interpolation between the cube's nodes.
vec3 acescct(vec3 v) {
    vec3 lin = 10.5402377416545 * v + 0.0729055341958355;
    vec3 logarithmic = (log2(max(v, vec3(1e-30))) + 9.72) / 17.52;
    return mix(logarithmic, lin, lessThanEqual(v, vec3(0.0078125)));
}

vec3 viewNode(uvec3 i) {
    uint n = params.viewLutSize;
    return viewLut[(i.b * n + i.g) * n + i.r];
}

vec3 throughView(vec3 linear) {
    float last = float(params.viewLutSize - 1u);
    vec3 x = clamp(acescct(linear), 0.0, 1.0) * last;
    vec3 base = min(floor(x), vec3(last - 1.0));
    vec3 f = x - base;
    uvec3 i = uvec3(base);
    vec3 c000 = viewNode(i), c111 = viewNode(i + uvec3(1u));
    // The tetrahedron holding f: walk from c000 to c111 along the axes, largest fraction first.
    uvec3 first, second;
    vec3 w;  // the weights of c000 → first, first → second, second → c111
    if (f.r > f.g) {
        if (f.g > f.b) {
            first = uvec3(1u, 0u, 0u), second = uvec3(1u, 1u, 0u), w = vec3(f.r, f.g, f.b);
        } else if (f.r > f.b) {
            first = uvec3(1u, 0u, 0u), second = uvec3(1u, 0u, 1u), w = vec3(f.r, f.b, f.g);
        } else {
            first = uvec3(0u, 0u, 1u), second = uvec3(1u, 0u, 1u), w = vec3(f.b, f.r, f.g);
        }
    } else if (f.b > f.g) {
        first = uvec3(0u, 0u, 1u), second = uvec3(0u, 1u, 1u), w = vec3(f.b, f.g, f.r);
    } else if (f.b > f.r) {
        first = uvec3(0u, 1u, 0u), second = uvec3(0u, 1u, 1u), w = vec3(f.g, f.b, f.r);
    } else {
        first = uvec3(0u, 1u, 0u), second = uvec3(1u, 1u, 0u), w = vec3(f.g, f.r, f.b);
    }
    return (1.0 - w.x) * c000 + (w.x - w.y) * viewNode(i + first) +
           (w.y - w.z) * viewNode(i + second) + w.z * c111;
}

// A display code value in [0, 1] to 8 bits, as OCIO's processor writes UINT8.
uint code8(float v) { return uint(clamp(v * 255.0 + 0.5, 0.0, 255.0)); }

void resolveStage(uvec2 p) {
    uint i = p.y * params.width + p.x;
    vec3 plate = plateAt(p.x, p.y);
    vec4 estimate = upsampled(p, plate);
    if (params.held != 0u)
        estimate = heldBlend(held[2u * i], held[2u * i + 1u].x, estimate,
                             params.heldEstimateSamples, params.heldOutlineTest != 0u);
    vec3 composite = PV_COMPOSITE_SUM(estimate.rgb, estimate.a, 1.0, plate);
    bvec3 bad = bvec3(uvec3(isnan(composite)) | uvec3(isinf(composite)));
    composite = mix(max(composite, vec3(0.0)), vec3(0.0), bad) * params.exposure;
    if (params.viewLutSize != 0u) {
        vec3 shown = throughView(composite);
        display[i] = code8(shown.r) | (code8(shown.g) << 8) | (code8(shown.b) << 16);
        return;
    }
    vec3 linear = toneCurve(composite, params.toneOp, params.maxRadiance, params.whiteLuminance);
    display[i] = encodeSrgb8(linear.r) | (encodeSrgb8(linear.g) << 8) | (encodeSrgb8(linear.b) << 16);
}

void main() {
    uvec2 p = gl_GlobalInvocationID.xy;
    bool traced = p.x < params.traceWidth && p.y < params.traceHeight;
    if (kStage == PV_FILM_STAGE_SIGNAL) {
        if (traced) signalStage(p);
    } else if (kStage == PV_FILM_STAGE_ESTIMATE) {
        if (traced) estimateStage(p);
    } else if (kStage == PV_FILM_STAGE_GUIDE) {
        if (traced) guideStage(p);
    } else if (p.x < params.width && p.y < params.height) {
        resolveStage(p);
    }
}
