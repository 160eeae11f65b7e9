#pragma once

#include <CLI/CLI.hpp>

namespace previs {

// `previs compare IMAGE REFERENCE`: DESIGN.md §4's error metrics between two linear images —
// RMSE and relMSE over every pixel and channel — and their means, one line on stdout (the error
// measure of bench/compare_blender.sh and bench/sampler_ablation.sh).
std::function<int()> addCompareCommand(CLI::App& app);

}  // namespace previs
