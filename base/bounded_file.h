#pragma once

// Reading a file someone else may have made (a take from a farm submitter, a copied scene): the
// one place previs opens such a file by name. Opened without waiting (a FIFO or a device is
// refused, never read), regular files only, the size checked before a byte is read — so a link
// to /dev/zero, a FIFO or a sparse 3 GiB file costs nothing — and, unless the caller trusts
// links, without following a symbolic link. Errors name the file and why, never its content.

#include <cstdint>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

enum class FileLinks {
    Refuse,  // a take's own files: a link could point anywhere on the reading machine
    Follow,  // a file the operator named (a config, a scene): links are theirs
};

// The whole file, at most `maxBytes`; `what` names it in errors ("camera index", "frame").
Result<std::vector<uint8_t>> readBoundedFile(const std::string& path, uint64_t maxBytes,
                                             FileLinks links = FileLinks::Refuse,
                                             const std::string& what = "file");

// The same, as text.
Result<std::string> readBoundedText(const std::string& path, uint64_t maxBytes,
                                    FileLinks links = FileLinks::Refuse,
                                    const std::string& what = "file");

// What readBoundedFile checks, without reading: for a file a library then opens by name.
Status checkBoundedFile(const std::string& path, uint64_t maxBytes,
                        FileLinks links = FileLinks::Refuse, const std::string& what = "file");

}  // namespace previs
