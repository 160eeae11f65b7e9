#include "web/stream_encoder.h"

#include <algorithm>
#include <exception>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "base/guarded_thread.h"
#include "base/log.h"

namespace previs {

namespace {

using Clock = std::chrono::steady_clock;

// How long the encoder waits for a frame before it looks at stop and the viewer count again.
constexpr std::chrono::milliseconds kInputPoll{100};

}  // namespace

Result<std::string> encodeJpeg(const WebFrame& frame, int width, int quality, int* outWidth,
                               int* outHeight) {
    if (!frame.rgb || frame.width == 0 || frame.height == 0)
        return makeError("web stream: empty frame ({}x{})", frame.width, frame.height);
    const size_t stride = frame.strideBytes ? frame.strideBytes : size_t(frame.width) * 3;
    try {
        // cv::Mat only borrows the pixels (const_cast: OpenCV has no const view type; nothing
        // writes to src).
        const cv::Mat src(int(frame.height), int(frame.width), CV_8UC3,
                          const_cast<uint8_t*>(frame.rgb), stride);
        cv::Mat scaled = src;
        if (width > 0 && int(frame.width) > width) {
            const int height =
                std::max(1, int(std::lround(double(frame.height) * width / double(frame.width))));
            // INTER_AREA: the antialiased choice for shrinking (no moiré on fine scene detail).
            cv::resize(src, scaled, cv::Size(width, height), 0, 0, cv::INTER_AREA);
        }
        // imencode takes BGR; converting after the downscale touches the fewest pixels.
        cv::Mat bgr;
        cv::cvtColor(scaled, bgr, cv::COLOR_RGB2BGR);
        std::vector<uint8_t> bytes;
        const std::vector<int> params{cv::IMWRITE_JPEG_QUALITY, std::clamp(quality, 1, 100)};
        if (!cv::imencode(".jpg", bgr, bytes, params))
            return makeError("web stream: OpenCV could not encode a {}x{} JPEG", bgr.cols,
                             bgr.rows);
        if (outWidth) *outWidth = bgr.cols;
        if (outHeight) *outHeight = bgr.rows;
        return std::string(bytes.begin(), bytes.end());
    } catch (const std::exception& e) {
        return makeError("web stream: JPEG encode failed: {}", e.what());
    }
}

Result<std::unique_ptr<StreamEncoder>> StreamEncoder::create(
    const StreamEncoderSettings& settings) {
    if (!(settings.fps > 0.0 && settings.fps <= 120.0))
        return makeError("[web] stream_fps must be in (0, 120], not {}", settings.fps);
    if (settings.width < 16 || settings.width > 7680)
        return makeError("[web] stream_width must be 16..7680 pixels, not {}", settings.width);
    if (settings.jpegQuality < 1 || settings.jpegQuality > 100)
        return makeError("[web] jpeg_quality must be 1..100, not {}", settings.jpegQuality);
    std::unique_ptr<StreamEncoder> encoder(new StreamEncoder(settings));
    encoder->thread_ =
        std::thread([e = encoder.get()] { runGuarded("web encoder", [e] { e->run(); }); });
    return encoder;
}

StreamEncoder::StreamEncoder(const StreamEncoderSettings& settings) : settings_(settings) {}

StreamEncoder::~StreamEncoder() {
    stop();
    if (thread_.joinable()) thread_.join();
}

void StreamEncoder::submit(WebFrame frame) {
    input_.publish(std::make_shared<const WebFrame>(std::move(frame)));
}

void StreamEncoder::addViewer() {
    {
        std::lock_guard lock(mutex_);
        ++viewers_;
    }
    encoderWake_.notify_all();
}

void StreamEncoder::removeViewer() {
    std::lock_guard lock(mutex_);
    --viewers_;
}

std::shared_ptr<const EncodedFrame> StreamEncoder::waitNewer(
    uint64_t after, std::chrono::milliseconds timeout) const {
    std::unique_lock lock(mutex_);
    frameReady_.wait_for(lock, timeout,
                         [&] { return stopping_ || (latest_ && latest_->sequence > after); });
    if (stopping_ || !latest_ || latest_->sequence <= after) return nullptr;
    return latest_;
}

uint64_t StreamEncoder::latestSequence() const {
    std::lock_guard lock(mutex_);
    return latest_ ? latest_->sequence : 0;
}

EncoderStats StreamEncoder::stats() const {
    EncoderStats s;
    s.submitted = input_.published();
    std::lock_guard lock(mutex_);
    s.encoded = encoded_;
    s.failed = failed_;
    s.viewers = viewers_;
    s.lastEncodeMs = lastEncodeMs_;
    s.meanEncodeMs = encoded_ ? encodeMsTotal_ / double(encoded_) : 0.0;
    s.lastJpegBytes = latest_ ? latest_->jpeg.size() : 0;
    return s;
}

void StreamEncoder::stop() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    encoderWake_.notify_all();
    frameReady_.notify_all();
}

void StreamEncoder::run() {
    const auto period = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(1.0 / settings_.fps));
    Clock::time_point due = Clock::now();
    std::unique_lock lock(mutex_);
    while (!stopping_) {
        // Nobody watching: no encode at all (the box's CPU belongs to the render).
        if (viewers_ == 0) {
            encoderWake_.wait(lock, [&] { return stopping_ || viewers_ > 0; });
            continue;
        }
        // The stream's rate: frames arriving faster replace each other in the input slot.
        if (Clock::now() < due) {
            encoderWake_.wait_until(lock, due, [&] { return stopping_; });
            continue;
        }
        lock.unlock();
        std::shared_ptr<const WebFrame> frame = input_.waitTakeFor(kInputPoll);
        const Clock::time_point taken = Clock::now();
        if (frame) encodeAndPublish(*frame);
        lock.lock();
        // Keeps the phase (a frame taken a little late does not lower the rate) but never
        // bursts to catch up after the input paused for longer than a period.
        if (frame) due = std::max(due + period, taken);
    }
}

void StreamEncoder::encodeAndPublish(const WebFrame& frame) {
    const Clock::time_point start = Clock::now();
    auto encoded = std::make_shared<EncodedFrame>();
    Result<std::string> jpeg = encodeJpeg(frame, settings_.width, settings_.jpegQuality,
                                          &encoded->width, &encoded->height);
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    if (!jpeg) {
        logWarning("{}", jpeg.message());
        std::lock_guard lock(mutex_);
        ++failed_;
        return;
    }
    encoded->jpeg = std::move(*jpeg);
    encoded->sourceIndex = frame.index;
    {
        std::lock_guard lock(mutex_);
        encoded->sequence = ++encoded_;
        encodeMsTotal_ += ms;
        lastEncodeMs_ = ms;
        latest_ = std::move(encoded);
    }
    frameReady_.notify_all();
}

}  // namespace previs
