#pragma once

#include <CLI/CLI.hpp>

namespace previs {

// `previs compare IMAGE REFERENCE`: the error metrics of DESIGN.md §4 between two linear images
// (RMSE and relMSE over pixels and RGB channels); registers the subcommand, the returned
// function runs it and gives the process exit code.
std::function<int()> addCompareCommand(CLI::App& app);

}  // namespace previs
