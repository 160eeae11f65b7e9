// bench_service: the service benchmark (bench/bench_service.h) as its own program, the same code
// `previs bench --only service` runs, with the options the section needs to be split up: one
// render size per invocation, shorter or longer live phases.
#include <CLI/CLI.hpp>
#include <cstdio>

#include "base/data_paths.h"
#include "bench/bench_service.h"

int main(int argc, char** argv) {
    previs::bench::ServiceBenchOptions o;
    if (auto root = previs::projectDataDir()) o.examplesDir = (*root / "examples").string();
    std::vector<std::string> sizes;
    CLI::App app(
        "bench_service: previsd's frame rate, latency, stage costs, CPU and memory on the "
        "demo session (Markdown on stdout)");
    app.add_option("--examples", o.examplesDir, "the repository's examples/ folder")
        ->check(CLI::ExistingDirectory);
    app.add_flag("--quick", o.quick, "8 s live runs and 10 frames per stage: a smoke run");
    app.add_option("--csv", o.csvPath, "also write the results as CSV to this file");
    app.add_option("--resolution-scale", o.resolutionScale,
                   "[render] resolution_scale: preview traces this fraction, (0, 1]")
        ->check(CLI::Range(1e-4f, 1.0f));
    app.add_option("--preview-fps", o.previewFps,
                   "[render] preview_fps: the dial's target frame rate (0: off)")
        ->check(CLI::Range(0.0, 240.0));
    app.add_option("--denoise", o.denoise, "[render] denoise for every run")
        ->check(CLI::IsMember({"off", "on", "auto"}));
    app.add_option("--size", sizes, "render size WxH (repeatable; default 640x480 and 1280x720)");
    app.add_option("--preview-seconds", o.previewSeconds, "live preview window per run")
        ->check(CLI::Range(1.0, 3600.0));
    app.add_option("--refine-seconds", o.refineSeconds, "refinement window")
        ->check(CLI::Range(1.0, 3600.0));
    app.add_option("--idle-seconds", o.idleSeconds, "idle (converged) CPU window")
        ->check(CLI::Range(1.0, 3600.0));
    CLI11_PARSE(app, argc, argv);
    for (const std::string& s : sizes) {
        unsigned w = 0, h = 0;
        if (std::sscanf(s.c_str(), "%ux%u", &w, &h) != 2 || w == 0 || h == 0 || w > 8192 ||
            h > 8192) {
            std::fprintf(stderr, "bench_service: --size %s: expected WIDTHxHEIGHT, e.g. 1280x720\n",
                         s.c_str());
            return 2;
        }
        o.sizes.emplace_back(w, h);
    }
    return previs::bench::runServiceBench(o);
}
