#pragma once

// `previs bench --only filter` (issue 38): the live pose filter (vision/pose_filter.h) against
// the tracker's raw poses, on sequences with known motion. Jitter: the standard deviation of the
// camera's position and rotation over frames where it holds still; lag: the delay that best
// aligns the poses with the truth while it moves, and the largest error in the frames after it
// starts to move. Sequences: boards rendered by the path tracer (still 1 s, then an orbit),
// the bundled demo take, and the held start of the ViSP RBT video.

#include <string>

#include "gpu/context.h"

namespace previs::bench {

// Returns the process exit code; Markdown on stdout, progress on stderr.
int runPoseFilterBench(GpuContext& ctx, const std::string& dataDir, const std::string& examplesDir,
                       bool quick);

}  // namespace previs::bench
