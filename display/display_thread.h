#pragma once

// The display thread (DESIGN.md §6): owns a FrameOutput and shows the newest submitted frame.
// The render thread never waits for it: submit() replaces a frame not yet shown (counted as
// dropped), and a slow output only makes more drops.

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "base/latest_value_slot.h"
#include "base/stage_watch.h"
#include "display/frame_output.h"

namespace previs {

struct DisplayStats {
    uint64_t shown = 0;    // show() succeeded on a live output
    uint64_t dropped = 0;  // replaced by a newer frame before the thread took it, or the
                           // output was still busy with the previous one (lastFrameDropped)
    uint64_t failed = 0;   // show() returned an error, or the output was lost
    std::string kind;      // the output's kind() after its last show ("kms", "lost", ...)
    // Steady clock (CLOCK_MONOTONIC, as captureTimestampNs) when the last show() returned; for
    // KMS the flip is then queued and on screen at the next vblank (≤ one refresh later).
    int64_t lastShownNs = 0;
    int64_t lastCaptureTimestampNs = 0;  // that frame's captureTimestampNs
    uint64_t lastIndex = 0;              // that frame's index
};

class DisplayThread {
public:
    // Starts the thread. `stage`: the service's watch over it (base/stage_watch.h): a frame the
    // output never finishes showing is a hang.
    explicit DisplayThread(std::unique_ptr<FrameOutput> output, Stage* stage = nullptr);
    ~DisplayThread();
    DisplayThread(const DisplayThread&) = delete;
    DisplayThread& operator=(const DisplayThread&) = delete;

    // Never blocks beyond a pointer swap.
    void submit(std::shared_ptr<const DisplayFrame> frame);
    // Finishes the frame being shown (bounded by the output: ≤ ~100 ms for KMS) and joins.
    // Frames still waiting are not shown. Idempotent.
    void stop();

    DisplayStats stats() const;
    // For output-specific counters (e.g. KmsOutput::counters(), which are thread-safe).
    FrameOutput& output() { return *output_; }

private:
    void run();

    std::unique_ptr<FrameOutput> output_;
    Stage* stage_;
    LatestValueSlot<DisplayFrame> slot_;
    bool stopping_ = false;  // guarded by slot_.mutex()
    std::atomic<uint64_t> dropped_{0};
    mutable std::mutex statsMutex_;
    DisplayStats stats_;  // except dropped, guarded by statsMutex_
    std::thread thread_;  // last: started after everything it uses exists
};

}  // namespace previs
