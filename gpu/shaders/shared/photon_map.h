// Photon map for caustics: the record layout, the hashed grid and the rules that decide which
// light paths the photons carry. Shared by trace_photons.comp (writes photons), photon_grid.comp
// (sorts them into cells), trace_paths.comp (gathers them) and the C++ host and tests.
//
// What the photon map carries (and the path tracer therefore leaves out): light from a photon
// light — an emissive triangle, a punctual light or an estimated (cone) light, never the
// environment map — that reached a surface through one or more purely specular scatterings
// (L S+ D). It is gathered at every vertex of a camera path that is not purely specular (a
// "gather vertex"), through the non-delta part of that vertex's BSDF. The path tracer drops
// exactly those paths: an emitter of a photon light reached from a gather vertex through a
// non-delta scattering followed only by 1..photonMaxBounces purely specular ones. Everything else
// (direct light, diffuse interreflection, environment light through glass) stays with the path
// tracer.
#ifndef PREVIS_SHARED_PHOTON_MAP_H
#define PREVIS_SHARED_PHOTON_MAP_H

#include "shared/prelude.h"

PV_BEGIN

// Hash buckets of the grid. Keys are 16 bits: buckets 0..PV_PHOTON_BUCKETS−1 and one key for
// "no photon here", sorted last and never looked up.
#define PV_PHOTON_BUCKETS 65535u
#define PV_PHOTON_EMPTY_KEY 65535u

// Each photon owns two records: slot 0 for the photon while it is in the mixed scene (or in
// both solutions, while it meets only real geometry), slot 1 for the real-only continuation
// after it met a virtual object (the paper's ray types, as in trace_paths).
#define PV_PHOTON_RECORDS_PER_PHOTON 2u
// Records are sorted in blocks of this many by photon_grid.comp (one workgroup each).
#define PV_PHOTON_SORT_BLOCK 256u
#define PV_PHOTON_GROUP_SIZE 64u
// photon_grid.comp's scan runs in one workgroup of this many invocations.
#define PV_PHOTON_SCAN_GROUP 1024u

// PhotonRecord.flags: the solutions the photon belongs to, and its specular bounces.
#define PV_PHOTON_IN_MIXED 1u
#define PV_PHOTON_IN_REAL 2u
#define PV_PHOTON_BOUNCES_SHIFT 8u

// Photon lights (PV_BINDING_PHOTON_LIGHTS, one 16-byte texel each): kind | real flag in x,
// the triangle (BVH order) or light index in y, inclusive cdf and probability in z and w.
#define PV_PHOTON_LIGHT_TRIANGLE 0u
#define PV_PHOTON_LIGHT_PUNCTUAL 1u
#define PV_PHOTON_LIGHT_REAL 0x100u

// A stored photon, two 16-byte texels: where it landed, the flags, its power (flux, already
// divided by the photons traced in the iteration) and the octahedral-encoded direction it came
// from.
struct PhotonRecord {
    vec3 position;
    uint flags;
    vec3 power;
    uint direction;  // packSnorm2x16(octahedralEncode(toward where the photon came from))
};

// The grid cell of p for cells of edge `cellSize` (twice the gather radius, so that a gather
// sphere overlaps at most 2×2×2 cells).
PV_INLINE ivec3 photonCell(vec3 p, float cellSize) { return ivec3(floor(p / cellSize)); }

// Teschner et al. 2003's spatial hash, folded onto the buckets.
PV_INLINE uint photonBucket(ivec3 c) {
    uint h = (uint(c.x) * 73856093u) ^ (uint(c.y) * 19349663u) ^ (uint(c.z) * 83492791u);
    return h % PV_PHOTON_BUCKETS;
}

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

// The gather radius of iteration i (0-based): r_i = r_0 · (i + 1)^((α − 1)/2), the global radius
// schedule of Knaus & Zwicker 2011 ("Progressive Photon Mapping: A Probabilistic Approach"),
// which gives progressive photon mapping's convergence with each iteration's estimate
// independent of the others — so iterations average like the path tracer's samples.
PV_INLINE float photonRadius(float initialRadius, float alpha, uint iteration) {
    return initialRadius * pow(float(iteration) + 1.0f, 0.5f * (alpha - 1.0f));
}

PV_END

#endif
