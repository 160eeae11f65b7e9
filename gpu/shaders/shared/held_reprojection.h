// The held view following a moving camera (render/held_reprojection.h): its bindings, its
// parameters and where one output pixel's samples land, which the shader (held_reprojection.comp)
// and the tests run alike.
#ifndef PREVIS_SHARED_HELD_REPROJECTION_H
#define PREVIS_SHARED_HELD_REPROJECTION_H

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

PV_END

#endif
