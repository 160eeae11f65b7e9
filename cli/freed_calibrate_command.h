#pragma once

#include <CLI/CLI.hpp>
#include <functional>

namespace previs {

// `previs freed-calibrate TAKE [--out FILE] [--camera-id N] [--recorded-poses]`: the FreeD
// input calibration (net/freed_calibration.h) of a take that holds the tracker's packets
// (freed.csv) and the tag board in view; docs/freed.md "FreeD in: calibration".
std::function<int()> addFreedCalibrateCommand(CLI::App& app);

}  // namespace previs
