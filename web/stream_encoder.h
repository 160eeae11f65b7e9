#pragma once

// The MJPEG stream's encoder (docs/web-monitor.md): one thread that takes the newest submitted
// frame at most `fps` times a second, downscales it and encodes it to JPEG once; every viewer
// then sends that same encoded frame. The display thread only swaps a pointer (submit), viewers
// only copy a shared_ptr (waitNewer), so neither a slow encoder nor a slow viewer can hold up
// the render, and N viewers cost one encode per frame. Nothing is encoded while nobody watches.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "base/latest_value_slot.h"
#include "base/result.h"
#include "web/web_frame.h"

namespace previs {

struct StreamEncoderSettings {
    double fps = 10.0;     // encodes per second at most (the stream's frame rate)
    int width = 640;       // stream width in pixels; the height keeps the aspect; never upscaled
    int jpegQuality = 80;  // cv::IMWRITE_JPEG_QUALITY, 1..100
};

struct EncodedFrame {
    std::string jpeg;
    uint64_t sequence = 0;     // 1, 2, 3... one per encode: a viewer's gap is its drop count
    uint64_t sourceIndex = 0;  // WebFrame::index of the frame it shows
    int width = 0;
    int height = 0;
};

struct EncoderStats {
    uint64_t submitted = 0;     // frames given to submit()
    uint64_t encoded = 0;       // JPEG encodes done (the cost: one per stream frame)
    uint64_t failed = 0;        // frames OpenCV could not encode (logged once each)
    int viewers = 0;            // viewers registered now
    double lastEncodeMs = 0.0;  // downscale + encode of the last frame
    double meanEncodeMs = 0.0;  // over all encodes
    size_t lastJpegBytes = 0;
};

// Downscales `frame` to `width` (keeping its aspect; never upscales) and encodes it as JPEG.
// Errors: an empty frame or an OpenCV failure (its exception is caught here).
Result<std::string> encodeJpeg(const WebFrame& frame, int width, int quality,
                               int* outWidth = nullptr, int* outHeight = nullptr);

class StreamEncoder {
public:
    static Result<std::unique_ptr<StreamEncoder>> create(const StreamEncoderSettings& settings);
    ~StreamEncoder();
    StreamEncoder(const StreamEncoder&) = delete;
    StreamEncoder& operator=(const StreamEncoder&) = delete;

    // Any thread; returns after a pointer swap (never waits for an encode).
    void submit(WebFrame frame);

    // A viewer registers for its lifetime: the encoder runs only while one is registered.
    void addViewer();
    void removeViewer();

    // The newest encoded frame whose sequence is above `after`, waiting up to `timeout` for
    // one; null on timeout or after stop().
    std::shared_ptr<const EncodedFrame> waitNewer(uint64_t after,
                                                  std::chrono::milliseconds timeout) const;
    // The sequence of the newest encoded frame (0 before the first).
    uint64_t latestSequence() const;

    EncoderStats stats() const;
    // Ends the encoder thread and wakes every waitNewer(); idempotent.
    void stop();

private:
    explicit StreamEncoder(const StreamEncoderSettings& settings);
    void run();
    void encodeAndPublish(const WebFrame& frame);

    const StreamEncoderSettings settings_;
    LatestValueSlot<WebFrame> input_;

    mutable std::mutex mutex_;
    // Wakes the encoder (a viewer came, stop) and the viewers (a new frame, stop).
    mutable std::condition_variable encoderWake_;
    mutable std::condition_variable frameReady_;
    bool stopping_ = false;
    int viewers_ = 0;
    std::shared_ptr<const EncodedFrame> latest_;
    uint64_t encoded_ = 0;
    uint64_t failed_ = 0;
    double encodeMsTotal_ = 0.0;
    double lastEncodeMs_ = 0.0;

    std::thread thread_;
};

}  // namespace previs
