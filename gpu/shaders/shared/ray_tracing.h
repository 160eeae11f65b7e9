// Ray casting shared by the shaders and the C++ reference tracer (render/cpu_tracer.cpp):
// watertight ray/triangle intersection, a conservative ray/box slab test, stack-based BVH
// traversal over the node layout of scene_types.h, and self-intersection-free ray origins.
//
// The first part (types, intersection, offsetRayOrigin) needs nothing from the includer. The
// traversal part is compiled only when the includer has defined the accessors first:
//   PV_BVH_NODE(i)  -> WideBvhNode  node i of the 4-wide BVH
//   PV_BVH_NODE_CHILDREN(i) -> uvec4  its child references alone (WideBvhNode::child)
//   PV_TRIANGLE_VERTEX(i, k) -> vec3  vertex k (0, 1, 2) of triangle i, in BVH order
// It has its own include guard, so a C++ file may include the first part through another header
// and the traversal after binding the macros. In C++ the traversal sits in an anonymous
// namespace: each translation unit binds its own accessors without breaking the ODR.
#ifndef PREVIS_SHARED_RAY_TRACING_H
#define PREVIS_SHARED_RAY_TRACING_H

#include "gpu/shaders/shared/prelude.h"
#include "gpu/shaders/shared/scene_types.h"

// `precise` stops the GLSL compiler from fusing a*b - c*d into an fma: an fma rounds the two
// products differently, so the two triangles sharing an edge would no longer compute exactly
// negated edge functions and rays could slip between them. C++ (x86-64, no -mfma, ISO mode)
// does not contract.
#ifdef __cplusplus
#define PV_PRECISE
#else
#define PV_PRECISE precise
#endif

// Root index of a BVH with no triangles: traversal returns "no hit" at once.
#define PV_BVH_NO_ROOT 0xffffffffu
// Traversal stack entries. An entry holds one node of the path from the root (see PV_BVH_POP),
// so a tree of depth D (root at depth 0) needs D entries; render/bvh.cpp caps the depth so that
// this always suffices.
#define PV_BVH_STACK_SIZE 72
// A stack entry keeps its node's index above this bit (PV_BVH_POP); render/bvh.cpp keeps node
// indices below 2^24.
#define PV_BVH_ENTRY_NODE_SHIFT 8u
// 1 + 2γ(3) with γ(n) = nε/(1 - nε), ε = 2^-24 (pbrt-v4 Bounds3::IntersectP; Ize 2013, "Robust
// BVH Ray Traversal"): widens a slab's far distance by the worst rounding error of
// (bound - origin) * invDir, so a ray that hits a triangle never misses its box.
#define PV_BOX_FAR_SCALE 1.0000003576278687f
// Ray origin offset of Wächter & Binder, "A Fast and Robust Method for Avoiding
// Self-Intersection" (Ray Tracing Gems, ch. 6): 256 ULPs along the normal, except within 1/32 of
// the origin, where ULPs get too small and a fixed 1/65536 is used instead.
#define PV_OFFSET_ORIGIN_EPS (1.0f / 32.0f)
#define PV_OFFSET_FLOAT_SCALE (1.0f / 65536.0f)
#define PV_OFFSET_INT_SCALE 256.0f

PV_BEGIN

struct Ray {
    vec3 origin;
    float tMin;     // hits count for t in (tMin, tMax)
    vec3 direction; // need not be unit; t is in units of |direction|
    float tMax;
};

struct Hit {
    float t;
    uint triangle;  // index in BVH order
    float b1;       // barycentric weight of the triangle's vertex 1
    float b2;       // barycentric weight of vertex 2 (vertex 0: 1 - b1 - b2)
};

// Per-ray setup of the watertight test (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
// Intersection", JCGT 2(1), §3): kz is the dominant direction axis, kx and ky the other two
// (swapped when dir[kz] < 0 to keep the winding), and the shear that maps the ray to +z.
struct TriangleRay {
    vec3 origin;
    int kx;
    int ky;
    int kz;
    float sx;
    float sy;
    float sz;
};

PV_INLINE TriangleRay makeTriangleRay(vec3 origin, vec3 direction) {
    TriangleRay r;
    r.origin = origin;
    vec3 a = abs(direction);
    r.kz = a.x > a.y ? (a.x > a.z ? 0 : 2) : (a.y > a.z ? 1 : 2);
    r.kx = r.kz == 2 ? 0 : r.kz + 1;
    r.ky = r.kx == 2 ? 0 : r.kx + 1;
    if (direction[r.kz] < 0.0f) {
        int k = r.kx;
        r.kx = r.ky;
        r.ky = k;
    }
    r.sx = direction[r.kx] / direction[r.kz];
    r.sy = direction[r.ky] / direction[r.kz];
    r.sz = 1.0f / direction[r.kz];
    return r;
}

// Woop et al. 2013, §3 (Fig. 1 code), in float only: GLSL has no portable double. Vertices are
// translated to the ray origin and sheared per vertex, so a vertex shared by two triangles is
// transformed identically in both; an edge function of a shared edge is then computed from the
// same two values in both triangles and comes out exactly negated (round-to-nearest is symmetric,
// and PV_PRECISE forbids fma), so a ray through an edge cannot miss both triangles. A zero edge
// function counts as inside for either winding, so a ray exactly on an edge or vertex hits.
// Accepts hits with t in (tMin, tMax); t, b1, b2 are written only on a hit.
PV_INLINE bool intersectTriangle(TriangleRay r, vec3 p0, vec3 p1, vec3 p2, float tMin, float tMax,
                                 PV_OUT(float) t, PV_OUT(float) b1, PV_OUT(float) b2) {
    vec3 a = p0 - r.origin;
    vec3 b = p1 - r.origin;
    vec3 c = p2 - r.origin;
    PV_PRECISE float ax = a[r.kx] - r.sx * a[r.kz];
    PV_PRECISE float ay = a[r.ky] - r.sy * a[r.kz];
    PV_PRECISE float bx = b[r.kx] - r.sx * b[r.kz];
    PV_PRECISE float by = b[r.ky] - r.sy * b[r.kz];
    PV_PRECISE float cx = c[r.kx] - r.sx * c[r.kz];
    PV_PRECISE float cy = c[r.ky] - r.sy * c[r.kz];
    PV_PRECISE float u = cx * by - cy * bx;
    PV_PRECISE float v = ax * cy - ay * cx;
    PV_PRECISE float w = bx * ay - by * ax;
    if ((u < 0.0f || v < 0.0f || w < 0.0f) && (u > 0.0f || v > 0.0f || w > 0.0f)) return false;
    float det = u + v + w;
    // det == 0: the ray lies in the triangle's plane (or the triangle is degenerate). NaN
    // (a non-finite vertex or direction) fails the comparisons below.
    if (det == 0.0f) return false;
    float az = r.sz * a[r.kz];
    float bz = r.sz * b[r.kz];
    float cz = r.sz * c[r.kz];
    float rcpDet = 1.0f / det;
    float tHit = (u * az + v * bz + w * cz) * rcpDet;
    if (!(tHit > tMin && tHit < tMax)) return false;
    t = tHit;
    b1 = v * rcpDet;
    b2 = w * rcpDet;
    return true;
}

// Slab test (Kay & Kajiya 1986) in pbrt-v4's robust form: the near/far plane of each axis is
// chosen by the sign of invDir, so a -0 direction component (invDir = -inf) picks the right
// planes; a 0 * inf = NaN (origin on a slab plane, ray parallel to it) fails both comparisons
// and leaves the interval unchanged, i.e. the box is not rejected on that axis. The far
// distance is widened by PV_BOX_FAR_SCALE, and so is the ray's tMax (the closest hit so far): a
// triangle whose computed t is a few ULPs below it must not lose its box to the box's own
// rounding. Writes the entry distance on a hit.
PV_INLINE bool intersectBox(vec3 lo, vec3 hi, vec3 origin, vec3 invDir, float tMin, float tMax,
                            PV_OUT(float) tEntry) {
    // All three axes without an early exit: on a SIMD-per-lane device (llvmpipe) a data-dependent
    // exit inside the axis loop costs mask bookkeeping per axis; the result is the same because
    // t0 only grows and t1 only shrinks. The comparisons (not min/max, whose NaN result GLSL
    // leaves undefined) keep the NaN behaviour described above.
    bvec3 negative = lessThan(invDir, vec3(0.0f));
    vec3 tNear = (mix(lo, hi, negative) - origin) * invDir;
    vec3 tFar = (mix(hi, lo, negative) - origin) * invDir * PV_BOX_FAR_SCALE;
    float t0 = tMin;
    float t1 = tMax * PV_BOX_FAR_SCALE;
    if (tNear.x > t0) t0 = tNear.x;
    if (tNear.y > t0) t0 = tNear.y;
    if (tNear.z > t0) t0 = tNear.z;
    if (tFar.x < t1) t1 = tFar.x;
    if (tFar.y < t1) t1 = tFar.y;
    if (tFar.z < t1) t1 = tFar.z;
    tEntry = t0;
    return t0 <= t1;
}

// Wächter & Binder, Ray Tracing Gems ch. 6, "A Fast and Robust Method for Avoiding
// Self-Intersection": moves p by PV_OFFSET_INT_SCALE ULPs (per component, scaled by n) along n,
// which bounds the error of a computed hit point at any scale; near the origin a fixed float
// offset. n is the geometric normal on the side the new ray leaves to (-n for transmission).
// Uses uint bit arithmetic, which wraps, where the paper adds ints: the result is the same and
// no signed overflow is possible for -0 or NaN components on the C++ side.
PV_INLINE vec3 offsetRayOrigin(vec3 p, vec3 n) {
    ivec3 offsetInt = ivec3(PV_OFFSET_INT_SCALE * n);
    uvec3 bits = floatBitsToUint(p);
    vec3 result;
    for (int i = 0; i < 3; ++i) {
        PV_COUNT_LOOP_ITERATION();
        // Negative floats grow in magnitude as their bits grow: step the bits the other way.
        int step = p[i] < 0.0f ? -offsetInt[i] : offsetInt[i];
        float moved = uintBitsToFloat(bits[i] + uint(step));
        result[i] = abs(p[i]) < PV_OFFSET_ORIGIN_EPS ? p[i] + PV_OFFSET_FLOAT_SCALE * n[i] : moved;
    }
    return result;
}

// False for a ray with a NaN or infinite origin or direction component. The slab test lets a
// NaN through on every axis (see intersectBox), so such a ray would visit every node of the BVH
// and hit nothing: traversal culls it at once. NaN fails every ordered comparison, so one
// comparison per component catches NaN and infinity alike.
PV_INLINE bool rayIsFinite(vec3 origin, vec3 direction) {
    return all(lessThanEqual(abs(origin), vec3(PV_FLOAT_MAX))) &&
           all(lessThanEqual(abs(direction), vec3(PV_FLOAT_MAX)));
}

PV_END

#endif  // PREVIS_SHARED_RAY_TRACING_H

#if defined(PV_BVH_NODE) && !(defined(PV_BVH_NODE_CHILDREN) && defined(PV_TRIANGLE_VERTEX))
#error "the traversal needs PV_BVH_NODE_CHILDREN and PV_TRIANGLE_VERTEX as well as PV_BVH_NODE"
#endif
#if defined(PV_BVH_NODE) && defined(PV_BVH_NODE_CHILDREN) && defined(PV_TRIANGLE_VERTEX) && \
    !defined(PREVIS_SHARED_RAY_TRACING_TRAVERSAL_H)
#define PREVIS_SHARED_RAY_TRACING_TRAVERSAL_H

PV_BEGIN
#ifdef __cplusplus
namespace {
#endif

// Intersects triangles [first, first + count) of a leaf, shrinking tMax to each hit.
PV_INLINE bool intersectLeaf(TriangleRay tr, uint first, uint count, float tMin,
                             PV_INOUT(float) tMax, PV_INOUT(Hit) hit) {
    bool found = false;
    // A leaf holds at least one triangle: the exit test can sit at the end (see below).
    for (uint i = first;;) {
        PV_COUNT_LOOP_ITERATION();
        float t;
        float b1;
        float b2;
        if (intersectTriangle(tr, PV_TRIANGLE_VERTEX(i, 0u), PV_TRIANGLE_VERTEX(i, 1u),
                              PV_TRIANGLE_VERTEX(i, 2u), tMin, tMax, t, b1, b2)) {
            tMax = t;
            hit.t = t;
            hit.triangle = i;
            hit.b1 = b1;
            hit.b2 = b2;
            found = true;
        }
        if (++i >= first + count) break;
    }
    return found;
}

// intersectBox for the four child boxes of a wide node at once (the same arithmetic per box, so
// the same robustness); writes each box's entry distance and returns which boxes the ray enters.
PV_INLINE bvec4 intersectChildBoxes(WideBvhNode n, vec3 origin, vec3 invDir, float tMin,
                                    float tMax, PV_OUT(vec4) tEntry) {
    bool negX = invDir.x < 0.0f;
    bool negY = invDir.y < 0.0f;
    bool negZ = invDir.z < 0.0f;
    vec4 nearX = ((negX ? n.hiX : n.loX) - origin.x) * invDir.x;
    vec4 nearY = ((negY ? n.hiY : n.loY) - origin.y) * invDir.y;
    vec4 nearZ = ((negZ ? n.hiZ : n.loZ) - origin.z) * invDir.z;
    vec4 farX = ((negX ? n.loX : n.hiX) - origin.x) * invDir.x * PV_BOX_FAR_SCALE;
    vec4 farY = ((negY ? n.loY : n.hiY) - origin.y) * invDir.y * PV_BOX_FAR_SCALE;
    vec4 farZ = ((negZ ? n.loZ : n.hiZ) - origin.z) * invDir.z * PV_BOX_FAR_SCALE;
    // Comparisons, not min/max: a NaN distance leaves the interval unchanged (see intersectBox).
    vec4 t0 = vec4(tMin);
    vec4 t1 = vec4(tMax * PV_BOX_FAR_SCALE);
    t0 = mix(t0, nearX, greaterThan(nearX, t0));
    t0 = mix(t0, nearY, greaterThan(nearY, t0));
    t0 = mix(t0, nearZ, greaterThan(nearZ, t0));
    t1 = mix(t1, farX, lessThan(farX, t1));
    t1 = mix(t1, farY, lessThan(farY, t1));
    t1 = mix(t1, farZ, lessThan(farZ, t1));
    tEntry = t0;
    return lessThanEqual(t0, t1);
}

PV_INLINE void sortPair(PV_INOUT(float) ka, PV_INOUT(uint) va, PV_INOUT(float) kb,
                        PV_INOUT(uint) vb) {
    if (kb < ka) {
        float k = ka;
        ka = kb;
        kb = k;
        uint v = va;
        va = vb;
        vb = v;
    }
}

// Visits wide node `ref`: writes its child references to `children` and the slots (0-3) of the
// children the ray enters to `order`, nearest entry first, two bits each from bit 0; returns how
// many the ray enters (0-4).
PV_INLINE uint enteredChildren(uint ref, vec3 origin, vec3 invDir, float tMin, float tMax,
                               PV_OUT(uvec4) children, PV_OUT(uint) order) {
    WideBvhNode n = PV_BVH_NODE(ref);
    vec4 tEntry;
    bvec4 entered = intersectChildBoxes(n, origin, invDir, tMin, tMax, tEntry);
    // +inf: after every entry distance, the key of a child not entered.
    float none = uintBitsToFloat(0x7f800000u);
    float k0 = entered.x ? tEntry.x : none;
    float k1 = entered.y ? tEntry.y : none;
    float k2 = entered.z ? tEntry.z : none;
    float k3 = entered.w ? tEntry.w : none;
    uint s0 = 0u;
    uint s1 = 1u;
    uint s2 = 2u;
    uint s3 = 3u;
    // A sorting network for four.
    sortPair(k0, s0, k1, s1);
    sortPair(k2, s2, k3, s3);
    sortPair(k0, s0, k2, s2);
    sortPair(k1, s1, k3, s3);
    sortPair(k1, s1, k2, s2);
    children = n.child;
    order = s0 | (s1 << 2u) | (s2 << 4u) | (s3 << 6u);
    return uint(entered.x) + uint(entered.y) + uint(entered.z) + uint(entered.w);
}

// The child reference in slot `slot` of `children` (selects: a per-lane index into a vector
// would be a per-lane loop on llvmpipe).
PV_INLINE uint childInSlot(uvec4 children, uint slot) {
    return slot == 0u   ? children.x
           : slot == 1u ? children.y
           : slot == 2u ? children.z
                        : children.w;
}

// Both traversals are "while-while" (Aila & Laine 2009, "Understanding the Efficiency of Ray
// Traversal on GPUs"): an inner loop walks nodes until the lane holds a leaf (or has nothing
// left), and only then are leaves intersected. On a SIMD device that runs the lanes of a batch
// in lock step (llvmpipe, GPUs) a lane at a leaf waits for the others instead of making every
// iteration pay for both the node and the leaf code.
//
// Shaped for llvmpipe, which runs both sides of every branch under a lane mask and tests a loop's
// mask only where its body ends:
// - every loop tests its exit at the end of its body. A test at the top would run the whole
//   body once more, masked, after the batch's last lane left it;
// - one traversal walks both BVHs, the second root waiting until the first tree is done, so a
//   shading point's code holds one traversal loop per ray, not one per BVH;
// - a node visit stores at most one stack entry, not one per sibling left to visit: an entry is
//   the node and the slots of its entered children still to visit, nearest first, and the newest
//   entry stays in a register (`top`) until a later node needs the register. The stack is a
//   per-lane array, and llvmpipe stores to one lane by lane, each behind a branch on the lane's
//   mask, whether or not any lane stores (measured: the three pushes per visit were a quarter of
//   all shader time on the area-light scene).
//
// An entry: node index << PV_BVH_ENTRY_NODE_SHIFT | the slots left (bits 2-3 the nearest, 4-5,
// 6-7) | their count (bits 0-1, 1-3). 0 is no entry (a count is never 0).

// Takes the next subtree into `ref`: the nearest sibling left in the newest entry, else the
// second BVH's root once the first is done; clears `live` when none is left. (No do-while
// wrapper: in a shader that would be a loop.)
#define PV_BVH_POP(ref, stack, stackSize, top, pendingRoot, live)                              \
    {                                                                                          \
        if ((top) == 0u && (stackSize) > 0) (top) = (stack)[--(stackSize)];                   \
        if ((top) != 0u) {                                                                     \
            (ref) = childInSlot(PV_BVH_NODE_CHILDREN((top) >> PV_BVH_ENTRY_NODE_SHIFT),         \
                                ((top) >> 2u) & 3u);                                           \
            uint left = ((top) & 3u) - 1u;                                                     \
            uint rest = (((top) >> 4u) & 0xfu) << 2u;                                          \
            (top) = left == 0u ? 0u : (((top) & ~0xffu) | rest | left);                        \
        } else if ((pendingRoot) != PV_BVH_NO_ROOT) {                                          \
            (ref) = (pendingRoot);                                                             \
            (pendingRoot) = PV_BVH_NO_ROOT;                                                    \
        } else {                                                                               \
            (live) = false;                                                                    \
        }                                                                                      \
    }

// Declares a traversal's state: the stack and its register top, the root `second` to walk once
// `first` is done, the subtree `ref` to walk first, and `live`, false once nothing is left to
// walk. This and PV_BVH_DESCEND end in an `if`: use them as statements of their own, never before
// an `else`.
#define PV_BVH_BEGIN(first, second)                                  \
    uint stack[PV_BVH_STACK_SIZE];                                   \
    int stackSize = 0;                                               \
    uint top = 0u;                                                   \
    uint pendingRoot = (second);                                     \
    uint ref = (first);                                              \
    bool live = true;                                                \
    if (ref == PV_BVH_NO_ROOT) PV_BVH_POP(ref, stack, stackSize, top, pendingRoot, live)

// Walks from `ref` down to a leaf, keeping the entered siblings not taken in an entry (see
// above); clears `live` when no leaf is left. A macro, not a function: GLSL passes arrays by
// value, so a helper taking the stack would copy all of it at every node.
#define PV_BVH_DESCEND(ref, stack, stackSize, top, pendingRoot, origin, invDir, tMin, tMax, live) \
    if (((ref) & PV_WIDE_LEAF) == 0u) {                                                          \
        for (;;) {                                                                               \
            PV_COUNT_LOOP_ITERATION();                                                           \
            uvec4 children;                                                                      \
            uint order;                                                                          \
            uint entered =                                                                       \
                enteredChildren((ref), (origin), (invDir), (tMin), (tMax), children, order);     \
            if (entered == 0u) {                                                                 \
                PV_BVH_POP(ref, stack, stackSize, top, pendingRoot, live)                        \
            } else {                                                                             \
                if (entered > 1u) {                                                              \
                    if ((top) != 0u) (stack)[(stackSize)++] = (top);                             \
                    uint slotsLeft = (order & 0xfcu) | (entered - 1u);                           \
                    (top) = ((ref) << PV_BVH_ENTRY_NODE_SHIFT) | slotsLeft;                      \
                }                                                                                \
                (ref) = childInSlot(children, order & 3u);                                       \
            }                                                                                    \
            if (!(live) || ((ref) & PV_WIDE_LEAF) != 0u) break;                                  \
        }                                                                                        \
    }

// Closest hit with t in (ray.tMin, min(ray.tMax, hit.t)) in the BVHs at `first` and `second`
// (either may be PV_BVH_NO_ROOT); updates `hit` and returns true if it found one. Children are
// visited nearest entry first, so boxes behind a found hit are culled. (Any-hit traversal visits
// them in the same order.)
PV_INLINE bool traceClosest(uint first, uint second, Ray ray, PV_INOUT(Hit) hit) {
    if (!rayIsFinite(ray.origin, ray.direction)) return false;
    PV_BVH_BEGIN(first, second)
    float tMax = min(ray.tMax, hit.t);
    vec3 invDir = 1.0f / ray.direction;
    TriangleRay tr = makeTriangleRay(ray.origin, ray.direction);
    bool found = false;
    if (live) {
        for (;;) {
            PV_COUNT_LOOP_ITERATION();
            PV_BVH_DESCEND(ref, stack, stackSize, top, pendingRoot, ray.origin, invDir, ray.tMin,
                           tMax, live)
            if (live) {
                uint start = wideLeafFirst(ref);
                uint count = wideLeafCount(ref);
                if (intersectLeaf(tr, start, count, ray.tMin, tMax, hit)) found = true;
                PV_BVH_POP(ref, stack, stackSize, top, pendingRoot, live)
            }
            if (!live) break;
        }
    }
    return found;
}

// Any hit with t in (ray.tMin, ray.tMax) in the BVHs at `first` and `second` (either may be
// PV_BVH_NO_ROOT; shadow rays). Returns the blocking triangle, or PV_BVH_NO_TRIANGLE. The second
// BVH is entered only once the first holds no blocker, so a blocker from the second means the
// first is clear: the differential renderer needs to know which scene blocks.
#define PV_BVH_NO_TRIANGLE 0xffffffffu
PV_INLINE uint traceAny(uint first, uint second, Ray ray) {
    if (!rayIsFinite(ray.origin, ray.direction)) return PV_BVH_NO_TRIANGLE;
    PV_BVH_BEGIN(first, second)
    vec3 invDir = 1.0f / ray.direction;
    TriangleRay tr = makeTriangleRay(ray.origin, ray.direction);
    uint blocker = PV_BVH_NO_TRIANGLE;
    if (live) {
        for (;;) {
            PV_COUNT_LOOP_ITERATION();
            PV_BVH_DESCEND(ref, stack, stackSize, top, pendingRoot, ray.origin, invDir, ray.tMin,
                           ray.tMax, live)
            if (live) {
                uint start = wideLeafFirst(ref);
                uint count = wideLeafCount(ref);
                for (uint i = start;;) {
                    PV_COUNT_LOOP_ITERATION();
                    float t;
                    float b1;
                    float b2;
                    if (intersectTriangle(tr, PV_TRIANGLE_VERTEX(i, 0u), PV_TRIANGLE_VERTEX(i, 1u),
                                          PV_TRIANGLE_VERTEX(i, 2u), ray.tMin, ray.tMax, t, b1,
                                          b2))
                        blocker = i;
                    if (blocker != PV_BVH_NO_TRIANGLE || ++i >= start + count) break;
                }
                if (blocker != PV_BVH_NO_TRIANGLE)
                    live = false;
                else
                    PV_BVH_POP(ref, stack, stackSize, top, pendingRoot, live)
            }
            if (!live) break;
        }
    }
    return blocker;
}

#ifdef __cplusplus
}  // namespace
#endif
PV_END

#endif  // traversal
