#include "daemon/camera_sources.h"

#include "base/log.h"
#include "capture/pixel_format.h"
#include "capture/recorded_source.h"
#include "capture/v4l2_device.h"
#ifdef PREVIS_HAVE_LIBCAMERA
#include "capture/libcamera_camera.h"
#endif

namespace previs {

namespace {

// A recorded camera played over and over. Each pass is shifted by the recording's length plus
// one frame interval, so timestamps keep increasing as a live camera's do.
class LoopingReader : public FrameReader {
public:
    explicit LoopingReader(std::string dir) : dir_(std::move(dir)) {}

    Status start() override { return open(); }
    Result<bool> read(int timeoutMs, Frame& frame) override {
        if (inner_->finished()) {
            // A recording with no readable frame would otherwise be reopened in a tight loop:
            // an error makes the capture thread log it once and retry at its slow pace.
            if (!framesThisPass_) return makeError("{}: no readable frame in the recording", dir_);
            framesThisPass_ = 0;
            offsetNs_ += lastNs_ - firstNs_ + periodNs_;
            if (Status s = open(); !s) return s.error();
        }
        Result<bool> got = inner_->read(timeoutMs, frame);
        if (!got || !*got) return got;
        ++framesThisPass_;
        if (!haveFirst_) {
            firstNs_ = frame.timestampNs;
            haveFirst_ = true;
        } else if (frame.timestampNs > lastNs_ && pass_ == 0) {
            periodNs_ = frame.timestampNs - lastNs_;
        }
        if (pass_ == 0) lastNs_ = frame.timestampNs;
        frame.timestampNs += offsetNs_;
        return true;
    }
    bool isLive() const override { return false; }
    uint64_t badFrames() const override { return inner_ ? inner_->badFrames() : 0; }

private:
    Status open() {
        Result<std::unique_ptr<RecordedReader>> r =
            RecordedReader::create(dir_, ReplayTiming::Recorded);
        if (!r) return r.error();
        inner_ = std::move(*r);
        if (haveFirst_) ++pass_;
        return inner_->start();
    }

    std::string dir_;
    std::unique_ptr<RecordedReader> inner_;
    bool haveFirst_ = false;
    int pass_ = 0;
    uint64_t framesThisPass_ = 0;
    uint64_t firstNs_ = 0, lastNs_ = 0, periodNs_ = 33'333'333, offsetNs_ = 0;
};

}  // namespace

std::unique_ptr<CameraSource> makeCameraSource(
    const CameraConfig& camera, bool loop,
    std::function<void(const std::shared_ptr<const Frame>&)> onFrame,
    const std::atomic<bool>* keepCaptured, Stage* stage) {
    CaptureOptions options;
    options.name = fmt::format("{} camera {}", camera.name, camera.device);
    options.onFrame = std::move(onFrame);
    options.stage = stage;
    switch (camera.source) {
        case CameraSourceKind::Session: {
            if (!loop) return makeRecordedSource(camera.device, ReplayTiming::Recorded, options);
            std::string dir = camera.device;
            return std::make_unique<CaptureThread>(
                [dir]() -> Result<std::unique_ptr<FrameReader>> {
                    return std::unique_ptr<FrameReader>(std::make_unique<LoopingReader>(dir));
                },
                options);
        }
        case CameraSourceKind::Libcamera: {
#ifdef PREVIS_HAVE_LIBCAMERA
            LibcameraConfig c;
            c.camera = camera.device;
            c.width = camera.width;
            c.height = camera.height;
            c.pixelFormat = camera.pixelFormat;
            c.fps = camera.fps;
            c.exposureUs = camera.exposureUs;
            c.analogueGain = camera.analogueGain;
            c.colourGains = camera.colourGains;
            c.keepCaptured = keepCaptured;
            if (camera.bracket) c.bracketStops = camera.bracket->stops;
            return makeLibcameraSource(c, options);
#else
            // The config reader refuses it in such a build (service_config.cpp); never another
            // path to the camera.
            return std::make_unique<CaptureThread>(
                []() -> Result<std::unique_ptr<FrameReader>> {
                    return makeError("this previs was built without libcamera");
                },
                options);
#endif
        }
        case CameraSourceKind::V4L2:
            break;
    }
    V4L2Config c;
    c.device = camera.device;
    c.width = camera.width;
    c.height = camera.height;
    c.fourcc = camera.pixelFormat.empty() ? 0 : fourccFromString(camera.pixelFormat);
    c.fps = camera.fps;
    c.keepCaptured = keepCaptured;
    // Set on every (re)open (V4L2Device::create): a camera whose controls do not apply is in
    // error, not streaming wrong pictures; the capture thread says why and tries again.
    for (const auto& [control, value] : camera.controls)
        c.controls.emplace_back(control, int32_t(value));
    // Bracketing: the device cycles the control and labels the frames it delivers; the lighting
    // stage's assembler checks the labels against the pictures (vision/hdr_bracket.h).
    if (camera.bracket)
        c.bracket = ExposureBracketConfig{camera.bracket->stops, camera.bracketFramesPerStep,
                                          camera.bracketControl};
    return std::make_unique<CaptureThread>(
        [c]() -> Result<std::unique_ptr<FrameReader>> {
            Result<std::unique_ptr<V4L2Device>> device = V4L2Device::create(c);
            if (!device) return device.error();
            return std::unique_ptr<FrameReader>(std::move(*device));
        },
        options);
}

}  // namespace previs
