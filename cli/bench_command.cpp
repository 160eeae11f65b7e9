#include "cli/bench_command.h"

#include <memory>

#include "base/data_paths.h"
#include "bench/bench_progress.h"
#include "bench/bench_runner.h"

namespace previs {

std::function<int()> addBenchCommand(CLI::App& app) {
    auto o = std::make_shared<bench::BenchOptions>();
    // Found at run time (base/data_paths.h): no machine path is compiled into the binary.
    if (auto shared = sharedDataDir()) o->dataDir = shared->string();
    if (auto root = projectDataDir()) {
        o->examplesDir = (*root / "examples").string();
        o->plotter = (*root / "bench" / "plot_trade.py").string();
    }
    CLI::App* cmd = app.add_subcommand(
        "bench",
        "speed measurements: paths/s, rays/s, BVH build, scaling; pose accuracy on "
        "rendered boards (Markdown on stdout)");
    cmd->add_option("--data", o->dataDir,
                    "test data folder (default: $PREVIS_DATA_DIR, else shared/data in a folder "
                    "above previs)")
        ->check(CLI::ExistingDirectory);
    cmd->add_flag("--quick", o->quick, "one repetition at 1 spp: a smoke run");
    cmd->add_option("--repetitions", o->repetitions, "timings are medians over this many runs")
        ->check(CLI::Range(1, 100));
    cmd->add_option("--spp", o->spp, "samples per pixel of the throughput runs")
        ->check(CLI::Range(1, 4096));
    cmd->add_option("--only", o->only, "one section")
        ->check(
            CLI::IsMember({"throughput", "resolution", "triangles", "specialisation",
                           "differential", "pose", "service", "shot", "memory", "preview", "trade",
                           "denoise", "recorder", "reach", "filter", "ltc", "network"}));
    cmd->add_option("--csv", o->csvPath,
                    "service, preview, shot: also write the results as CSV to this file");
    cmd->add_option("--reference-cache", o->referenceCache,
                    "shot: read its references from this folder, or render them (1600 spp, "
                    "--quick too) and write them there")
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--variant", o->variant,
                    "shot: only the variants whose name contains this text");
    cmd->add_option("--out-dir", o->outDir,
                    "trade: folder for its CSVs, frames and plots (default bench-trade)");
    auto quiet = std::make_shared<bool>(false);
    cmd->add_flag("--quiet", *quiet, "no progress lines on stderr");
    return [o, quiet] {
        bench::benchQuiet() = *quiet;
        return bench::runBenchmarks(*o);
    };
}

}  // namespace previs
