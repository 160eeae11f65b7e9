#pragma once

#include <CLI/CLI.hpp>

namespace previs {

// `previs bench`: registers the subcommand; the returned function runs it.
std::function<int()> addBenchCommand(CLI::App& app);

}  // namespace previs
