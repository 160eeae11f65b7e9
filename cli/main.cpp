// previs: the command line (DESIGN.md §3).
#include <CLI/CLI.hpp>

#include "base/log.h"
#include "cli/bench_command.h"
#include "cli/compare_command.h"
#include "cli/ctl_command.h"
#include "cli/envmap_command.h"
#include "cli/lights_command.h"
#include "cli/render_command.h"
#include "cli/replay_command.h"
#include "cli/track_command.h"

int main(int argc, char** argv) {
    CLI::App app("previs: on-set AR previsualization (differential progressive path tracing)");
    app.require_subcommand(1);
    auto runRender = previs::addRenderCommand(app);
    auto runTrack = previs::addTrackCommand(app);
    auto runEnvmap = previs::addEnvmapCommand(app);
    auto runLights = previs::addLightsCommand(app);
    auto runBench = previs::addBenchCommand(app);
    auto runReplay = previs::addReplayCommand(app);
    auto runCtl = previs::addCtlCommand(app);
    auto runCompare = previs::addCompareCommand(app);
    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        // Usage errors exit with 2 (DESIGN.md §3), --help with 0.
        int code = app.exit(e);
        return code == 0 ? 0 : 2;
    }
    if (app.got_subcommand("render")) return runRender();
    if (app.got_subcommand("track")) return runTrack();
    if (app.got_subcommand("envmap")) return runEnvmap();
    if (app.got_subcommand("lights")) return runLights();
    if (app.got_subcommand("bench")) return runBench();
    if (app.got_subcommand("replay")) return runReplay();
    if (app.got_subcommand("ctl")) return runCtl();
    if (app.got_subcommand("compare")) return runCompare();
    return 2;
}
