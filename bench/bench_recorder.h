#pragma once

// `previs bench --only recorder` (issue 36): how fast the take recorder (take/take_recorder.h)
// writes, against what a box's two cameras deliver at 1280×720 and 30 fps: MJPEG frames (stored
// as they came) and raw YUYV frames (stored as lossless PNG). Frames are a real photograph
// (../shared/data) with sensor noise, so PNG compresses as it would on set.

#include <string>

namespace previs::bench {

struct RecorderBenchOptions {
    std::string examplesDir;  // the demo's config is the take's config
    std::string dataDir;      // the photograph
    bool quick = false;
};

// Returns the process exit code; a Markdown table on stdout.
int runRecorderBench(const RecorderBenchOptions& options);

}  // namespace previs::bench
