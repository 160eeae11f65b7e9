#pragma once

#include <CLI/CLI.hpp>

namespace previs {

// `previs lights` (DESIGN.md §3): registers the subcommand; the returned function runs it and gives
// the process exit code.
std::function<int()> addLightsCommand(CLI::App& app);

}  // namespace previs
