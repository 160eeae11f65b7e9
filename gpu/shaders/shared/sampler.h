// The path tracer's sample generator: every random number a path uses is addressed by (pixel,
// sample index, dimension), so a sample index gives the same numbers on every frame (preview's
// fixed sequence) and the real continuation of a split path draws what a real-only render draws
// at the same depth (differential rendering's identities).
//
// Two generators share that addressing (RenderSettings::sampler; PV_SPEC_SAMPLER selects
// PV_SAMPLER_SOBOL or PV_SAMPLER_INDEPENDENT, defined in shared/scene_types.h):
// - Sobol': Owen-scrambled Sobol' points in the manner of Burley 2020, "Practical Hash-based
//   Owen Scrambling" (JCGT 9(4)). Dimensions come in sets of four; each set draws the first four
//   Sobol' dimensions at its own pseudo-random shuffle of the sample index (a nested uniform
//   scramble, which keeps every power-of-two block of samples a block of the sequence) and
//   Owen-scrambles each dimension with its own seed, both hashed from (pixel, set). Sets are
//   thus "padded": statistically independent of each other, each well stratified in itself.
// - Independent: one PCG stream per (pixel, sample, set): the ablation baseline.
//
// Dimension layout. A set's .xy is its 2D pair, from Sobol' dimensions 0 and 1, whose
// projection is a (0,2)-sequence (every 2^m-sample block is a (0,m,2)-net; no other pair of the
// first five Sobol' dimensions has that property, hence one pair per set); .z and .w are 1D
// decisions from dimensions 2 and 3, stratified on their own and jointly with .xy as a (t,4)-net.
//
//   set                                  .xy                   .z                .w
//   PV_SET_CAMERA_JITTER                 sub-pixel position    -                 -
//   PV_SET_CAMERA_LENS                   aperture point        -                 -
//   per vertex at depth d (0 = first hit), set PV_SET_FIRST_VERTEX + 4d + ...:
//   + PV_SET_VERTEX_ENV                  environment texel     -                 -
//   + PV_SET_VERTEX_EMISSIVE             point on triangle     triangle pick     -
//   + PV_SET_VERTEX_LIGHT                cone-light direction  light pick        -
//   + PV_SET_VERTEX_BSDF                 scattered direction   lobe choice       roulette
//
// Vertices at depth ≥ PV_SOBOL_MAX_DEPTH draw independent (hashed) numbers under either
// generator: stratification no longer pays that deep, where paths are few and diffuse.
#ifndef PREVIS_SHARED_SAMPLER_H
#define PREVIS_SHARED_SAMPLER_H

#include "gpu/shaders/shared/prelude.h"
#include "gpu/shaders/shared/sampling.h"
#include "gpu/shaders/shared/scene_types.h"

PV_BEGIN

#define PV_SET_CAMERA_JITTER 0u
#define PV_SET_CAMERA_LENS 1u
#define PV_SET_FIRST_VERTEX 2u
#define PV_SETS_PER_VERTEX 4u
#define PV_SET_VERTEX_ENV 0u
#define PV_SET_VERTEX_EMISSIVE 1u
#define PV_SET_VERTEX_LIGHT 2u
#define PV_SET_VERTEX_BSDF 3u
// Beyond this depth even the Sobol' generator draws hashed numbers (see above).
#define PV_SOBOL_MAX_DEPTH 8u

// Sobol' sets hold 2^16 samples of one scramble: sample index i uses Sobol' index i mod 2^16
// under a scramble seeded also by i / 2^16, so each further 65536 samples are a fresh randomised
// net (the estimate stays unbiased and keeps converging past 2^16 samples) and the Sobol' matrix
// product needs only 16 columns.
#define PV_SOBOL_BITS 16u

// The set of a vertex at `depth` (scattering events before it); `which` is PV_SET_VERTEX_*.
PV_INLINE uint vertexSet(uint depth, uint which) {
    return PV_SET_FIRST_VERTEX + depth * PV_SETS_PER_VERTEX + which;
}

// What a sample's draws depend on, computed once per (pixel, sample).
struct SampleKey {
    uint streamSeed;  // independent generator and deep-vertex fallback: hash of (pixel, i, seed)
    uint blockSeed;   // Sobol': hash of (pixel, seed, replicate, i / 2^16)
    uint sobolIndex;  // Sobol': i mod 2^16
};
// Replicates: with the convergence meter on, the path tracer interleaves two independently
// randomised sequences, sample n of a pixel being sample n / 2 of replicate n mod 2. Each
// replicate alone is a complete shuffled, scrambled Sobol' sequence; the two are statistically
// independent, so the difference of their means measures the image's error, stratification
// gains included (randomised quasi-Monte Carlo with independent replicates;
// render/convergence.h). The price: two nets of n/2 points stratify less than one of n.
#define PV_MAX_REPLICATES 2u
PV_INLINE SampleKey makeSampleKey(uint pixelIndex, uint sampleIndex, uint seed, uint replicate) {
    SampleKey k;
    // Salted so the two generators' seeds differ, and so do the replicates'.
    uint replicateSeed = seed ^ (replicate * 0x9e3779b9u);
    k.streamSeed = rngSeed(pixelIndex, sampleIndex, replicateSeed);
    uint block = sampleIndex >> PV_SOBOL_BITS;
    k.blockSeed = pcgHash(pixelIndex ^ pcgHash(block ^ pcgHash(replicateSeed ^ 0x5ab1e5u)));
    k.sobolIndex = sampleIndex & ((1u << PV_SOBOL_BITS) - 1u);
    return k;
}
// The key of a pixel's sample `n` when `replicates` (1 or 2) sequences are interleaved.
PV_INLINE SampleKey interleavedSampleKey(uint pixelIndex, uint n, uint seed, uint replicates) {
    return makeSampleKey(pixelIndex, n / replicates, seed, n % replicates);
}
// Laine & Karras 2011's hash as Burley 2020 uses it: add and xor-multiply by even constants, so
// output bit k depends only on input bits 0..k and the seed. Applied to a bit-reversed number
// (bit 0 = the most significant binary digit of the fraction) that is an Owen scramble: each digit
// is flipped by a pseudo-random function of the seed and the digits before it.
PV_INLINE uint laineKarrasPermutation(uint x, uint seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

// Owen scramble of a 32-bit fixed-point fraction (bit 31 = 1/2).
PV_INLINE uint nestedUniformScramble(uint x, uint seed) {
    return bitfieldReverse(laineKarrasPermutation(bitfieldReverse(x), seed));
}

// Fixed-point fraction → float in [0, 1): the 24 high bits, exact in a float.
PV_INLINE float fractionToFloat(uint x) { return float(x >> 8u) * 5.9604644775390625e-8f; }

// Columns of the generator matrices of Sobol' dimensions 1-3 (Joe & Kuo 2008's direction
// numbers, dimension 0 being the identity) for the 16 index bits, stored bit-reversed: bit j of
// column k is digit j+1 of the fraction (weight 2^-(j+1)). Accumulating reversed columns saves
// the bit reversal before the Owen scramble (which works on reversed fractions). The tests
// rebuild these from the primitive polynomials.
#define PV_SOBOL_COLUMN(k, c1, c2, c3)       \
    {                                        \
        uint m = 0u - ((index >> k) & 1u);   \
        r1 ^= c1 & m;                        \
        r2 ^= c2 & m;                        \
        r3 ^= c3 & m;                        \
    }

// Sobol' dimensions 0-3 of `index` (< 2^16), bit-reversed. Straight-line code: no loop for
// llvmpipe's loop budget, and constant columns.
PV_INLINE uvec4 sobolReversed4(uint index) {
    uint r1 = 0u;
    uint r2 = 0u;
    uint r3 = 0u;
    PV_SOBOL_COLUMN(0u, 0x0001u, 0x0001u, 0x0001u)
    PV_SOBOL_COLUMN(1u, 0x0003u, 0x0003u, 0x0003u)
    PV_SOBOL_COLUMN(2u, 0x0005u, 0x0006u, 0x0004u)
    PV_SOBOL_COLUMN(3u, 0x000fu, 0x0009u, 0x000au)
    PV_SOBOL_COLUMN(4u, 0x0011u, 0x0017u, 0x001fu)
    PV_SOBOL_COLUMN(5u, 0x0033u, 0x003au, 0x002eu)
    PV_SOBOL_COLUMN(6u, 0x0055u, 0x0071u, 0x0045u)
    PV_SOBOL_COLUMN(7u, 0x00ffu, 0x00a3u, 0x00c9u)
    PV_SOBOL_COLUMN(8u, 0x0101u, 0x0116u, 0x011bu)
    PV_SOBOL_COLUMN(9u, 0x0303u, 0x0339u, 0x02a4u)
    PV_SOBOL_COLUMN(10u, 0x0505u, 0x0677u, 0x079au)
    PV_SOBOL_COLUMN(11u, 0x0f0fu, 0x09aau, 0x0b67u)
    PV_SOBOL_COLUMN(12u, 0x1111u, 0x1601u, 0x101eu)
    PV_SOBOL_COLUMN(13u, 0x3333u, 0x3903u, 0x302du)
    PV_SOBOL_COLUMN(14u, 0x5555u, 0x7706u, 0x4041u)
    PV_SOBOL_COLUMN(15u, 0xffffu, 0xaa09u, 0xa0c3u)
    // Dimension 0 is the van der Corput sequence: its reversed value is the index itself.
    return uvec4(index, r1, r2, r3);
}

#undef PV_SOBOL_COLUMN

// The seed of dimension set `set` of a sample (before the per-dimension offsets below).
PV_INLINE uint sobolSetSeed(SampleKey k, uint set) { return pcgHash(k.blockSeed ^ pcgHash(set)); }

// Four dimensions of set `set`: shuffled, Owen-scrambled Sobol' (Burley 2020, section 4).
PV_INLINE vec4 sobolSet(SampleKey k, uint set) {
    uint seed = sobolSetSeed(k, set);
    // Shuffle: a nested uniform scramble of the 16-bit index. Bits ≥ 16 of the result do not
    // depend on the index (they see only its zero high bits), so the low 16 bits permute
    // [0, 2^16) and map every aligned 2^m block of indices onto an aligned 2^m block.
    uint shuffled = nestedUniformScramble(k.sobolIndex, seed) & ((1u << PV_SOBOL_BITS) - 1u);
    uvec4 r = sobolReversed4(shuffled);
    // One Owen scramble per dimension, each with its own seed; values returned in natural order.
    return vec4(fractionToFloat(bitfieldReverse(laineKarrasPermutation(r.x, pcgHash(seed + 1u)))),
                fractionToFloat(bitfieldReverse(laineKarrasPermutation(r.y, pcgHash(seed + 2u)))),
                fractionToFloat(bitfieldReverse(laineKarrasPermutation(r.z, pcgHash(seed + 3u)))),
                fractionToFloat(bitfieldReverse(laineKarrasPermutation(r.w, pcgHash(seed + 4u)))));
}

// Four dimensions of set `set` from a PCG stream of its own.
PV_INLINE vec4 independentSet(SampleKey k, uint set) {
    uint state = pcgHash(k.streamSeed ^ pcgHash(set));
    float a = rngNext(state);
    float b = rngNext(state);
    float c = rngNext(state);
    float d = rngNext(state);
    return vec4(a, b, c, d);
}

// Generator `generator` (PV_SAMPLER_*) at set `set`; vertices deeper than PV_SOBOL_MAX_DEPTH
// fall back to the independent generator.
PV_INLINE vec4 sampleSet(uint generator, SampleKey k, uint set) {
    bool sobol = generator == PV_SAMPLER_SOBOL &&
                 set < PV_SET_FIRST_VERTEX + PV_SOBOL_MAX_DEPTH * PV_SETS_PER_VERTEX;
    return sobol ? sobolSet(k, set) : independentSet(k, set);
}

// The held view's phase schedule (temporal super-resolution; FrameParams::heldPhaseCells): a
// preview that traces a pixel for each k×k output pixels places the pixel's samples, frame after
// frame, in the k×k cells of its footprint in a Latin order: phase p is the cell in column
// p mod k and row (p mod k + p / k) mod k, so the k phases from a multiple of k fill each column
// and each row once, and any k² consecutive phases fill each cell once. A held camera then gives
// every output pixel a sample within k² samples of its traced pixel (random jitter leaves
// (1 − 1/k²)^(k²), about a third at k = 3, still without one), and the frames' samples spread
// evenly over each output pixel. `offset` (a hash, a traced pixel's own) shifts its columns and
// rows (a shift keeps the order Latin), so a frame's sample still lies anywhere in its
// footprint: over the offsets, `u` (uniform in [0, 1)²) gives a position uniform over the
// footprint, as the sampler's own jitter does.
PV_INLINE vec2 heldPhaseJitter(uint phase, uint offset, uint k, vec2 u) {
    uint p = phase % (k * k);
    uint column = (p % k + offset % k) % k;
    uint row = (p % k + p / k + (offset / k) % k) % k;
    // Below 1: (2 + u) / 3 rounds to 1 for the largest u below 1 in float.
    return min((vec2(float(column), float(row)) + u) / float(k), vec2(0.99999994f));
}

PV_END

#endif
