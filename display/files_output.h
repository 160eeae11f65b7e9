#pragma once

// Headless outputs: PNG files into a folder (what `previs replay` and CI look at) and nothing.

#include <cstdint>
#include <deque>
#include <map>
#include <string>

#include "display/frame_output.h"

namespace previs {

// Writes each frame as rendered (status overlaid, no letterbox, render size) to
// FOLDER/frame_NNNNNN.png (NNNNNN = DisplayFrame::index); a file appears whole or not at all
// (written to a hidden temporary, then renamed: base/atomic_file.h). The oldest frames beyond
// the limits are removed as new ones come, frames a previous run left counted among them; below
// the free-space floor a frame is not written (one warning, counted as a drop) until space is
// back.
class FilesOutput : public FrameOutput {
public:
    // Creates the folder if missing; removes the temporaries a killed run left there.
    static Result<std::unique_ptr<FilesOutput>> create(const std::string& folder,
                                                       const FilesOutputLimits& limits = {});

    Status show(const DisplayFrame& frame) override;
    std::string kind() const override { return "files"; }
    bool lastFrameDropped() const override { return lastDropped_; }

    // The path frame `index` is written to.
    std::string framePath(uint64_t index) const;

private:
    FilesOutput(std::string folder, const FilesOutputLimits& limits)
        : folder_(std::move(folder)), limits_(limits) {}
    void adoptExisting();
    // Whether the folder's disk has room for `bytes` above the floor; says so once a spell.
    bool roomFor(uint64_t bytes);
    void remember(uint64_t index, uint64_t bytes);
    void prune();

    std::string folder_;
    FilesOutputLimits limits_;
    // The frames in the folder, oldest first: (index, generation) in order of writing, sizes by
    // index. A frame written again (a new run counts from 0) gets a new generation; its older
    // place in the order is skipped.
    std::deque<std::pair<uint64_t, uint64_t>> order_;
    std::map<uint64_t, std::pair<uint64_t, uint64_t>> frames_;  // index → (bytes, generation)
    uint64_t totalBytes_ = 0;
    uint64_t generation_ = 0;
    bool lastDropped_ = false;
    bool lowOnSpace_ = false;
};

class NoneOutput : public FrameOutput {
public:
    Status show(const DisplayFrame&) override { return {}; }
    std::string kind() const override { return "none"; }
};

}  // namespace previs
