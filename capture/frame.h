#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

namespace previs {

// One camera frame as handed between threads: built once by the capture thread, then shared as
// std::shared_ptr<const Frame> (an immutable snapshot, DESIGN.md §6), so readers need no locks.
struct Frame {
    uint32_t width = 0;
    uint32_t height = 0;
    // Tightly packed 8-bit RGB, row 0 at the top, width * height * 3 bytes.
    std::vector<uint8_t> rgb;
    // When the sensor finished the frame, CLOCK_MONOTONIC (the kernel's V4L2 buffer timestamp;
    // for recorded sessions the recorded value), so poses and frames from different sources
    // can be matched on one clock.
    uint64_t timestampNs = 0;
    // Frames delivered by this source so far, across reconnects: strictly increasing, and a
    // gap means frames were lost before delivery (the consumer's drops are counted separately).
    uint64_t sequence = 0;
    // The driver's own counter (v4l2_buffer::sequence); restarts at 0 when a device reopens.
    uint32_t deviceSequence = 0;
    // CLOCK_REALTIME when the sensor finished the frame (the capture thread's estimate from
    // timestampNs), so a take can be placed in the day; 0 when unknown.
    uint64_t wallClockNs = 0;
    // A bracketing camera's exposure for this frame, in stops relative to its radiometry (0 = as
    // calibrated, −4 = a sixteenth of the light): what the camera reported (libcamera's metadata)
    // or was set to (V4L2, whose controls land a few frames late; vision/hdr_bracket.h checks
    // it against the pictures). Empty when the camera does not bracket.
    std::optional<float> exposureStops;
    // The frame as the camera sent it, kept only while a take rolls (CaptureOptions::
    // keepCaptured): a JPEG's bytes as they came, a raw format's planes with any line padding
    // removed; `capturedFourcc` names their V4L2 format. The recorder stores these bytes, never
    // re-encoded. Null otherwise.
    std::shared_ptr<const std::vector<uint8_t>> captured;
    uint32_t capturedFourcc = 0;
};

}  // namespace previs
