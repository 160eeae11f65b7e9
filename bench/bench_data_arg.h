#pragma once

// The data folder a standalone bench binary reads: its first argument, else the shared data
// (base/data_paths.h). Neither: one line saying what to pass, and no folder.

#include <optional>
#include <string>

#include "base/data_paths.h"
#include "base/log.h"

namespace previs::bench {

inline std::optional<std::string> dataDirArgument(int argc, char** argv) {
    if (argc > 1) return std::string(argv[1]);
    if (const auto shared = sharedDataDir()) return shared->string();
    logError("no shared data found: pass DATA_DIR or set PREVIS_DATA_DIR");
    return std::nullopt;
}

}  // namespace previs::bench
