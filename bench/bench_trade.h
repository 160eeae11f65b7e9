#pragma once

// `previs bench --only trade`: the speed ⇄ accuracy trade, measured. On the bunny standing on a
// real floor under an environment map (differential rendering, the plate being the set's own
// converged real-only render), it renders progressively from 1 to 1024 samples per pixel under
// several settings and records, at every power of two, the wall time, the RMSE and relMSE
// (DESIGN §4) against a long reference, and the convergence meter's estimate:
//   - refinement settings at max depth 1, 2, 4, 8 and 16 (depth's bias shows as a floor), and
//     at depth 8 denoised (each point's filter time counted);
//   - preview settings (depth 2, at full resolution and at a third upsampled): each point one
//     fixed-sequence frame of that many samples, the frame the service shows live;
//   - the dial at 640×480: 36 preview settings' frame time and error, the Pareto front, the
//     choice for 10 frames per second and its neighbours (render/quality_dial.h);
//   - the paper's figure 2 (the composite after 1, 10, 100 and 1000 frames of refinement) and
//     figure 4 (time of a 1-spp frame against resolution).
// Writes trade.csv, resolution.csv and the figure-2 frames into a folder, then draws the plots
// with bench/plot_trade.py (matplotlib).

#include <filesystem>
#include <string>

namespace previs::bench {

struct TradeBenchOptions {
    std::string dataDir;            // ../shared/data
    std::filesystem::path outDir;   // CSVs, frames and plots
    std::filesystem::path plotter;  // bench/plot_trade.py; empty: no plots
    bool quick = false;             // smaller, shorter: a smoke run
    int repetitions = 3;            // figure 4's timings are medians over this many
};

// Returns the process exit code; a Markdown summary on stdout, progress on stderr.
int runTradeBench(const TradeBenchOptions& options);

}  // namespace previs::bench
