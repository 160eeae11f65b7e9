#pragma once

#include <CLI/CLI.hpp>

namespace previs {

// `previs compare A B`: the root-mean-square difference of two linear images (every pixel and
// channel) and their means, one line on stdout; bench/compare_blender.sh's error measure.
std::function<int()> addCompareCommand(CLI::App& app);

}  // namespace previs
