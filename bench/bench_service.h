#pragma once

// The service benchmark of issue 7 (`previs bench --only service`, BENCHMARKS.md "The live service
// (previsd)"): per-stage cost per frame in lock step over the demo session (as `previs replay`
// drives the stages), then the live service (daemon/service.h) on the same session at recorded
// timing: preview fps and latency, drops, refinement samples/s, CPU use once refinement has
// converged, peak host RSS and the renderer's device memory. Each configuration runs in its own
// forked child so that its peak RSS is its own; the parent must not have started threads or a
// Vulkan device before calling runServiceBench.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace previs::bench {

struct ServiceBenchOptions {
    std::string examplesDir;  // the repository's examples/ (the demo config and session)
    bool quick = false;       // short runs and few frames: a smoke run
    std::string csvPath;      // "" = no CSV
    // Render sizes; empty = 640×480 and 1280×720.
    std::vector<std::pair<uint32_t, uint32_t>> sizes;
    // Live phases in seconds; 0 = the defaults (20/10/10, quick: 8/4/4).
    double previewSeconds = 0.0;
    double refineSeconds = 0.0;
    double idleSeconds = 0.0;
    // [render] resolution_scale for every run (preview traces this fraction; refinement all).
    float resolutionScale = 1.0f;
    // [render] preview_fps (the dial; 0: off) and denoise (off | on | auto) for every run.
    double previewFps = 0.0;
    std::string denoise = "off";
};

// Prints a Markdown report on stdout (progress on stderr); returns the process exit code.
int runServiceBench(const ServiceBenchOptions& options);

}  // namespace previs::bench
