#include "cli/lights_command.h"

#include "base/log.h"

namespace previs {

std::function<int()> addLightsCommand(CLI::App& app) {
    app.add_subcommand("lights", "(in progress)");
    return [] {
        logError("previs lights: not implemented yet");
        return 1;
    };
}

}  // namespace previs
