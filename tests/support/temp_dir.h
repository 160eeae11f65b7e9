#pragma once

// A per-process scratch folder for tests that write files, removed when the test binary exits
// so repeated runs leave nothing behind.

#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>

namespace previs::testing {

inline std::filesystem::path scratchDir(const std::string& prefix) {
    static const auto dir =
        std::filesystem::temp_directory_path() / (prefix + "_" + std::to_string(::getpid()));
    struct Cleanup {
        ~Cleanup() {
            std::error_code ec;
            std::filesystem::remove_all(dir, ec);
        }
    };
    static Cleanup cleanup;
    std::filesystem::create_directories(dir);
    return dir;
}

// A test's own folder in the scratch folder, empty: what an earlier case left is removed; not
// created (the code under test may be what creates it).
inline std::filesystem::path emptyScratchDir(const std::string& prefix, const std::string& name) {
    const auto dir = scratchDir(prefix) / name;
    std::filesystem::remove_all(dir);
    return dir;
}

}  // namespace previs::testing
