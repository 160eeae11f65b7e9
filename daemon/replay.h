#pragma once

// `previs replay` (DESIGN.md §3): the service pipeline over a recorded session in lock step —
// every scene-camera frame is tracked, lit by the fisheye frames recorded before it, rendered
// and written; nothing is dropped because a stage was slow. Same session and config ⇒ the same
// pixels: frames are written without the (timing-dependent) status overlay, refinement adds a
// fixed number of samples per frame, and preview uses the fixed random sequence.

#include <optional>
#include <string>

#include "daemon/mode_machine.h"

namespace previs {

struct ReplayOptions {
    std::string sessionDir;
    std::string configPath;  // "" = the session's own config.toml
    std::string outDir = "replay";
    // Fixed mode for the whole session (its button events are then ignored); nullopt = start in
    // preview and follow the recorded button and ctl events.
    std::optional<Mode> mode;
    bool exr = false;  // also write frame_NNNNNN.exr (linear composite)
    bool quiet = false;
};

// 0 on success, 1 on a runtime failure, 2 on a bad session, config or option (one line logged).
int runReplay(const ReplayOptions& options);

}  // namespace previs
