#pragma once

#include <CLI/CLI.hpp>
#include <functional>

namespace previs {

// `previs ctl [--socket PATH] status [--json] | mode preview|refine | toggle` (DESIGN.md §3).
std::function<int()> addCtlCommand(CLI::App& app);

}  // namespace previs
