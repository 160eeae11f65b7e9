#pragma once

#include <CLI/CLI.hpp>
#include <functional>

namespace previs {

// `previs replay SESSION_DIR [--config FILE] [--out DIR] [--mode preview|refine] [--exr]`.
std::function<int()> addReplayCommand(CLI::App& app);

}  // namespace previs
