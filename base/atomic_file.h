#pragma once

// The one way previs writes a file that must appear whole or not at all (a take's frames and
// indices' neighbours, a rendered frame, the files output, a calibration, the shader cache): the
// bytes go to a fresh temporary beside the target, which commit() makes durable (when asked) and
// renames over it.
//
// The temporary is `<path>.<random>.tmp` (or `.<name>.<random>.tmp`, hidden, in the same folder),
// created with O_CREAT | O_EXCL | O_NOFOLLOW: whatever already lies at a name — a killed writer's
// leftover, a symbolic link someone planted, a FIFO — is never opened, followed, truncated or
// removed; a fresh name is drawn instead. Two writers of one target never share a temporary, so
// the target is always one writer's whole file.

#include <span>
#include <string>

#include "base/result.h"
#include "base/unique_fd.h"

namespace previs {

struct AtomicFileOptions {
    // fdatasync the temporary before the rename, so a power cut leaves the old file or the whole
    // new one (the caller fsyncs the folder to keep the rename itself). Off for files that are
    // only ever looked at live (the files output).
    bool durable = true;
    // A hidden temporary (".<name>.<random>.tmp"), for folders other programs list (the files
    // output, the shader cache).
    bool hidden = false;
};

class AtomicFile {
public:
    // Creates the temporary for `path` (its folder must exist). The error names the temporary and
    // why.
    static Result<AtomicFile> create(const std::string& path,
                                     const AtomicFileOptions& options = {});

    AtomicFile(AtomicFile&& other) noexcept;
    AtomicFile& operator=(AtomicFile&& other) noexcept;
    AtomicFile(const AtomicFile&) = delete;
    AtomicFile& operator=(const AtomicFile&) = delete;
    // Not committed: the temporary goes (a full disk must not fill further).
    ~AtomicFile() { discard(); }

    // The temporary's descriptor (write-only, at offset 0), for a writer that takes one.
    int fd() const { return fd_.get(); }
    const std::string& path() const { return path_; }
    const std::string& temporaryPath() const { return temporary_; }

    // Appends all of `bytes` (retrying short writes).
    Status write(std::span<const uint8_t> bytes);
    // fdatasync (when durable), close and rename over the target. Once, after the last write;
    // on failure the temporary is removed and the target left as it was.
    Status commit();
    // Removes the temporary now (nothing when committed or moved from).
    void discard();

private:
    AtomicFile(std::string path, std::string temporary, UniqueFD fd, bool durable)
        : path_(std::move(path)),
          temporary_(std::move(temporary)),
          fd_(std::move(fd)),
          durable_(durable) {}

    std::string path_;
    std::string temporary_;  // empty once committed, discarded or moved from
    UniqueFD fd_;
    bool durable_ = true;
};

// A whole file in one call: AtomicFile::create, write, commit.
Status writeFileAtomic(const std::string& path, std::span<const uint8_t> bytes,
                       const AtomicFileOptions& options = {});

}  // namespace previs
