#pragma once

// Where the service's frames go (DESIGN.md §1 "display", issue 7): a KMS display on the box, a
// folder of PNG files or nothing for headless use. One display thread owns the output and calls
// show() with the newest frame; an output never throws and never blocks for longer than a frame
// period (a KMS output waits at most for the pending page flip).

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

// A tone-mapped frame, ready to show.
struct DisplayFrame {
    uint32_t width = 0;
    uint32_t height = 0;
    std::vector<uint8_t> rgb;  // 8-bit sRGB, 3 bytes per pixel, rows packed (stride = 3·width)
    std::string status;        // the one-line overlay ("PREVIEW 1 spp 9.8 fps"); "" = none
    uint64_t index = 0;        // output frame number, from 0
    int64_t captureTimestampNs = 0;  // the camera frame's timestamp (CLOCK_MONOTONIC)
};

class FrameOutput {
public:
    virtual ~FrameOutput() = default;
    // Shows (or writes) the frame. An error is logged by the caller; the output stays usable
    // and is tried again with the next frame. A KMS output whose display went away reports
    // kind() "lost" and returns success without showing anything until it is back.
    virtual Status show(const DisplayFrame& frame) = 0;
    // DESIGN.md §3 status "display": "kms" | "files" | "none" | "lost".
    virtual std::string kind() const = 0;
    // Whether the last show() succeeded without showing the frame because the output was still
    // busy with the previous one (a page flip not yet done): a drop, not a frame shown.
    virtual bool lastFrameDropped() const { return false; }
};

// What the files output keeps ([output] keep_frames, max_mb, min_free_mb): a service that runs
// for days writes a frame per render, so the folder holds a ring of the newest frames and never
// takes the disk's last free space.
struct FilesOutputLimits {
    uint64_t keepFrames = 1000;                   // the newest this many frames
    uint64_t maxBytes = uint64_t(1) << 30;        // and at most this many bytes of them
    uint64_t minFreeBytes = uint64_t(256) << 20;  // no frame written below this much free space
};

// The service config's [output] table (docs/config-format.md).
struct OutputSettings {
    std::string kind = "none";  // "kms" | "files" | "none"
    std::string folder{};       // files: where frame_NNNNNN.png go (created if missing)
    std::string card{};         // kms: "" = first /dev/dri/card* with a connected connector;
                                // "card0" or a path
    std::string connector{};    // kms: "" = first connected, else a name like "Virtual-1"
    std::string mode{};         // kms: "" = preferred, else "WIDTHxHEIGHT" or "WIDTHxHEIGHT@HZ"
    bool forceLegacy = false;   // kms: legacy SetCrtc/PageFlip even where atomic works (tests)
    FilesOutputLimits files{};  // files: the ring's size and the free-space floor
};

// Builds the configured output. Errors are the user's (unknown kind, a folder that cannot be
// created, a bad mode string, a connector or mode the present device does not have). A KMS
// display that cannot be opened now is not an error: the output reports "lost" and retries.
Result<std::unique_ptr<FrameOutput>> makeFrameOutput(const OutputSettings& settings);

}  // namespace previs
