// denoise: edge-avoiding à-trous wavelet filter (Dammertz et al. 2010) with SVGF's edge-stopping
// weights and temporal accumulation (Schied et al. 2017, §4.1 and Eq. 3–5) on the
// albedo-demodulated signal. Four stages:
//   prepare:  D = colour / albedo and the variance of D's luminance (the pixel's own, from the
//             path tracer's moments, or a spatial estimate where it has too few samples), and
//             the packed guide texel every later tap reads (depth, normal, mask, depth slopes);
//   temporal: (preview) the previous frame's history reprojected into this frame, validated and
//             blended with D; its variance from the temporal moments;
//   atrous:   one 5×5 (or 3×3) iteration with taps 2^i pixels apart, run `iterations` times;
//   finish:   colour + (D_filtered − D)·albedo.
// Every filter sums weighted *differences* to the centre, so a region whose values are all equal
// comes out bit for bit unchanged (a flat image stays flat; a zero differential signal stays 0,
// and the composite there is the plate).
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

#include "gpu/shaders/shared/denoise.h"
#include "gpu/shaders/shared/octahedral.h"
#include "gpu/shaders/shared/sampling.h"

layout(constant_id = 0) const uint kStage = PV_DENOISE_STAGE_PREPARE;
layout(local_size_x = PV_DENOISE_GROUP_X, local_size_y = PV_DENOISE_GROUP_Y) in;

layout(binding = PV_DENOISE_BINDING_PARAMS, scalar) readonly buffer Params { DenoiseParams params; };
// Read-only arrays are texel buffers (shared/denoise.h says why).
layout(binding = PV_DENOISE_BINDING_COLOR) uniform usamplerBuffer colorTexels;
layout(binding = PV_DENOISE_BINDING_GUIDES) uniform usamplerBuffer guideTexels;
layout(binding = PV_DENOISE_BINDING_WORK, scalar) writeonly buffer Work { vec4 work[]; };
layout(binding = PV_DENOISE_BINDING_WORK_TEXELS) uniform usamplerBuffer workTexels;
layout(binding = PV_DENOISE_BINDING_OUTPUT, scalar) writeonly buffer Output { vec4 outColor[]; };
layout(binding = PV_DENOISE_BINDING_PACKED, scalar) writeonly buffer Packed { uvec4 packedOut[]; };
layout(binding = PV_DENOISE_BINDING_PACKED_TEXELS) uniform usamplerBuffer packedTexels;
layout(binding = PV_DENOISE_BINDING_HISTORY, scalar) writeonly buffer History { vec4 historyOut[]; };
layout(binding = PV_DENOISE_BINDING_HISTORY_TEXELS) uniform usamplerBuffer historyTexels;

// Demodulation divides by at least this albedo: a black surface's signal is not blown up.
const float kMinAlbedo = 0.01;
// SVGF's ε: keeps the tolerances positive where the variance or the depth gradient is zero.
const float kEpsilon = 1e-10;
// The B3-spline kernel (1, 4, 6, 4, 1)/16 of the à-trous transform, and the linear B-spline
// (1, 2, 1)/4 of the 3×3 variant.
const float kKernel5[3] = float[3](3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0);
const float kKernel3[3] = float[3](1.0 / 2.0, 1.0 / 4.0, 0.0);
// The cosine below which the normal weight's log is clamped: cos^σ_n is then e^(−69·σ_n), 0 in
// float for any σ_n ≥ 2, and log() never sees 0 (undefined in GLSL).
const float kMinCosine = 1e-30;
// Temporal validation (SVGF §4.1 compares depth, normal and mesh id): the reprojected depth may
// differ by 1 % plus the depth change over the bilinear footprint (one pixel each way); normals by
// about 25°; the mask by 1/16 (the spatial filter weighs that e^−16: a different signal). None
// of them holds for a pixel's own history when it moved less than kOwnHistoryPx: the same
// surfaces lie under it (the scene does not move; only the camera does), and guides that change
// are which of them this frame's few samples hit at an outline (a virtual object's, or any depth
// edge's), not a disocclusion. Checking them there restarted the outlines' history every few
// frames (a held camera's outline pixels kept 3.8 of 16 frames on the demo).
const float kTemporalDepthRel = 0.01;
const float kTemporalMaxMaskChange = 1.0 / 16.0;
const float kOwnHistoryPx = 0.5;
// A reprojected position within this of a pixel centre is that centre: a still camera then
// reads its history exactly instead of blurring it by a float-rounding bilinear weight.
const float kSnapPx = 1.0 / 64.0;
// Bilinear weights of the valid taps below this sum: the history is treated as disoccluded.
const float kMinHistoryWeight = 1e-3;

uint pixelCount() { return params.width * params.height; }
uint indexOf(ivec2 p) { return uint(p.y) * params.width + uint(p.x); }
vec4 fetch(usamplerBuffer b, uint i) { return uintBitsToFloat(texelFetch(b, int(i))); }
vec4 colorAt(ivec2 p) { return fetch(colorTexels, indexOf(p)); }
vec4 guideAt(ivec2 p, uint slot) { return fetch(guideTexels, indexOf(p) * PV_GUIDE_COUNT + slot); }
bool inside(ivec2 p) { return all(greaterThanEqual(p, ivec2(0))) && all(lessThan(p, ivec2(params.width, params.height))); }
vec3 albedoAt(ivec2 p) { return max(guideAt(p, PV_GUIDE_ALBEDO_DEPTH).rgb, vec3(kMinAlbedo)); }
float rawDepthAt(ivec2 p) { return guideAt(p, PV_GUIDE_ALBEDO_DEPTH).w; }
vec3 rawNormalAt(ivec2 p) {
    vec3 n = guideAt(p, PV_GUIDE_NORMAL).xyz;
    float len = length(n);
    return len > 0.0 ? n / len : vec3(0.0);
}
vec4 workAt(uint image, ivec2 p) { return fetch(workTexels, image * pixelCount() + indexOf(p)); }

// The packed guide texel (shared/denoise.h).
struct Guide {
    float depth;
    vec3 normal;  // unit, or 0 where the guide has none (then no tap weighs it)
    float mask;
    vec2 slope;
};
uint packNormal(vec3 n) {
    return n == vec3(0.0) ? PV_PACKED_NO_NORMAL : packSnorm2x16(octahedralEncode(n));
}
Guide unpackGuide(uvec4 t) {
    Guide g;
    g.depth = uintBitsToFloat(t.x);
    g.normal = t.y == PV_PACKED_NO_NORMAL ? vec3(0.0) : octahedralDecode(unpackSnorm2x16(t.y));
    g.mask = uintBitsToFloat(t.z);
    g.slope = unpackHalf2x16(t.w);
    return g;
}
Guide guideOf(uint image, ivec2 p) {
    return unpackGuide(texelFetch(packedTexels, int(image * pixelCount() + indexOf(p))));
}

// The depth change per pixel along `axis`: the smaller one-sided difference, so a pixel on a
// silhouette takes its own surface's slope, not the jump to the other surface.
float depthSlope(ivec2 p, ivec2 axis) {
    float z = rawDepthAt(p);
    float slope = PV_FLOAT_MAX;
    if (inside(p + axis)) slope = abs(rawDepthAt(p + axis) - z);
    if (inside(p - axis)) slope = min(slope, abs(z - rawDepthAt(p - axis)));
    return slope == PV_FLOAT_MAX ? 0.0 : slope;
}

// −log of SVGF's geometric edge-stopping weight between p and q = p + offset (Eq. 4 and 5), and
// of the mask's (shared/denoise.h: virtual objects and the real set are different signals). The
// normal term cos^σ_n is exp(σ_n·log cos), so a tap costs one exp() in all.
float geometryExponent(Guide gp, Guide gq, ivec2 offset) {
    float tolerance = params.sigmaDepth * dot(gp.slope, abs(vec2(offset))) + kEpsilon;
    float e = abs(gp.depth - gq.depth) / tolerance + params.sigmaMask * abs(gp.mask - gq.mask);
    if (params.sigmaNormal > 0.0)
        e -= params.sigmaNormal * log(max(dot(gp.normal, gq.normal), kMinCosine));
    return e;
}

void prepare(ivec2 p) {
    vec4 c = colorAt(p);
    vec3 a = albedoAt(p);
    Guide gp;
    gp.depth = rawDepthAt(p);
    gp.normal = rawNormalAt(p);
    gp.mask = guideAt(p, PV_GUIDE_MOMENTS).w;
    gp.slope = vec2(depthSlope(p, ivec2(1, 0)), depthSlope(p, ivec2(0, 1)));
    packedOut[params.packedImage * pixelCount() + indexOf(p)] =
        uvec4(floatBitsToUint(gp.depth), packNormal(gp.normal), floatBitsToUint(gp.mask),
              packHalf2x16(gp.slope));
    float variance = c.w / (luminance(a) * luminance(a));
    if (c.w < 0.0) {
        // Too few samples for the pixel's own variance: the luminance variance over the 5×5
        // neighbourhood on the same surface (SVGF §4.3 estimates it spatially the same way).
        // Neighbours' packed texels are being written by this dispatch: read the raw guides.
        float sumW = 0.0, m1 = 0.0, m2 = 0.0;
        for (int dy = -2; dy <= 2; ++dy) {
            for (int dx = -2; dx <= 2; ++dx) {
                ivec2 q = p + ivec2(dx, dy);
                if (!inside(q)) continue;
                Guide gq;
                gq.depth = rawDepthAt(q);
                gq.normal = rawNormalAt(q);
                gq.mask = guideAt(q, PV_GUIDE_MOMENTS).w;
                float w = exp(-geometryExponent(gp, gq, ivec2(dx, dy)));
                float l = luminance(colorAt(q).rgb / albedoAt(q));
                sumW += w;
                m1 += w * l;
                m2 += w * l * l;
            }
        }
        // sumW is 0 only for a guide without a normal (no surface): no estimate, no filtering.
        m1 /= max(sumW, kEpsilon);
        variance = max(0.0, m2 / max(sumW, kEpsilon) - m1 * m1);
    }
    work[PV_DENOISE_WORK_PREPARED * pixelCount() + indexOf(p)] = vec4(c.rgb / a, variance);
}

// SVGF §4.1: this frame's demodulated signal D blended with the previous frame's history,
// reprojected through the two cameras (pinhole: the guides' depth is the distance along the
// pixel centre's ray), where depth, normal and mask agree.
void temporal(ivec2 p) {
    vec4 current = workAt(PV_DENOISE_WORK_PREPARED, p);
    Guide gp = guideOf(params.packedImage, p);
    const uint prevPacked = 1u - params.packedImage;
    const uint histIn = params.historyIn;
    vec4 h0 = vec4(0.0), h1 = vec4(0.0), h2 = vec4(0.0);
    float sumW = 0.0;
    if (params.historyValid != 0u) {
        vec2 ndc = vec2((float(p.x) + 0.5) / float(params.width) * 2.0 - 1.0,
                        1.0 - (float(p.y) + 0.5) / float(params.height) * 2.0);
        vec3 dir = normalize(vec3(ndc * params.tanHalfFov, -1.0));
        vec3 prev = (params.prevCameraFromCamera * vec4(dir * gp.depth, 1.0)).xyz;
        float prevDistance = length(prev);
        if (prev.z < 0.0) {
            vec2 prevNdc = prev.xy / (-prev.z) / params.prevTanHalfFov;
            vec2 q = vec2((prevNdc.x + 1.0) * 0.5 * float(params.width),
                          (1.0 - prevNdc.y) * 0.5 * float(params.height)) - 0.5;
            vec2 rounded = round(q);
            q = mix(q, rounded, lessThan(abs(q - rounded), vec2(kSnapPx)));
            const bool nearlyStill = all(lessThan(abs(q - vec2(p)), vec2(kOwnHistoryPx)));
            ivec2 q0 = ivec2(floor(q));
            vec2 f = q - vec2(q0);
            float tolerance = kTemporalDepthRel * gp.depth + gp.slope.x + gp.slope.y;
            for (int k = 0; k < 4; ++k) {
                ivec2 o = ivec2(k & 1, k >> 1);
                float w = (o.x == 1 ? f.x : 1.0 - f.x) * (o.y == 1 ? f.y : 1.0 - f.y);
                ivec2 t = q0 + o;
                if (w <= 0.0 || !inside(t)) continue;
                Guide gq = guideOf(prevPacked, t);
                const bool ownHistory = nearlyStill && t == p;
                if (!ownHistory && (abs(gq.depth - prevDistance) > tolerance ||
                                    dot(gp.normal, gq.normal) < PV_HISTORY_MIN_NORMAL_COS ||
                                    abs(gp.mask - gq.mask) > kTemporalMaxMaskChange))
                    continue;
                uint i = (histIn * pixelCount() + indexOf(t)) * PV_HISTORY_TEXELS;
                h0 += w * fetch(historyTexels, i);
                h1 += w * fetch(historyTexels, i + 1u);
                h2 += w * fetch(historyTexels, i + 2u);
                sumW += w;
            }
        }
    }
    float l = luminance(current.rgb);
    const vec4 signalAndMask = vec4(colorAt(p).rgb, gp.mask);
    vec4 out0, out1, out2;
    if (sumW < kMinHistoryWeight) {
        // Disoccluded, off screen or reset: the history starts with this frame.
        out0 = vec4(current.rgb, 1.0);
        out1 = vec4(l, l * l, current.w, 1.0);
        out2 = signalAndMask;
    } else {
        // Weights summing to 1 keep equal histories exact: Σ w·h / Σ w = h when w = 1.
        h0 /= sumW;
        h1 /= sumW;
        h2 /= sumW;
        float n = h0.w;
        // SVGF's α, with a plain mean while the history is shorter than 1/α.
        float alpha = max(params.temporalAlpha, 1.0 / (n + 1.0));
        // x + α(y − x) gives x exactly when y = x: a still frame leaves its history unchanged.
        out0 = vec4(h0.rgb + alpha * (current.rgb - h0.rgb), min(n + 1.0, params.maxHistory));
        out1 = vec4(h1.x + alpha * (l - h1.x), h1.y + alpha * (l * l - h1.y),
                    h1.z + alpha * (current.w - h1.z),
                    (1.0 - alpha) * (1.0 - alpha) * h1.w + alpha * alpha);
        out2 = h2 + alpha * (signalAndMask - h2);
    }
    uint o = ((1u - histIn) * pixelCount() + indexOf(p)) * PV_HISTORY_TEXELS;
    historyOut[o] = out0;
    historyOut[o + 1u] = out1;
    historyOut[o + 2u] = out2;
    // The variance of the integrated mean. Preview traces the same sample sequence every frame,
    // so successive frames' noise is correlated (ρ = 1 with a still camera) and averaging them
    // need not reduce it. With σ² the frames' own variance (EMA), g = Σ w² the EMA's weights and
    // s² = the EMA's luminance variance across frames, E[s²] = (1 − ρ)(1 − g)σ² and the mean's
    // variance is σ²(ρ + (1 − ρ)g) = σ² − E[s²]: σ² for identical frames, gσ² for independent
    // ones (its floor).
    precise float temporalVariance = max(0.0, out1.y - out1.x * out1.x);
    float variance = max(out1.w * out1.z, out1.z - temporalVariance);
    work[PV_DENOISE_WORK_TEMPORAL * pixelCount() + indexOf(p)] = vec4(out0.rgb, variance);
}

void atrous(ivec2 p) {
    vec4 centre = workAt(params.inImage, p);
    // SVGF Eq. 5 uses the variance blurred by a 3×3 Gaussian: one noisy estimate alone would let
    // a lucky pixel stop all filtering.
    float variance = 0.0, varianceWeight = 0.0;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 q = p + ivec2(dx, dy);
            if (!inside(q)) continue;
            float w = kKernel5[abs(dx) + 1] * kKernel5[abs(dy) + 1];
            variance += w * workAt(params.inImage, q).w;
            varianceWeight += w;
        }
    }
    float luminanceTolerance = params.sigmaLuminance * sqrt(variance / varianceWeight) + kEpsilon;
    Guide gp = guideOf(params.packedImage, p);
    float lp = luminance(centre.rgb);
    const int radius = int(params.kernelRadius);
    const bool wide = radius == 2;
    float sumW = wide ? kKernel5[0] * kKernel5[0] : kKernel3[0] * kKernel3[0];
    vec3 change = vec3(0.0);
    float filteredVariance = sumW * sumW * centre.w;
    for (int dy = -radius; dy <= radius; ++dy) {
        for (int dx = -radius; dx <= radius; ++dx) {
            if (dx == 0 && dy == 0) continue;
            ivec2 offset = ivec2(dx, dy) * int(params.stepPx);
            ivec2 q = p + offset;
            if (!inside(q)) continue;
            vec4 v = workAt(params.inImage, q);
            Guide gq = guideOf(params.packedImage, q);
            float wl = abs(lp - luminance(v.rgb)) / luminanceTolerance;
            float h = wide ? kKernel5[abs(dx)] * kKernel5[abs(dy)]
                           : kKernel3[abs(dx)] * kKernel3[abs(dy)];
            float w = h * exp(-wl - geometryExponent(gp, gq, offset));
            change += w * (v.rgb - centre.rgb);
            sumW += w;
            filteredVariance += w * w * v.w;
        }
    }
    // The variance of the weighted mean (SVGF Eq. 6), for the next iteration's tolerance.
    work[params.outImage * pixelCount() + indexOf(p)] =
        vec4(centre.rgb + change / sumW, filteredVariance / (sumW * sumW));
}

// The spatial filter's change to the demodulated signal, remodulated, on the signal it filtered:
// this frame's, or after a temporal stage the history's mean of the signal itself (with the
// mask's mean that goes with it), which this frame's albedo does not scale.
void finish(ivec2 p) {
    if (params.temporal != 0u) {
        vec3 change = workAt(params.inImage, p).rgb - workAt(PV_DENOISE_WORK_TEMPORAL, p).rgb;
        uint o = ((1u - params.historyIn) * pixelCount() + indexOf(p)) * PV_HISTORY_TEXELS;
        vec4 mean = fetch(historyTexels, o + 2u);
        outColor[indexOf(p)] = vec4(mean.rgb + change * albedoAt(p), mean.w);
        return;
    }
    vec3 change = workAt(params.inImage, p).rgb - workAt(PV_DENOISE_WORK_PREPARED, p).rgb;
    outColor[indexOf(p)] =
        vec4(colorAt(p).rgb + change * albedoAt(p), guideAt(p, PV_GUIDE_MOMENTS).w);
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (!inside(p)) return;
    if (kStage == PV_DENOISE_STAGE_PREPARE) prepare(p);
    else if (kStage == PV_DENOISE_STAGE_TEMPORAL) temporal(p);
    else if (kStage == PV_DENOISE_STAGE_ATROUS) atrous(p);
    else finish(p);
}
