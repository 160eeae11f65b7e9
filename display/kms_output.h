#pragma once

// A KMS display through libdrm: one connector, one mode, two XRGB8888 dumb buffers flipped on
// vblank. Atomic modesetting where the driver has it, legacy SetCrtc/PageFlip otherwise. A
// display that cannot be opened, or goes away, makes the output "lost": one log line, then a
// quiet retry every 2 s from show(); the service never fails because of its monitor.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>

#include "display/frame_output.h"

namespace previs {

class KmsDevice;

struct KmsCounters {
    uint64_t flipsCompleted = 0;  // vblank events for our page flips
    uint64_t framesDropped = 0;   // show() gave up: the previous flip was still pending
    uint32_t lastVblank = 0;      // the CRTC's vblank sequence number of the last flip
};

// show() and kind() are the FrameOutput contract; counters() may be read from any thread.
class KmsOutput : public FrameOutput {
public:
    // Errors are the user's only: a bad mode string, or a connector or mode that the present
    // device does not have (the message lists the available ones). A missing device, no
    // connected display or another DRM master give a "lost" output (logged once).
    static Result<std::unique_ptr<KmsOutput>> create(const OutputSettings& settings);
    ~KmsOutput() override;

    // Composes into the back buffer and queues a flip for the next vblank, after waiting up to
    // ~100 ms for the previous flip (else the frame is dropped and counted).
    Status show(const DisplayFrame& frame) override;
    std::string kind() const override { return lost_ ? "lost" : "kms"; }
    bool lastFrameDropped() const override { return lastDropped_; }

    // Thread-safe (the benchmark reads them while the display thread shows).
    KmsCounters counters() const {
        return {flipsCompleted_.load(), framesDropped_.load(), lastVblank_.load()};
    }

    // The methods below, like show(), belong to the thread that shows (the display thread).

    // Waits (bounded, ~100 ms) until no flip is pending, so what is scanned out is the last frame
    // shown. True when idle.
    bool waitIdle();

    // The mode in use (0×0 while lost), and a description such as "card0 Virtual-1 1024x768@60
    // atomic".
    uint32_t modeWidth() const;
    uint32_t modeHeight() const;
    std::string describe() const;

private:
    explicit KmsOutput(const OutputSettings& settings);
    void markLost(const std::string& why);
    void retryOpen();

    OutputSettings settings_;
    std::unique_ptr<KmsDevice> device_;
    std::atomic<bool> lost_{true};
    std::chrono::steady_clock::time_point lastAttempt_;
    std::chrono::steady_clock::time_point lastConnectorCheck_;
    std::atomic<uint64_t> flipsCompleted_{0};
    std::atomic<uint64_t> framesDropped_{0};
    std::atomic<uint32_t> lastVblank_{0};
    std::string lastRetryWarning_;
    bool lastDropped_ = false;  // the display thread's own: set and read there only  // the last
                                // user-caused retry failure logged
};

// Parses an [output] mode string: "WIDTHxHEIGHT" or "WIDTHxHEIGHT@HZ" (hz 0 = any). False if
// malformed.
bool parseModeString(const std::string& text, uint32_t* width, uint32_t* height, uint32_t* hz);

}  // namespace previs
