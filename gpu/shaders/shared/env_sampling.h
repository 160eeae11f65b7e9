// Equirectangular environment map lookup and importance sampling, shared by the shaders and the
// C++ code (scene/environment_sampler.h), so the CPU tests check the very math the GPU runs.
//
// Orientation (DESIGN.md §4): u = 0.5 + atan2(d.z, d.x)/(2π), v = 0.5 − asin(d.y)/π, v = 0 the
// top row; θ = πv is the polar angle from +Y. Radiance is piecewise constant per texel (nearest
// lookup), the same function the sampling density is built from, so sample and pdf agree exactly.
//
// The includer defines, before including this file:
//   PV_ENV_RADIANCE(i)        vec3, texel i = row * width + column, row 0 at the top
//   PV_ENV_MARGINAL_CDF(i)    float, i in [0, height]: cdf[0] = 0, cdf[height] = 1
//   PV_ENV_CONDITIONAL_CDF(i) float, row r's cdf at r * (width + 1) + [0, width]
// (tables from buildEnvironmentDistribution in scene/environment_map.h). The map's scale is
// applied by the caller.
#ifndef PREVIS_SHARED_ENV_SAMPLING_H
#define PREVIS_SHARED_ENV_SAMPLING_H

#include "gpu/shaders/shared/prelude.h"

#if !defined(PV_ENV_RADIANCE) || !defined(PV_ENV_MARGINAL_CDF) || \
    !defined(PV_ENV_CONDITIONAL_CDF)
#error "define PV_ENV_RADIANCE, PV_ENV_MARGINAL_CDF and PV_ENV_CONDITIONAL_CDF first"
#endif

PV_BEGIN

// The map's rotation about +Y as (cos, sin) of its angle, counter-clockwise seen from above:
// computed once per map (FrameParams::envRotationCos/Sin), not per lookup.
PV_INLINE vec2 envRotationCosSin(float angleRad) { return vec2(cos(angleRad), sin(angleRad)); }

// Rotation about +Y by the angle whose (cos, sin) is cs (right-handed about +Y).
PV_INLINE vec3 envRotateY(vec3 d, vec2 cs) {
    return vec3(cs.x * d.x + cs.y * d.z, d.y, -cs.y * d.x + cs.x * d.z);
}

// The inverse rotation: world to map.
PV_INLINE vec3 envUnrotateY(vec3 d, vec2 cs) { return envRotateY(d, vec2(cs.x, -cs.y)); }

PV_INLINE vec2 envDirectionToUv(vec3 d) {
    float u = 0.5f + atan(d.z, d.x) * PV_INV_TWO_PI;
    float v = 0.5f - asin(clamp(d.y, -1.0f, 1.0f)) * PV_INV_PI;
    return vec2(u, v);
}

// Exact inverse of envDirectionToUv (up to rounding).
PV_INLINE vec3 envUvToDirection(vec2 uv) {
    float phi = (uv.x - 0.5f) * PV_TWO_PI;
    float theta = uv.y * PV_PI;
    float sinTheta = sin(theta);
    return vec3(sinTheta * cos(phi), cos(theta), sinTheta * sin(phi));
}

// Texel containing uv; u wraps (u = 1 is column 0's left edge), v clamps.
PV_INLINE uint envTexelIndex(vec2 uv, uint width, uint height) {
    float u = uv.x - floor(uv.x);
    uint x = min(uint(max(u * float(width), 0.0f)), width - 1u);
    uint y = min(uint(max(uv.y * float(height), 0.0f)), height - 1u);
    return y * width + x;
}

// Radiance arriving from world direction dirWorld (unscaled), nearest texel.
PV_INLINE vec3 envRadiance(vec3 dirWorld, uint width, uint height, vec2 rotationCosSin) {
    vec3 dMap = envUnrotateY(dirWorld, rotationCosSin);
    return PV_ENV_RADIANCE(envTexelIndex(envDirectionToUv(dMap), width, height));
}

// Sets `lo` to the largest i in [0, n) with CDF(base + i) <= x, for CDF(base) <= x <
// CDF(base + n). A macro taking the table's macro, not a function: GLSL has no function pointers,
// and both tables share this one loop. The loop tests its exit at the end: on llvmpipe a test at
// the top runs the body once more after the last lane is done (trace_paths.comp's tracePaths).
#define PV_ENV_SEARCH_CDF(CDF, base, n, x, lo)                                                   \
    {                                                                                            \
        uint searchHi = (n);                                                                     \
        (lo) = 0u;                                                                               \
        if (searchHi > 1u) {                                                                     \
            for (;;) {                                                                           \
                PV_COUNT_LOOP_ITERATION();                                                       \
                uint searchMid = ((lo) + searchHi) / 2u;                                         \
                if (CDF((base) + searchMid) <= (x)) (lo) = searchMid; else searchHi = searchMid; \
                if (searchHi - (lo) <= 1u) break;                                                \
            }                                                                                    \
        }                                                                                        \
    }

PV_INLINE uint envSearchMarginal(float x, uint height) {
    uint lo;
    PV_ENV_SEARCH_CDF(PV_ENV_MARGINAL_CDF, 0u, height, x, lo)
    return lo;
}

PV_INLINE uint envSearchConditional(float x, uint row, uint width) {
    uint base = row * (width + 1u);
    uint lo;
    PV_ENV_SEARCH_CDF(PV_ENV_CONDITIONAL_CDF, base, width, x, lo)
    return lo;
}

// Density over the unit square [0,1)^2 of the piecewise-constant distribution, from the same
// CDF differences envSample uses (so the two agree to the last bit).
PV_INLINE float envPdfUv(uint x, uint y, uint width, uint height) {
    float pRow = PV_ENV_MARGINAL_CDF(y + 1u) - PV_ENV_MARGINAL_CDF(y);
    uint base = y * (width + 1u);
    float pColumn = PV_ENV_CONDITIONAL_CDF(base + x + 1u) - PV_ENV_CONDITIONAL_CDF(base + x);
    return pRow * pColumn * float(width) * float(height);
}

// Solid-angle density: dω = 2π² sinθ du dv (pbrt-v4 §12.5.2's equal-area Jacobian for lat-long).
// 0 at the poles, where sinθ = 0 and the map's weight sinθ vanishes too: never NaN/Inf.
PV_INLINE float envPdfFromUv(float pdfUv, float sinTheta) {
    if (!(sinTheta > 0.0f) || !(pdfUv > 0.0f)) return 0.0f;
    float pdf = pdfUv / (2.0f * PV_PI * PV_PI * sinTheta);
    return pdf < PV_FLOAT_MAX ? pdf : 0.0f;
}

// Importance-samples a world direction for the uniform pair u; pdfSolidAngle is envPdf of it
// (0 only for a degenerate sample exactly at a pole, which the caller must discard).
// As envSample, also giving the index of the texel the sample was drawn from. Callers that
// weight the sample by the map's radiance should read that texel rather than look the direction
// up again: the float uv → direction → uv round trip moves samples near a texel edge (by up to
// ~1e-3 texel) into the neighbour, which next to a bright sun loses ~0.2% of its energy.
PV_INLINE vec3 envSampleTexel(vec2 u, uint width, uint height, vec2 rotationCosSin,
                              PV_OUT(float) pdfSolidAngle, PV_OUT(uint) texel) {
    vec2 w = clamp(u, vec2(0.0f), vec2(PV_ONE_MINUS_EPSILON));
    uint y = envSearchMarginal(w.y, height);
    float m0 = PV_ENV_MARGINAL_CDF(y);
    float m1 = PV_ENV_MARGINAL_CDF(y + 1u);
    // Rows with zero probability are never selected: m0 <= w.y < m1 implies m1 > m0.
    float dv = clamp((w.y - m0) / (m1 - m0), 0.0f, PV_ONE_MINUS_EPSILON);

    uint x = envSearchConditional(w.x, y, width);
    uint base = y * (width + 1u);
    float c0 = PV_ENV_CONDITIONAL_CDF(base + x);
    float c1 = PV_ENV_CONDITIONAL_CDF(base + x + 1u);
    float du = clamp((w.x - c0) / (c1 - c0), 0.0f, PV_ONE_MINUS_EPSILON);

    vec2 uv = vec2((float(x) + du) / float(width), (float(y) + dv) / float(height));
    vec3 dMap = envUvToDirection(uv);
    pdfSolidAngle = envPdfFromUv(envPdfUv(x, y, width, height), sin(uv.y * PV_PI));
    texel = y * width + x;
    return envRotateY(dMap, rotationCosSin);
}

PV_INLINE vec3 envSample(vec2 u, uint width, uint height, vec2 rotationCosSin,
                         PV_OUT(float) pdfSolidAngle) {
    uint texel;
    return envSampleTexel(u, width, height, rotationCosSin, pdfSolidAngle, texel);
}

// Solid-angle density of envSample producing dirWorld.
PV_INLINE float envPdf(vec3 dirWorld, uint width, uint height, vec2 rotationCosSin) {
    vec3 dMap = envUnrotateY(dirWorld, rotationCosSin);
    vec2 uv = envDirectionToUv(dMap);
    uint texel = envTexelIndex(uv, width, height);
    uint y = texel / width;
    uint x = texel - y * width;
    float sinTheta = sqrt(max(0.0f, 1.0f - dMap.y * dMap.y));
    return envPdfFromUv(envPdfUv(x, y, width, height), sinTheta);
}

PV_END

#endif
