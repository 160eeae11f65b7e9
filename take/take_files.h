#pragma once

// What makes a take self-contained (docs/session-format.md v3, "config/"): every file the
// service config names — the scene and the files it names in turn (a description's glTF and
// environment map, a glTF's buffers and images), the calibrations, the board — copied into the
// take, and the config rewritten to name the copies and the take's own cameras. The same list
// checks a take from elsewhere: everything it names stays inside its folder.

#include <string>
#include <vector>

#include "base/result.h"
#include "config/service_config.h"
#include "io/session.h"

namespace previs {

// The files a scene file names, absolute and normalised, the scene file itself first: a
// description's glTF and environment map (not the bundled "studio"), a glTF's external buffers
// and images (data: URIs hold their bytes inline). A .glb's external URIs are read from its
// JSON chunk. With `takeDir`, each file must lie inside it (containedPath) before it is read.
Result<std::vector<std::string>> sceneFiles(const std::string& scenePath,
                                            const std::string& takeDir = "");

// Copies what `config` names into TAKE/config/ and returns the text of TAKE/config.toml: the
// original with its paths pointing at the copies (relative to the take folder), its cameras
// replaying the take's own cameras/<name>/, and what belongs to the box alone (output, button,
// control socket, recording, saved lighting) removed. The original is kept verbatim as
// config/recorded-from.toml.
Result<std::string> copyConfigIntoTake(const ServiceConfig& config, const std::string& takeDir);

// A take's config and scene name only files inside the take (no absolute path, no "..", no
// symbolic link, regular files of bounded size): one line naming the file and the path when
// not. `configDirInTake`: session.toml's config_dir, where the config's relative paths start.
Status checkTakeContained(const std::string& takeDir, const std::string& configPath,
                          const std::string& configDirInTake = "");

// The service config a session was recorded with (its config.toml; docs/session-format.md),
// checked with checkTakeContained first, whatever version the session declares.
Result<ServiceConfig> loadSessionConfig(const SessionInfo& session);

}  // namespace previs
