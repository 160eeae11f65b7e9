#pragma once

#include <CLI/CLI.hpp>

namespace previs {

// `previs track` (DESIGN.md §3): AprilTag detection and camera pose on still images. Registers
// the subcommand; the returned function runs it and gives the process exit code.
std::function<int()> addTrackCommand(CLI::App& app);

}  // namespace previs
