#pragma once

// Shared by the fuzz targets (docs/fuzzing.md): the parsers take paths, so each input is written
// to a file in a per-process scratch folder under $TMPDIR (never the network, never a device).

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include "base/log.h"

namespace previs::fuzz {

inline const std::filesystem::path& scratchDir() {
    static const std::filesystem::path dir = [] {
        auto d =
            std::filesystem::temp_directory_path() / ("previs_fuzz_" + std::to_string(::getpid()));
        std::filesystem::create_directories(d);
        // The parsers' warnings would flood the fuzzer's output.
        setLogLevel(LogLevel::Error);
        return d;
    }();
    struct Cleanup {
        ~Cleanup() {
            std::error_code ec;
            std::filesystem::remove_all(dir, ec);
        }
    };
    static Cleanup cleanup;
    return dir;
}

// Writes `bytes` to scratchDir()/relPath (creating folders) and returns the full path.
inline std::string writeScratch(const std::string& relPath, std::string_view bytes) {
    const std::filesystem::path path = scratchDir() / relPath;
    std::filesystem::create_directories(path.parent_path());
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), std::streamsize(bytes.size()));
    return path.string();
}

inline std::string_view asText(const uint8_t* data, size_t size) {
    return std::string_view(reinterpret_cast<const char*>(data), size);
}

// Splits an input into up to `parts` files at lines "@@@@" (a multi-file input such as a session
// folder); missing parts are empty.
inline std::vector<std::string_view> splitParts(std::string_view text, size_t parts) {
    std::vector<std::string_view> out;
    constexpr std::string_view kSeparator = "\n@@@@\n";
    while (out.size() + 1 < parts) {
        const size_t at = text.find(kSeparator);
        if (at == std::string_view::npos) break;
        out.push_back(text.substr(0, at + 1));
        text.remove_prefix(at + kSeparator.size());
    }
    out.push_back(text);
    out.resize(parts);
    return out;
}

}  // namespace previs::fuzz
