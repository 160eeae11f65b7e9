// Random numbers and sample warps shared by the shaders and the C++ tests (which check each warp
// against its stated density with a chi-square test).
#ifndef PREVIS_SHARED_SAMPLING_H
#define PREVIS_SHARED_SAMPLING_H

#include "gpu/shaders/shared/prelude.h"

PV_BEGIN

// PCG hash (Jarzynski & Olano 2020, "Hash Functions for GPU Rendering"): a good 32-bit
// permutation, used to seed generators from (pixel, sample, dimension set) so that a sample's
// random numbers depend only on its indices: the same sample index gives the same path on every
// frame (shared/sampler.h addresses the dimensions).
PV_INLINE uint pcgHash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

PV_INLINE uint rngSeed(uint pixelIndex, uint sampleIndex, uint seed) {
    return pcgHash(pixelIndex ^ pcgHash(sampleIndex ^ pcgHash(seed)));
}

// PCG-RXS-M-XS 32-bit generator step; returns a float uniform in [0, 1).
PV_INLINE float rngNext(PV_INOUT(uint) state) {
    state = state * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    word = (word >> 22u) ^ word;
    // 24 high bits give every float in [0, 1) on a uniform grid of 2^-24.
    return float(word >> 8u) * 5.9604644775390625e-8f;
}

// Concentric map of the unit square to the unit disk (Shirley & Chiu 1997): area preserving,
// pdf 1/π on the disk.
PV_INLINE vec2 sampleUniformDiskConcentric(vec2 u) {
    vec2 o = 2.0f * u - vec2(1.0f);
    if (o.x == 0.0f && o.y == 0.0f) return vec2(0.0f);
    float r;
    float theta;
    if (abs(o.x) > abs(o.y)) {
        r = o.x;
        theta = (PV_PI / 4.0f) * (o.y / o.x);
    } else {
        r = o.y;
        theta = (PV_PI / 2.0f) - (PV_PI / 4.0f) * (o.x / o.y);
    }
    return r * vec2(cos(theta), sin(theta));
}

// Cosine-weighted hemisphere about +Z (Malley's method); pdf cosθ/π.
PV_INLINE vec3 sampleCosineHemisphere(vec2 u) {
    vec2 d = sampleUniformDiskConcentric(u);
    float z = sqrt(max(0.0f, 1.0f - d.x * d.x - d.y * d.y));
    return vec3(d.x, d.y, z);
}

PV_INLINE float cosineHemispherePdf(float cosTheta) { return max(cosTheta, 0.0f) * PV_INV_PI; }

// Uniform direction on the sphere; pdf 1/(4π).
PV_INLINE vec3 sampleUniformSphere(vec2 u) {
    float z = 1.0f - 2.0f * u.x;
    float r = sqrt(max(0.0f, 1.0f - z * z));
    float phi = PV_TWO_PI * u.y;
    return vec3(r * cos(phi), r * sin(phi), z);
}

// Uniform direction in the cone of half-angle θmax about +Z, given oneMinusCosMax = 1 − cos θmax
// (passed instead of cos θmax, which rounds to 1 for a small cone); pdf uniformConePdf.
PV_INLINE vec3 sampleUniformCone(vec2 u, float oneMinusCosMax) {
    float oneMinusCos = u.x * oneMinusCosMax;
    float sinTheta = sqrt(max(0.0f, oneMinusCos * (2.0f - oneMinusCos)));
    float phi = PV_TWO_PI * u.y;
    return vec3(sinTheta * cos(phi), sinTheta * sin(phi), 1.0f - oneMinusCos);
}

// 1 / solid angle of the cone.
PV_INLINE float uniformConePdf(float oneMinusCosMax) {
    return 1.0f / (PV_TWO_PI * oneMinusCosMax);
}

// Uniform point on a triangle as barycentrics (b1, b2) of vertices 1 and 2 (Heitz 2019,
// "A Low-Distortion Map Between Triangle and Square"); pdf 1/area.
PV_INLINE vec2 sampleUniformTriangle(vec2 u) {
    float b0;
    float b1;
    if (u.x < u.y) {
        b0 = u.x / 2.0f;
        b1 = u.y - b0;
    } else {
        b1 = u.y / 2.0f;
        b0 = u.x - b1;
    }
    return vec2(b1, 1.0f - b0 - b1);
}

// Veach's power heuristic with β = 2 for one sample from each of two strategies. Written so
// that an infinite pdf (never passed here) or two zero pdfs give a defined result.
PV_INLINE float powerHeuristic(float pdfA, float pdfB) {
    float a = pdfA * pdfA;
    float b = pdfB * pdfB;
    if (a + b <= 0.0f) return 0.0f;
    // For huge pdfs a*a overflows to +inf; inf/inf is NaN, so compare the ratio instead.
    if (isinf(a)) return isinf(b) ? 0.5f : 1.0f;
    return a / (a + b);
}

// Orthonormal basis around a unit vector n (Duff et al. 2017, "Building an Orthonormal Basis,
// Revisited"): continuous, no division by zero.
PV_INLINE void buildBasis(vec3 n, PV_OUT(vec3) t, PV_OUT(vec3) b) {
    float sign = n.z >= 0.0f ? 1.0f : -1.0f;
    float a = -1.0f / (sign + n.z);
    float c = n.x * n.y * a;
    t = vec3(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
    b = vec3(c, sign + n.y * n.y * a, -n.y);
}

PV_INLINE float luminance(vec3 c) { return dot(c, vec3(0.2126f, 0.7152f, 0.0722f)); }

PV_INLINE float maxComponent(vec3 c) { return max(c.x, max(c.y, c.z)); }

PV_END

#endif
