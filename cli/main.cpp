// previs: the command line (DESIGN.md §3). Exit codes: 0 success, 1 runtime failure, 2 bad usage
// or input (base/command_line.h), the same in every subcommand.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "base/command_line.h"
#include "base/log.h"
#include "base/strings.h"
#include "cli/bench_command.h"
#include "cli/compare_command.h"
#include "cli/ctl_command.h"
#include "cli/envmap_command.h"
#include "cli/freed_calibrate_command.h"
#include "cli/lights_command.h"
#include "cli/render_command.h"
#include "cli/replay_command.h"
#include "cli/take_commands.h"
#include "cli/track_command.h"

#ifndef PREVIS_VERSION
#define PREVIS_VERSION "unknown"
#endif

int main(int argc, char** argv) {
    using namespace previs;
    CLI::App app("previs: on-set AR previsualization (differential progressive path tracing)",
                 "previs");
    app.set_version_flag("--version", "previs " PREVIS_VERSION);
    app.require_subcommand(1);
    useOneLineUsageErrors(app);
    auto runRender = addRenderCommand(app);
    auto runTrack = addTrackCommand(app);
    auto runEnvmap = addEnvmapCommand(app);
    auto runLights = addLightsCommand(app);
    auto runBench = addBenchCommand(app);
    auto runReplay = addReplayCommand(app);
    auto runCtl = addCtlCommand(app);
    auto runCompare = addCompareCommand(app);
    auto runRenderSession = addRenderSessionCommand(app);
    auto runExportTrack = addExportTrackCommand(app);
    auto runFreedCalibrate = addFreedCalibrateCommand(app);
    std::vector<std::string> names;
    for (const CLI::App* sub : app.get_subcommands({})) names.push_back(sub->get_name());
    if (argc > 1 && argv[1][0] != '-' &&
        std::find(names.begin(), names.end(), argv[1]) == names.end()) {
        std::fprintf(stderr, "previs: '%s' is not a command (%s); see previs --help\n", argv[1],
                     joined(names).c_str());
        return kExitUsage;
    }
    if (auto exitCode = parseCommandLine(app, argc, argv)) return *exitCode;
    return runReportingExceptions("previs", [&] {
        if (app.got_subcommand("render")) return runRender();
        if (app.got_subcommand("track")) return runTrack();
        if (app.got_subcommand("envmap")) return runEnvmap();
        if (app.got_subcommand("lights")) return runLights();
        if (app.got_subcommand("bench")) return runBench();
        if (app.got_subcommand("replay")) return runReplay();
        if (app.got_subcommand("ctl")) return runCtl();
        if (app.got_subcommand("compare")) return runCompare();
        if (app.got_subcommand("render-session")) return runRenderSession();
        if (app.got_subcommand("export-track")) return runExportTrack();
        if (app.got_subcommand("freed-calibrate")) return runFreedCalibrate();
        return kExitUsage;
    });
}
