#pragma once

// A V4L2 capture device driven through the kernel API (single-planar, mmap streaming), the way
// libcamera's V4L2VideoDevice does it, minus the media graph: UVC webcams, vivid, loopback.

#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "base/result.h"
#include "base/unique_fd.h"
#include "capture/camera_source.h"
#include "capture/exposure_bracket.h"

namespace previs {

struct V4L2Config {
    std::string device = "/dev/video0";
    uint32_t width = 640;
    uint32_t height = 480;
    uint32_t fourcc = 0;       // V4L2_PIX_FMT_*; 0 = YUYV
    double fps = 0;            // 0 = the driver's default rate
    uint32_t bufferCount = 4;  // enough to absorb a late conversion without the driver dropping
    // While set, frames keep the bytes as captured (Frame::captured), for the take recorder.
    const std::atomic<bool>* keepCaptured = nullptr;
    // Controls set on every open, before streaming (a replugged camera comes back in auto
    // exposure): by name as `v4l2-ctl -l` lists them, or by their short id. One that does not
    // apply fails create(): the pictures would not be what the config's radiometry promises.
    std::vector<std::pair<std::string, int32_t>> controls;
    // Exposure bracketing (capture/exposure_bracket.h): `bracket.control` cycles from its value
    // in `controls` through the stops, settling frames are withheld and the others delivered
    // labelled (Frame::exposureStops). A control that is missing, inactive (an automatic mode
    // still owns it) or cannot reach a stop fails create(). Unset: no bracketing.
    std::optional<ExposureBracketConfig> bracket;
};

// A control name as v4l2-ctl prints it: "Exposure Time, Absolute" → "exposure_time_absolute"
// (lower case, each run of other characters one '_', none at the ends): two names for the same
// control compare equal in this form.
std::string v4l2ControlKey(std::string_view name);

class V4L2Device : public FrameReader {
public:
    // Opens and configures the device; reports a missing node, a node that is not a capture
    // device, a format the device does not offer (listing what it offers) and a control that
    // does not apply.
    static Result<std::unique_ptr<V4L2Device>> create(const V4L2Config& config);
    ~V4L2Device() override;
    V4L2Device(const V4L2Device&) = delete;
    V4L2Device& operator=(const V4L2Device&) = delete;

    // Queues every buffer and starts streaming.
    Status start() override;
    // Stops streaming (errors ignored: the device may already be gone).
    void stop();
    Result<bool> read(int timeoutMs, Frame& frame) override;
    uint64_t badFrames() const override { return badFrames_; }
    uint64_t withheldFrames() const override { return cycle_ ? cycle_->settleFrames() : 0; }

    // Sets a control by its driver name ("Exposure Time, Absolute") or v4l2-ctl's form of it
    // ("exposure_time_absolute"), case-insensitive: exposure, gain and white balance come from
    // config this way.
    Status setControl(std::string_view name, int32_t value);

    // While bracketing: the cycle's state (which step, frames withheld); null otherwise.
    const ExposureCycle* exposureCycle() const { return cycle_ ? &*cycle_ : nullptr; }

    const std::string& path() const { return path_; }
    const std::string& card() const { return card_; }
    uint32_t width() const { return width_; }
    uint32_t height() const { return height_; }
    uint32_t fourcc() const { return fourcc_; }
    uint32_t stride() const { return stride_; }
    // The frame interval the driver accepted, in frames per second (0 when unknown).
    double fps() const { return fps_; }

    // The formats `fd` offers, as "YUYV, MJPG, ..." (for error messages and the CLI).
    static std::string listFormats(int fd);

private:
    // An mmap'ed driver buffer, unmapped on destruction.
    struct Mapping {
        void* data = nullptr;
        size_t length = 0;
        Mapping(void* d, size_t l) : data(d), length(l) {}
        Mapping(Mapping&& o) noexcept;
        Mapping& operator=(Mapping&&) = delete;
        Mapping(const Mapping&) = delete;
        ~Mapping();
    };

    explicit V4L2Device(std::string path);
    Status configure(const V4L2Config& config);
    Status allocateBuffers(uint32_t count);
    Status queueBuffer(uint32_t index);
    Status setUpBracket(const ExposureBracketConfig& bracket,
                        const std::vector<std::pair<std::string, int32_t>>& controls);
    // Sets the bracket control to step `step`'s value (by id: no enumeration per frame).
    Status setBracketStep(size_t step);
    // The message for a device that went away mid-stream.
    Error vanished(const char* during, int err) const;

    // Declared first so it is destroyed last: mappings are released while the fd is open.
    UniqueFD fd_;
    std::vector<Mapping> buffers_;
    std::string path_;
    std::string card_;
    uint32_t width_ = 0;
    uint32_t height_ = 0;
    uint32_t fourcc_ = 0;
    const std::atomic<bool>* keepCaptured_ = nullptr;
    uint32_t stride_ = 0;
    double fps_ = 0;
    bool streaming_ = false;
    uint64_t badFrames_ = 0;
    // Bracketing (V4L2Config::bracket): the control's id and name, each step's value and stops.
    std::optional<ExposureCycle> cycle_;
    uint32_t bracketControlId_ = 0;
    std::string bracketControlName_;
    std::vector<int64_t> bracketValues_;
    std::vector<float> bracketStops_;
};

}  // namespace previs
