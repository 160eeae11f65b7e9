// A unit vector in two numbers: the photons' directions, the denoiser's guide normals and the
// held view's normals keep it so.
#ifndef PREVIS_SHARED_OCTAHEDRAL_H
#define PREVIS_SHARED_OCTAHEDRAL_H

#include "gpu/shaders/shared/prelude.h"

PV_BEGIN

// Octahedral map of a unit vector to [−1, 1]² (Cigolle et al. 2014) and back.
PV_INLINE vec2 octahedralEncode(vec3 v) {
    vec3 a = abs(v);
    vec2 p = vec2(v.x, v.y) / (a.x + a.y + a.z);
    if (v.z < 0.0f) {
        vec2 s = vec2(p.x >= 0.0f ? 1.0f : -1.0f, p.y >= 0.0f ? 1.0f : -1.0f);
        p = (vec2(1.0f) - abs(vec2(p.y, p.x))) * s;
    }
    return p;
}

PV_INLINE vec3 octahedralDecode(vec2 p) {
    vec3 v = vec3(p.x, p.y, 1.0f - abs(p.x) - abs(p.y));
    if (v.z < 0.0f) {
        vec2 s = vec2(v.x >= 0.0f ? 1.0f : -1.0f, v.y >= 0.0f ? 1.0f : -1.0f);
        vec2 xy = (vec2(1.0f) - abs(vec2(v.y, v.x))) * s;
        v.x = xy.x;
        v.y = xy.y;
    }
    return normalize(v);
}

PV_END

#endif
