#pragma once

#include <functional>

#include <CLI/CLI.hpp>

namespace previs {

// `previs replay SESSION_DIR [--config FILE] [--out DIR] [--mode preview|refine] [--exr]`.
std::function<int()> addReplayCommand(CLI::App& app);

}  // namespace previs
