#pragma once

// `previs bench --only preview`: where a 640×480 preview frame's time goes (plate inverse tone
// map, setPlate, the 1-spp render, the frame finished on the device as the service shows it,
// compose to the 1920×1080 screen; beside them, untotalled, the host's readback + upsampling +
// composite and tone map), frames per second, and the error each resolution scale costs against
// a long full-resolution reference (RMSE and DESIGN.md §4's relMSE). Scene: the bunny on a real
// floor under an environment map, differential (bench_scenes.h).

#include <cstdint>
#include <string>
#include <vector>

namespace previs::bench {

struct PreviewBenchOptions {
    std::string dataDir;
    bool quick = false;           // 1 round of 3 frames, a 16-spp reference: a smoke run
    int rounds = 3;               // the scales alternate within each round (A/B/C/D, …)
    int framesPerRound = 5;       // frames per scale per round
    uint32_t referenceSpp = 256;  // the full-resolution reference
    uint32_t maxDepth = 4;        // as the demo's [render] max_depth
    std::vector<float> scales = {1.0f, 1.0f / 2.0f, 1.0f / 3.0f, 1.0f / 4.0f};
    std::string csvPath;  // also write the results as CSV ("" = none)
};

// Returns the process exit code; the report goes to stdout (Markdown), progress to stderr.
int runPreviewBench(const PreviewBenchOptions& options);

}  // namespace previs::bench
