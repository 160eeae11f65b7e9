// held_reprojection: the held view's samples moved with the camera (render/held_reprojection.h).
// Two stages over the old output pixels: claim (each pixel clears its place in the output; one
// with samples finds where they land in the new camera, and the landing keeps the nearest
// distance), move (the pixel that won its
// landing moves its samples there, weighted by `keep`). Where several land, the nearest surface
// hides the others, as the new camera sees them; where none lands (what the move uncovers), the
// new frames start afresh.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

#include "gpu/shaders/shared/held_reprojection_params.h"

layout(constant_id = 0) const uint kStage = PV_REPROJECT_STAGE_MOVE;
layout(local_size_x = PV_REPROJECT_GROUP, local_size_y = PV_REPROJECT_GROUP) in;

layout(binding = PV_REPROJECT_BINDING_PARAMS, scalar) readonly buffer Params {
    ReprojectParams params;
};
layout(binding = PV_REPROJECT_BINDING_FROM, scalar) readonly buffer From { vec4 from[]; };
layout(binding = PV_REPROJECT_BINDING_TO, scalar) writeonly buffer To { vec4 to[]; };
layout(binding = PV_REPROJECT_BINDING_NEAREST, scalar) buffer Nearest { uint nearest[]; };

void main() {
    uvec2 pixel = gl_GlobalInvocationID.xy;
    if (pixel.x >= params.width || pixel.y >= params.height) return;
    uint i = pixel.y * params.width + pixel.x;
    if (kStage == PV_REPROJECT_STAGE_CLAIM) {
        // Cleared here: the move stage, which writes it, runs after every claim.
        to[2u * i] = vec4(0.0);
        to[2u * i + 1u] = vec4(0.0);
    }
    vec4 counts = from[2u * i + 1u];  // (samples, Σ first-hit distance, 0, 0)
    if (!(counts.x > 0.0)) return;
    vec3 landing = heldLanding(params, pixel, counts.y / counts.x);
    if (!(landing.z > 0.0)) return;
    uint j = uint(landing.y) * params.width + uint(landing.x);
    uint bits = floatBitsToUint(landing.z);
    if (kStage == PV_REPROJECT_STAGE_CLAIM) {
        atomicMin(nearest[j], bits);
        return;
    }
    // Two at the very same distance both write: either is right.
    if (nearest[j] != bits) return;
    float kept = counts.x * params.keep;
    to[2u * j] = from[2u * i] * params.keep;
    to[2u * j + 1u] = vec4(kept, landing.z * kept, counts.z, PV_HELD_MOVED);
}
