// Texture addressing as glTF's sampler defines it (glTF 2.0 §3.8.4.3: wrapS/wrapT REPEAT,
// MIRRORED_REPEAT, CLAMP_TO_EDGE with OpenGL's meaning; magFilter NEAREST or LINEAR). Shared so
// the C++ tests check the same integer and float arithmetic the shader runs. Every texel index
// these return is in [0, size) for any finite or non-finite coordinate: GLSL's `%` is undefined
// for negative operands, and `int(u * size)` overflows for |u| beyond about 2^31 / size, so
// coordinates are first reduced in float to one period, then indices wrapped by comparisons.
#ifndef PREVIS_SHARED_TEXTURE_SAMPLING_H
#define PREVIS_SHARED_TEXTURE_SAMPLING_H

#include "gpu/shaders/shared/prelude.h"

// TextureInfo::flags (shared/scene_types.h): bit 0 sRGB, bits 8-9 wrapS, bits 10-11 wrapT,
// bit 16 nearest filtering.
#define PV_TEXTURE_SRGB 1u
#define PV_TEXTURE_WRAP_S_SHIFT 8u
#define PV_TEXTURE_WRAP_T_SHIFT 10u
#define PV_TEXTURE_NEAREST 0x10000u
#define PV_WRAP_REPEAT 0u
#define PV_WRAP_MIRRORED_REPEAT 1u
#define PV_WRAP_CLAMP_TO_EDGE 2u

PV_BEGIN

// The coordinate reduced to one period of its wrap mode, in texture units (0..1 across the
// image): [0, 1] for REPEAT and CLAMP_TO_EDGE, [0, 2) for MIRRORED_REPEAT (whose period is two
// images). u − floor(u) is exact in float for every finite u. A non-finite coordinate reads as 0.
PV_INLINE float reduceTextureCoordinate(float u, uint mode) {
    if (isnan(u) || isinf(u)) return 0.0f;
    if (mode == PV_WRAP_CLAMP_TO_EDGE) return clamp(u, 0.0f, 1.0f);
    if (mode == PV_WRAP_MIRRORED_REPEAT) return u - 2.0f * floor(0.5f * u);
    return u - floor(u);
}

// A texel index i of a reduced coordinate (i in [-1, 2 size], the range the filters below make)
// mapped into [0, size) as the mode says.
PV_INLINE int wrapTexelIndex(int i, int size, uint mode) {
    if (mode == PV_WRAP_CLAMP_TO_EDGE) return clamp(i, 0, size - 1);
    if (mode == PV_WRAP_MIRRORED_REPEAT) {
        // Period 2·size: texels 0..size-1, then the same mirrored.
        int period = 2 * size;
        int m = i < 0 ? i + period : (i >= period ? i - period : i);
        return m < size ? m : period - 1 - m;
    }
    int r = i < 0 ? i + size : (i >= size ? i - size : i);
    return clamp(r, 0, size - 1);
}

// Nearest filtering: the texel containing the reduced coordinate.
PV_INLINE int nearestTexel(float u, int size, uint mode) {
    float r = reduceTextureCoordinate(u, mode);
    return wrapTexelIndex(int(floor(r * float(size))), size, mode);
}

// Bilinear filtering: the two texels around the coordinate (texel centres at (i + 0.5) / size)
// and the weight of the second.
PV_INLINE void linearTexels(float u, int size, uint mode, PV_OUT(int) i0, PV_OUT(int) i1,
                            PV_OUT(float) w1) {
    float p = reduceTextureCoordinate(u, mode) * float(size) - 0.5f;
    float f = floor(p);
    w1 = p - f;
    int i = int(f);
    i0 = wrapTexelIndex(i, size, mode);
    i1 = wrapTexelIndex(i + 1, size, mode);
}

PV_END

#endif
