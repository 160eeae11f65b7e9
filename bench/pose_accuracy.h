#pragma once

// `previs bench --only pose`: camera-pose accuracy of the tracker on boards rendered by the path
// tracer at known poses (render/board_render.h), over distances, viewing angles, blur, noise and
// both lens models. Prints Markdown tables.

#include <cstdint>

#include "gpu/context.h"

namespace previs::bench {

struct PoseSweepOptions {
    // A smoke run: 2 distances, 2 angles, 1 view, clean and worst image, 4 spp.
    bool quick = false;
    // Antialiasing samples per pixel of each render. Fewer leave Monte Carlo noise on the edge
    // pixels that moves corners (~0.15 px RMS at 4 spp, ~0.09 px at 16: rendered_pose_test).
    uint32_t spp = 16;
};

// Returns the process exit code; the report goes to stdout, progress to stderr.
int runPoseSweep(GpuContext& ctx, const PoseSweepOptions& options);

// `previs bench --only reach` (issue 38): per distance, how often the A2 board gives a pose and
// how many of those are within the on-set requirement, and the time a frame's tracking takes,
// for libapriltag's defaults (decimate 2, its corners) against the tracker's own (the search of
// vision/tag_search.h, corners re-fitted in linear light), on a frame tracked on its own and on
// one tracked after the previous frame's pose. sRGB frames through the rad-tan lens.
int runReachSweep(GpuContext& ctx, bool quick);

}  // namespace previs::bench
