#pragma once

// `previs bench --only memory`: peak host memory (RSS) and device allocations of a renderer of
// the 810K-triangle scene ("dragon ×4") at 640×480 and 1920×1080. Each resolution runs in its own
// forked child, before any Vulkan object exists in the parent, so each peak is that run's alone.

#include <cstdint>
#include <string>

namespace previs::bench {

struct MemoryBenchOptions {
    std::string dataDir;  // ../shared/data
    uint32_t spp = 8;     // samples rendered before the peak is read
};

// Returns the process exit code; writes a Markdown table to stdout, progress to stderr.
int runMemoryBench(const MemoryBenchOptions& options);

}  // namespace previs::bench
