#pragma once

// `previs bench --only shot` (BENCHMARKS.md, "The preview as shipped"): the demo take
// (examples/demo) through `previs replay`'s lock-step loop (take/replay.h) with the shipped
// config and with the paper's fixed-sequence preview, against a deep refinement of the take's
// still view (its frames 20–44 hold one view; their first few are lit by a bracket the fisheye
// took while the map still turned, so they have a reference of their own), and a second
// refinement of it with another random sequence, the reference's own noise. Per frame of the pan
// and of the hold: DESIGN.md §4's √relMSE of what the preview adds to the plate (composite − plate,
// so the plates' own noise cancels) against the reference's; flicker (temporal standard deviation
// of the still frames' added signal, relative to the reference's); the virtual objects' level on
// the first frame (before any lighting snapshot) against the reference's; lock-step ms per frame.

#include <cstdint>
#include <string>

namespace previs::bench {

struct ShotBenchOptions {
    std::string examplesDir;  // the repository's examples/ (the demo config and take)
    bool quick = false;       // a 64-spp reference (without a cache) and no later pan: a smoke run
    uint32_t referenceSpp = 1600;  // the deep refinement of the still view
    std::string csvPath;           // per-frame rows as CSV ("" = none)
    // References are read from this folder when there, else rendered and written there ("" =
    // always rendered), named by a hash of the demo config's text: empty the folder after a
    // change to the renderer or the take, which the name does not see.
    std::string referenceCache;
    // Only the variants whose name contains this ("" = all).
    std::string variant;
};

// Prints a Markdown report on stdout (progress on stderr); returns the process exit code.
int runShotBench(const ShotBenchOptions& options);

}  // namespace previs::bench
