// The held view following a moving camera (render/held_reprojection.h): its bindings, its
// parameters and where one output pixel's samples land, which the shader (held_reprojection.comp)
// and the tests run alike.
#ifndef PREVIS_SHARED_HELD_REPROJECTION_PARAMS_H
#define PREVIS_SHARED_HELD_REPROJECTION_PARAMS_H

#include "gpu/shaders/shared/denoise.h"
#include "gpu/shaders/shared/octahedral.h"
#include "gpu/shaders/shared/prelude.h"

PV_BEGIN

#define PV_REPROJECT_BINDING_PARAMS 0
// The held samples as the last camera kept them (PV_BINDING_HELD_SAMPLES' layout).
#define PV_REPROJECT_BINDING_FROM 1
// The moved samples land here (the same layout), cleared by the claim stage.
#define PV_REPROJECT_BINDING_TO 2
// Per output pixel the bits of the nearest distance landing there (cleared to all ones: the
// bits of a positive float order as the floats do).
#define PV_REPROJECT_BINDING_NEAREST 3
#define PV_REPROJECT_BINDING_COUNT 4

// Each old pixel's landing takes the nearest distance (claim); the one that won moves its
// samples there (move).
#define PV_REPROJECT_STAGE_CLAIM 0u
#define PV_REPROJECT_STAGE_MOVE 1u
#define PV_REPROJECT_GROUP 8  // a workgroup's edge

struct ReprojectParams {
    // The new camera's frame from the old one's (metres; cameras look along −Z, +Y up).
    mat4 toFromCamera;
    vec2 fromTanHalfFov;  // tan of the half field of view in x and y, the old camera's
    vec2 toTanHalfFov;    // ... and the new one's
    uint width;           // the output's
    uint height;
    float keep;  // the weight the moved samples keep: the history fades while the camera moves
    float unused;
};

// Where the samples of output pixel `pixel` land in the new camera, their mean first-hit distance
// `distance` taken along the old pinhole's ray through the pixel's centre: the landing point in
// pixels (x, y) and the distance from the new camera (z); z = 0 where the point is behind the new
// camera or outside its image.
PV_INLINE vec3 heldLanding(ReprojectParams p, uvec2 pixel, float distance) {
    vec2 ndc = vec2((float(pixel.x) + 0.5f) / float(p.width) * 2.0f - 1.0f,
                    1.0f - (float(pixel.y) + 0.5f) / float(p.height) * 2.0f);
    vec3 dir = normalize(vec3(ndc * p.fromTanHalfFov, -1.0f));
    vec4 q = p.toFromCamera * vec4(dir * distance, 1.0f);
    if (!(q.z < 0.0f)) return vec3(0.0f);
    vec2 n = vec2(q.x, q.y) / (-q.z) / p.toTanHalfFov;
    vec2 at = vec2((n.x + 1.0f) * 0.5f * float(p.width), (1.0f - n.y) * 0.5f * float(p.height));
    if (!(at.x >= 0.0f && at.y >= 0.0f && at.x < float(p.width) && at.y < float(p.height)))
        return vec3(0.0f);
    return vec3(at.x, at.y, length(vec3(q.x, q.y, q.z)));
}

// An output pixel's second vec4 of held samples (PV_BINDING_HELD_SAMPLES): the samples, the sum of
// their first hits' distances, the last sample's first-hit normal (heldNormalCode) and whether
// they were moved from the last camera and no sample traced from the new one has met them yet
// (PV_HELD_MOVED).
#define PV_HELD_MOVED 1.0f
// A moved history that the new camera's first sample in its pixel contradicts is dropped
// (heldHistoryAgrees): the first hit's distance off the history's mean by more than this share
// of the larger, ...
#define PV_HELD_DEPTH_TOLERANCE 0.05f
// ... the geometric normals further apart than PV_HISTORY_MIN_NORMAL_COS (the denoiser's bound),
// ... or the virtual mask off the history's mean by more than a half.
#define PV_HELD_MASK_TOLERANCE 0.5f

// A unit normal as an integer a float holds exactly: its octahedral map at 12 bits a coordinate,
// plus one (0: no normal; the refinement's samples seeding a held view carry none).
PV_INLINE float heldNormalCode(vec3 n) {
    if (n == vec3(0.0f)) return 0.0f;
    vec2 p = octahedralEncode(n);
    uint qx = uint(clamp(p.x * 0.5f + 0.5f, 0.0f, 1.0f) * 4095.0f + 0.5f);
    uint qy = uint(clamp(p.y * 0.5f + 0.5f, 0.0f, 1.0f) * 4095.0f + 0.5f);
    return float(qx * 4096u + qy + 1u);
}

PV_INLINE vec3 heldNormalOf(float code) {
    if (!(code >= 1.0f)) return vec3(0.0f);
    uint c = uint(code) - 1u;
    vec2 q = vec2(float(c / 4096u), float(c % 4096u)) / 4095.0f;
    return octahedralDecode(q * 2.0f - vec2(1.0f));
}

// Whether samples moved from the last camera (sums: Σ composite, Σ M; counts: the second vec4)
// still show the surface the new camera's first sample in their pixel met (its first hit's
// distance, geometric normal and mask): SVGF's temporal test (depth, normal, mesh id) for the
// held view's history, one sample against the history's means. A pixel straddling an outline
// may lose its history to a sample that hit the other side: while the camera moves the mean
// distance that placed it lies on neither surface, so it is the least trustworthy there anyway.
PV_INLINE bool heldHistoryAgrees(vec4 sums, vec4 counts, float distance, vec3 normal, float mask) {
    if (!(counts.x > 0.0f)) return true;
    float meanDistance = counts.y / counts.x;
    if (abs(distance - meanDistance) > PV_HELD_DEPTH_TOLERANCE * max(distance, meanDistance))
        return false;
    vec3 historyNormal = heldNormalOf(counts.z);
    bool normals = historyNormal != vec3(0.0f) && normal != vec3(0.0f);
    if (normals && dot(historyNormal, normal) < PV_HISTORY_MIN_NORMAL_COS) return false;
    return abs(mask - sums.w / counts.x) <= PV_HELD_MASK_TOLERANCE;
}

PV_END

#endif
