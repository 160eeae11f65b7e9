#pragma once

// Checks, before any long work starts, that an output file can be written: an hour-long render
// must not end in "cannot open file" (issue 11).

#include <unistd.h>

#include <filesystem>
#include <string>
#include <system_error>

#include "base/result.h"

namespace previs {

// `option` names the flag in the message ("--out").
inline Status checkOutputFile(const std::string& option, const std::string& path) {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path p(path);
    if (path.empty() || p.filename().empty())
        return makeError("{} '{}': give a file name, not a folder", option, path);
    const fs::path folder = p.has_parent_path() ? p.parent_path() : fs::path(".");
    if (!fs::is_directory(folder, ec))
        return makeError("{} {}: the folder {} does not exist (create it first)", option, path,
                         folder.string());
    if (fs::exists(p, ec)) {
        if (fs::is_directory(p, ec))
            return makeError("{} {}: is a folder; give a file name", option, path);
        if (::access(path.c_str(), W_OK) != 0)
            return makeError("{} {}: the file exists and is not writable", option, path);
    } else if (::access(folder.c_str(), W_OK) != 0) {
        return makeError("{} {}: the folder {} is not writable", option, path, folder.string());
    }
    return {};
}

}  // namespace previs
