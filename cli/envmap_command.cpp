#include "cli/envmap_command.h"

#include "base/log.h"

namespace previs {

std::function<int()> addEnvmapCommand(CLI::App& app) {
    app.add_subcommand("envmap", "(in progress)");
    return [] {
        logError("previs envmap: not implemented yet");
        return 1;
    };
}

}  // namespace previs
