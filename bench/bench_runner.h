#pragma once

// `previs bench`: paths and rays per second, BVH build time and memory, scaling with resolution
// and triangle count, the saving of the specialised pipeline, and the tracker's pose accuracy on
// rendered boards (bench/pose_accuracy.h). Prints a Markdown report.

#include <string>

namespace previs::bench {

struct BenchOptions {
    std::string dataDir;      // ../shared/data
    std::string examplesDir;  // the repository's examples/
    bool quick = false;       // one repetition, fewer samples: a smoke run
    int repetitions = 3;      // timings are medians over this many runs
    uint32_t spp = 8;         // samples per pixel of the throughput runs
    // Run one section: throughput, resolution, triangles, specialisation, differential, pose,
    // service (bench/bench_service.h; only when asked for by name: it runs for minutes),
    // memory (bench/bench_memory.h; only by name: it forks a child per resolution),
    // preview (bench/bench_preview.h; only by name: it renders a long reference first),
    // trade (bench/bench_trade.h; only by name: it runs for minutes),
    // denoise (bench/bench_denoise.h; only by name: a long reference render),
    // reach (bench/pose_accuracy.h; only by name: tag reach by distance),
    // filter (bench/bench_pose_filter.h; only by name: the live pose filter's jitter and lag).
    std::string only;
    std::string csvPath;         // service, preview: also write the results as CSV here ("" = none)
    std::string referenceCache;  // shot: its references' folder (bench/bench_shot.h)
    std::string variant;         // shot: only the variants whose name contains this
    // trade: its CSVs, frames and plots go here, drawn by this script.
    std::string outDir = "bench-trade";
    std::string plotter;
};

// Returns the process exit code; writes the report to stdout, progress to stderr.
int runBenchmarks(const BenchOptions& options);

}  // namespace previs::bench
