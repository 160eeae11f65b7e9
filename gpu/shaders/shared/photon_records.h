// Photon map for caustics: the record layout, the hashed grid and the rules that decide which
// light paths the photons carry. Shared by trace_photons.comp (writes photons), photon_grid.comp
// (sorts them into cells), trace_paths.comp (gathers them) and the C++ host and tests.
//
// What the photon map carries (and the path tracer therefore leaves out): light from a photon
// light — an emissive triangle, a punctual light, an estimated (cone) light or the environment
// map — that reached a surface D through one or more scatterings at surfaces that carry
// caustics (S: purely specular, or polished below PV_CAUSTIC_ALPHA without a diffuse base;
// bsdf.h's bsdfCarriesCaustics) (L S+ D, the caustic). The path tracer drops exactly those
// paths: an emitter of a photon light reached from a gather vertex (a vertex that does not carry
// caustics) through a non-delta scattering followed only by 1..photonMaxBounces S ones, whether
// the last S vertex reaches the emitter by its sampled direction or by light sampling (a
// polished vertex samples lights; a purely specular one cannot). Everything else (direct light,
// diffuse interreflection) stays with the path tracer.
//
// Photons are stored at two levels, so that the light a caustic throws onward is a density
// estimate too, not the path tracer's rare bright samples (a point in a glass ball's shadow that
// sees the ball's bright caustic through the ball):
// - level 1 where the photon lands on D, as above;
// - level 2 where it lands next: after D it scatters through the non-delta part of D's BSDF (a
//   delta lobe ends it) and S scatterings, and is stored at the next vertex that is not an S
//   vertex (L S+ D S* G).
// The camera path gathers level 2 at every gather vertex (where level 2 is all it takes, with a
// probability and the inverse weight: PV_PHOTON_LEVEL_2_GATHER_PROBABILITY) and level 1 only at
// a gather vertex whose previous gather vertex, if any, scattered through a delta lobe. Each of
// the dropped paths is then counted once: L S+ D … E is level 1 at D when the path reached D
// from the camera through delta scatterings only, and level 2 at the gather vertex before D
// otherwise (which scattered toward D through its non-delta part, the part a gather evaluates).
// Where the photon pass splats (photonSplatsActive), the camera path's first vertex does not
// gather: the photon pass sends each record the camera sees directly to its pixel instead
// (trace_photons.comp's splatToCamera), the same paths (L S+ D E, L S+ D S* D E) counted once.
#ifndef PREVIS_SHARED_PHOTON_RECORDS_H
#define PREVIS_SHARED_PHOTON_RECORDS_H

#include "gpu/shaders/shared/octahedral.h"
#include "gpu/shaders/shared/prelude.h"

PV_BEGIN

// Hash buckets of the grid: 27 classes (a cell's place in its 3×3×3 block) of
// PV_PHOTON_PARENT_BUCKETS each (photonBucket). Keys are 24 bits: buckets 0..PV_PHOTON_BUCKETS−1
// and one key for "no photon here", sorted last and never looked up. A bucket a gather visits
// holds, besides its own cell's records, those of every cell hashed onto it, each read and
// rejected: with 65528 buckets those collisions were a third of the gather's time on the caustics
// scene (BENCHMARKS.md), so the table holds about a million (8 MiB of ranges), sorted in three
// radix passes of 8 bits.
#define PV_PHOTON_PARENT_BUCKETS 38833u
#define PV_PHOTON_BUCKETS (27u * PV_PHOTON_PARENT_BUCKETS)
#define PV_PHOTON_EMPTY_KEY 0xffffffu
#define PV_PHOTON_SORT_PASSES 3u
// Each pass sorts by one 8-bit digit: 256 digit counts per sort block (photon_grid.comp's
// histograms, and the host's buffer for them).
#define PV_PHOTON_SORT_DIGITS 256u

// Each photon owns four records, two per level: slot 2·level' + 0 for the photon while it is in
// the mixed scene (or in both solutions, while it meets only real geometry), + 1 for the
// real-only continuation after it met a virtual object (the paper's ray types, as in
// trace_paths); level' is 0 for level 1, 1 for level 2.
#define PV_PHOTON_RECORDS_PER_PHOTON 4u
// Records are sorted in blocks of this many by photon_grid.comp, one invocation walking each
// block in order: its histogram and scatter cost one step a record whatever the block size, and
// the one-workgroup scan over blocks × 256 digit counts shrinks as blocks grow. 512 is four
// records each of the 128 photons the photon count is a multiple of (renderer.cpp).
#define PV_PHOTON_SORT_BLOCK 512u
#define PV_PHOTON_GROUP_SIZE 64u
// trace_photons packs a workgroup's stored sort pairs at the start of its slots, this many (four
// per photon); photon_grid.comp's compaction gathers them from there.
#define PV_PHOTON_GROUP_SLOTS (PV_PHOTON_RECORDS_PER_PHOTON * PV_PHOTON_GROUP_SIZE)
// photon_grid.comp's scan runs in one workgroup of this many invocations.
#define PV_PHOTON_SCAN_GROUP 1024u

// PhotonRecord.flags: the solutions the photon belongs to, its level, and its scatterings.
#define PV_PHOTON_IN_MIXED 1u
#define PV_PHOTON_IN_REAL 2u
#define PV_PHOTON_LEVEL_2 4u
// A camera path's gather vertex that takes level 2 only gathers with this probability (weighted
// by its inverse): the light a caustic throws on after two diffuse bounces is small beside the
// path tracer's own at that vertex, and a gather costs its bucket lookups wherever it runs.
#define PV_PHOTON_LEVEL_2_GATHER_PROBABILITY 0.25f

// Scatterings before the photon landed (all of them: a level-2 photon counts D too), which the
// camera path's remaining depth must hold.
#define PV_PHOTON_BOUNCES_SHIFT 8u

// Photon lights (PV_BINDING_PHOTON_LIGHTS, one 16-byte texel each): kind | real flag in x,
// the triangle (BVH order) or light index in y, inclusive cdf and probability in z and w.
#define PV_PHOTON_LIGHT_TRIANGLE 0u
#define PV_PHOTON_LIGHT_PUNCTUAL 1u
// The environment map as a distant light over the aim sphere's cross-section (y unused).
#define PV_PHOTON_LIGHT_ENVIRONMENT 2u
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

// The grid cell of p for cells of edge `cellSize` (photonCellSize of the gather radius).
PV_INLINE ivec3 photonCell(vec3 p, float cellSize) { return ivec3(floor(p / cellSize)); }

// The grid's cell edge for gather radius r: 2r, so a gather's sphere meets 2×2×2 cells. (3×3×3
// cells of edge r read fewer records, about 8 r² of a surface instead of 15 r² for a disc of
// π r², but llvmpipe runs a gather's cell loop 27 trips instead of 8 wherever a lane gathers:
// with a window of 1024 records a cell (PhotonSettings::gatherCap) the 8 cells make an iteration
// about 10 % faster at the same error, BENCHMARKS.md.)
// The span is the cells a gather visits per axis; the edge follows from it, as a sphere of
// radius r spans 2r: 2 cells of 2r, or 3 of r.
#define PV_PHOTON_GATHER_SPAN 2
PV_INLINE float photonCellSize(float radius) {
    return 2.0f * radius / float(PV_PHOTON_GATHER_SPAN - 1);
}

// Teschner et al. 2003's spatial hash of the 3×3×3 block holding the cell, folded onto the
// parent buckets, then the cell's place within the block. Neighbouring cells (the 2×2×2 a gather
// visits) have different places: they never share a bucket, so no record is summed twice and the
// gather needs no duplicate check.
PV_INLINE uint photonBucket(ivec3 c) {
    // Offset by a multiple of 3 so that unsigned division floors negative cells too.
    uvec3 u = uvec3(c) + uvec3(1610612736u);
    uvec3 block = u / 3u;
    uvec3 place = u - block * 3u;
    uint h = (block.x * 73856093u) ^ (block.y * 19349663u) ^ (block.z * 83492791u);
    return (h % PV_PHOTON_PARENT_BUCKETS) * 27u + place.x + 3u * place.y + 9u * place.z;
}

// The even bits of v, packed: one coordinate of a Morton (Z-order) index.
PV_INLINE uint compactEvenBits(uint v) {
    v &= 0x55555555u;
    v = (v | (v >> 1u)) & 0x33333333u;
    v = (v | (v >> 2u)) & 0x0f0f0f0fu;
    v = (v | (v >> 4u)) & 0x00ff00ffu;
    return (v | (v >> 8u)) & 0x0000ffffu;
}

// The two numbers of photon `photon`'s direction, of an iteration's N = 2^m photons, from three
// uniform ones: the photon takes the photon-th of N equal stretches of a Z-order curve through
// the 2^k × 2^k cells of the unit square (k = ⌈m/2⌉: one or two cells a stretch), u.x picks the
// cell in its stretch and u.yz the point in the cell. Over the N photons that is uniform
// (stratified along the curve), and consecutive photons — the lanes of one SIMD batch — leave in
// neighbouring directions and meet the same BVH nodes, where a scrambled net's consecutive
// points go anywhere. Another N (any multiple of 128 is allowed) takes the sampler's `plain`.
PV_INLINE vec2 photonDirectionSample(uint photon, uint n, vec3 u, vec2 plain) {
    if ((n & (n - 1u)) != 0u) return plain;
    uint k = (uint(findMSB(n)) + 1u) / 2u;
    uint cellsPerPhoton = (1u << (2u * k)) / n;
    uint cell =
        photon * cellsPerPhoton + min(uint(u.x * float(cellsPerPhoton)), cellsPerPhoton - 1u);
    vec2 corner = vec2(compactEvenBits(cell), compactEvenBits(cell >> 1u));
    return min((corner + vec2(u.y, u.z)) / float(1u << k), vec2(PV_ONE_MINUS_EPSILON));
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
