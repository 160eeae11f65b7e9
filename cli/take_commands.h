#pragma once

#include <CLI/CLI.hpp>
#include <functional>

namespace previs {

// `previs render-session TAKE --out DIR [--frames RANGE] [--spp N | --target-noise X]
// [--aov LIST] [--width W --height H] [--plan N]` (take/take_render.h).
std::function<int()> addRenderSessionCommand(CLI::App& app);

// `previs export-track TAKE --out FILE.chan|FILE.jsonl [--smoothed]` (take/track_export.h).
std::function<int()> addExportTrackCommand(CLI::App& app);

}  // namespace previs
