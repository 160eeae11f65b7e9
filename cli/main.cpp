// previs: the command line (DESIGN.md §3). Exit codes: 0 success, 1 runtime failure, 2 bad usage
// or input (base/command_line.h), the same in every subcommand.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <functional>
#include <string>
#include <utility>
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
    // Each subcommand with its runner: an add function adds one subcommand, the app's last.
    std::vector<std::pair<const CLI::App*, std::function<int()>>> commands;
    for (auto add : {addRenderCommand, addTrackCommand, addEnvmapCommand, addLightsCommand,
                     addBenchCommand, addReplayCommand, addCtlCommand, addCompareCommand,
                     addRenderSessionCommand, addExportTrackCommand, addFreedCalibrateCommand}) {
        std::function<int()> run = add(app);
        commands.emplace_back(app.get_subcommands({}).back(), std::move(run));
        PV_ASSERT(app.get_subcommands({}).size() == commands.size());  // one subcommand each
    }
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
        for (const auto& [sub, run] : commands)
            if (sub->parsed()) return run();
        return kExitUsage;
    });
}
