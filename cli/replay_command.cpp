#include "cli/replay_command.h"

#include <memory>

#include "base/log.h"
#include "take/replay.h"

namespace previs {

std::function<int()> addReplayCommand(CLI::App& app) {
    auto o = std::make_shared<ReplayOptions>();
    auto mode = std::make_shared<std::string>();
    CLI::App* cmd = app.add_subcommand(
        "replay", "run the service pipeline over a recorded session, frame by frame");
    cmd->add_option("SESSION_DIR", o->sessionDir, "the session folder (docs/session-format.md)")
        ->required()
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--config", o->configPath,
                    "service config (default: the session's own config.toml)")
        ->check(CLI::ExistingFile);
    cmd->add_option("--out", o->outDir, "output folder for frame_NNNNNN.png and frames.csv")
        ->capture_default_str();
    cmd->add_option("--mode", *mode,
                    "hold this mode for the whole session, ignoring its recorded button presses")
        ->check(CLI::IsMember({"preview", "refine"}));
    cmd->add_flag("--exr", o->exr, "also write the linear composite as frame_NNNNNN.exr");
    cmd->add_flag("--quiet", o->quiet, "no per-frame progress line");
    return [o, mode] {
        if (!mode->empty()) o->mode = parseMode(*mode);
        return runReplay(*o);
    };
}

}  // namespace previs
