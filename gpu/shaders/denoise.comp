// denoise: edge-avoiding à-trous wavelet filter (Dammertz et al. 2010) with SVGF's edge-stopping
// weights (Schied et al. 2017, Eq. 3–5) on the albedo-demodulated signal. Three stages:
//   prepare: D = colour / albedo and the variance of D's luminance (the pixel's own, from the
//            path tracer's moments, or a spatial estimate where it has too few samples);
//   atrous:  one 5×5 iteration with taps 2^i pixels apart, run five times (ping-pong);
//   finish:  colour + (D_filtered − D)·albedo.
// Every filter sums weighted *differences* to the centre, so a region whose values are all equal
// comes out bit for bit unchanged (a flat image stays flat; a zero differential signal stays 0,
// and the composite there is the plate).
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

#include "shared/denoise.h"
#include "shared/sampling.h"

layout(constant_id = 0) const uint kStage = PV_DENOISE_STAGE_PREPARE;
layout(local_size_x = PV_DENOISE_GROUP_SIZE, local_size_y = PV_DENOISE_GROUP_SIZE) in;

layout(binding = PV_DENOISE_BINDING_PARAMS, scalar) readonly buffer Params { DenoiseParams params; };
// Read-only arrays are texel buffers (shared/denoise.h says why).
layout(binding = PV_DENOISE_BINDING_COLOR) uniform usamplerBuffer colorTexels;
layout(binding = PV_DENOISE_BINDING_GUIDES) uniform usamplerBuffer guideTexels;
layout(binding = PV_DENOISE_BINDING_WORK, scalar) writeonly buffer Work { vec4 work[]; };
layout(binding = PV_DENOISE_BINDING_WORK_TEXELS) uniform usamplerBuffer workTexels;
layout(binding = PV_DENOISE_BINDING_OUTPUT, scalar) writeonly buffer Output { vec4 outColor[]; };

// Demodulation divides by at least this albedo: a black surface's signal is not blown up.
const float kMinAlbedo = 0.01;
// SVGF's ε: keeps the tolerances positive where the variance or the depth gradient is zero.
const float kEpsilon = 1e-10;
// The B3-spline kernel (1, 4, 6, 4, 1)/16 of the à-trous transform.
const float kKernel[3] = float[3](3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0);

uint indexOf(ivec2 p) { return uint(p.y) * params.width + uint(p.x); }
vec4 fetch(usamplerBuffer b, uint i) { return uintBitsToFloat(texelFetch(b, int(i))); }
vec4 colorAt(ivec2 p) { return fetch(colorTexels, indexOf(p)); }
vec4 guideAt(ivec2 p, uint slot) { return fetch(guideTexels, indexOf(p) * PV_GUIDE_COUNT + slot); }
bool inside(ivec2 p) { return all(greaterThanEqual(p, ivec2(0))) && all(lessThan(p, ivec2(params.width, params.height))); }
vec3 albedoAt(ivec2 p) { return max(guideAt(p, PV_GUIDE_ALBEDO_DEPTH).rgb, vec3(kMinAlbedo)); }
float depthAt(ivec2 p) { return guideAt(p, PV_GUIDE_ALBEDO_DEPTH).w; }
float maskAt(ivec2 p) { return guideAt(p, PV_GUIDE_MOMENTS).w; }
vec3 normalAt(ivec2 p) {
    vec3 n = guideAt(p, PV_GUIDE_NORMAL).xyz;
    float len = length(n);
    return len > 0.0 ? n / len : vec3(0.0);
}
vec4 workAt(uint image, ivec2 p) { return fetch(workTexels, image * params.width * params.height + indexOf(p)); }

// The depth change per pixel along `axis`: the smaller one-sided difference, so a pixel on a
// silhouette takes its own surface's slope, not the jump to the other surface.
float depthSlope(ivec2 p, ivec2 axis) {
    float z = depthAt(p);
    float slope = PV_FLOAT_MAX;
    if (inside(p + axis)) slope = abs(depthAt(p + axis) - z);
    if (inside(p - axis)) slope = min(slope, abs(z - depthAt(p - axis)));
    return slope == PV_FLOAT_MAX ? 0.0 : slope;
}

// SVGF's geometric edge-stopping weight between p and q = p + offset (Eq. 4 and 5), and the
// mask's (shared/denoise.h: virtual objects and the real set are different signals).
float geometryWeight(ivec2 p, ivec2 q, ivec2 offset, vec2 slope, vec3 np) {
    float tolerance = params.sigmaDepth * dot(slope, abs(vec2(offset))) + kEpsilon;
    float wz = abs(depthAt(p) - depthAt(q)) / tolerance;
    float wm = params.sigmaMask * abs(maskAt(p) - maskAt(q));
    float wn = pow(max(0.0, dot(np, normalAt(q))), params.sigmaNormal);
    return exp(-wz - wm) * wn;
}

void prepare(ivec2 p) {
    vec4 c = colorAt(p);
    vec3 a = albedoAt(p);
    float variance = c.w / (luminance(a) * luminance(a));
    if (c.w < 0.0) {
        // Too few samples for the pixel's own variance: the luminance variance over the 5×5
        // neighbourhood on the same surface (SVGF §4.3 estimates it spatially the same way).
        // HOOK: the convergence meter's per-pixel variance replaces this when it lands.
        vec2 slope = vec2(depthSlope(p, ivec2(1, 0)), depthSlope(p, ivec2(0, 1)));
        vec3 np = normalAt(p);
        float sumW = 0.0, m1 = 0.0, m2 = 0.0;
        for (int dy = -2; dy <= 2; ++dy) {
            for (int dx = -2; dx <= 2; ++dx) {
                ivec2 q = p + ivec2(dx, dy);
                if (!inside(q)) continue;
                float w = geometryWeight(p, q, ivec2(dx, dy), slope, np);
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
    work[indexOf(p)] = vec4(c.rgb / a, variance);
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
            float w = kKernel[abs(dx) + 1] * kKernel[abs(dy) + 1];
            variance += w * workAt(params.inImage, q).w;
            varianceWeight += w;
        }
    }
    float luminanceTolerance = params.sigmaLuminance * sqrt(variance / varianceWeight) + kEpsilon;
    vec2 slope = vec2(depthSlope(p, ivec2(1, 0)), depthSlope(p, ivec2(0, 1)));
    vec3 np = normalAt(p);
    float lp = luminance(centre.rgb);
    float sumW = kKernel[0] * kKernel[0];
    vec3 change = vec3(0.0);
    float filteredVariance = sumW * sumW * centre.w;
    for (int dy = -2; dy <= 2; ++dy) {
        for (int dx = -2; dx <= 2; ++dx) {
            if (dx == 0 && dy == 0) continue;
            ivec2 offset = ivec2(dx, dy) * int(params.stepPx);
            ivec2 q = p + offset;
            if (!inside(q)) continue;
            vec4 v = workAt(params.inImage, q);
            float wl = abs(lp - luminance(v.rgb)) / luminanceTolerance;
            float w = kKernel[abs(dx)] * kKernel[abs(dy)] * exp(-wl) *
                      geometryWeight(p, q, offset, slope, np);
            change += w * (v.rgb - centre.rgb);
            sumW += w;
            filteredVariance += w * w * v.w;
        }
    }
    // The variance of the weighted mean (SVGF Eq. 6), for the next iteration's tolerance.
    work[params.outImage * params.width * params.height + indexOf(p)] =
        vec4(centre.rgb + change / sumW, filteredVariance / (sumW * sumW));
}

void finish(ivec2 p) {
    vec3 change = workAt(params.inImage, p).rgb - workAt(0u, p).rgb;
    outColor[indexOf(p)] = vec4(colorAt(p).rgb + change * albedoAt(p), 0.0);
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (!inside(p)) return;
    if (kStage == PV_DENOISE_STAGE_PREPARE) prepare(p);
    else if (kStage == PV_DENOISE_STAGE_ATROUS) atrous(p);
    else finish(p);
}
