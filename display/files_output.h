#pragma once

// Headless outputs: PNG files into a folder (what `previs replay` and CI look at) and nothing.

#include <string>

#include "display/frame_output.h"

namespace previs {

// Writes each frame as rendered (status overlaid, no letterbox, render size) to
// FOLDER/frame_NNNNNN.png (NNNNNN = DisplayFrame::index); a file appears whole or not at all
// (written to a hidden temporary name, then renamed).
class FilesOutput : public FrameOutput {
public:
    // Creates the folder if missing.
    static Result<std::unique_ptr<FilesOutput>> create(const std::string& folder);

    Status show(const DisplayFrame& frame) override;
    std::string kind() const override { return "files"; }

    // The path frame `index` is written to.
    std::string framePath(uint64_t index) const;

private:
    explicit FilesOutput(std::string folder) : folder_(std::move(folder)) {}
    std::string folder_;
};

class NoneOutput : public FrameOutput {
public:
    Status show(const DisplayFrame&) override { return {}; }
    std::string kind() const override { return "none"; }
};

}  // namespace previs
