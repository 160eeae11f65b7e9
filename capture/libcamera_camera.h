#pragma once

// A camera driven through libcamera (CSI sensors behind an ISP: Raspberry Pi, Rockchip, IPU3;
// also UVC and vimc), behind the same FrameReader interface as V4L2Device. Built only when
// libcamera is found (PREVIS_HAVE_LIBCAMERA). libcamera's types stay in the .cpp, so code that
// uses this header needs neither libcamera's headers nor its include path.

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "capture/camera_source.h"

namespace previs {

struct LibcameraConfig {
    // While set, frames keep the bytes as captured (Frame::captured), for the take recorder.
    const std::atomic<bool>* keepCaptured = nullptr;
    // The camera's libcamera id ("platform/vimc.0 Sensor B", as `cam -l` prints it), its index
    // in libcamera's list ("0"), or a part of the id that names one camera ("imx477");
    // "" = the first camera.
    std::string camera;
    uint32_t width = 640;
    uint32_t height = 480;
    // libcamera's name for the format ("BGR888", "YUYV", "NV12", "MJPEG"); "" = the camera's
    // preferred format if previs converts it, else the first one it converts.
    std::string pixelFormat;
    // Fixed frame rate through FrameDurationLimits; 0 = the camera's default. A camera without
    // that control runs at its own rate (with a warning).
    double fps = 0;
    // Manual exposure (µs) and analogue gain; either turns auto-exposure off.
    std::optional<int32_t> exposureUs;
    std::optional<float> analogueGain;
    // Manual white balance as {red, blue} gains; turns auto white balance off.
    std::optional<std::array<float, 2>> colourGains;
    // 0 = what the pipeline asks for (enough to keep its ISP busy).
    uint32_t bufferCount = 0;
    // Exposure bracketing (capture/exposure_bracket.h): the stops from exposureUs ×
    // analogueGain (both required) that the requests cycle through, each frame labelled from its
    // request's metadata (Frame::exposureStops). Empty: no bracketing.
    std::vector<float> bracketStops;
};

class LibcameraCamera : public FrameReader {
public:
    // Finds, acquires and configures the camera. Reports no cameras at all, no camera matching
    // config.camera, one already in use, and a format, size or control it does not offer, each
    // naming the camera and listing what exists.
    static Result<std::unique_ptr<LibcameraCamera>> create(const LibcameraConfig& config);
    ~LibcameraCamera() override;
    LibcameraCamera(const LibcameraCamera&) = delete;
    LibcameraCamera& operator=(const LibcameraCamera&) = delete;

    // Starts the camera with the configured controls and queues every request.
    Status start() override;
    // Stops the camera; requests still in flight come back cancelled and are discarded.
    void stop();
    // An error once the camera was disconnected (unplugged, driver unbound) or libcamera
    // cancelled a request while streaming, so the capture thread reopens it.
    Result<bool> read(int timeoutMs, Frame& frame) override;
    uint64_t badFrames() const override;

    const std::string& id() const;
    uint32_t width() const;
    uint32_t height() const;
    // libcamera's name of the streamed format ("BGR888").
    const std::string& pixelFormat() const;
    // The frame rate set through FrameDurationLimits; 0 when the camera runs at its own.
    double fps() const;

private:
    struct State;  // libcamera's objects, kept out of this header

    explicit LibcameraCamera(std::unique_ptr<State> state);

    std::unique_ptr<State> state_;
};

struct LibcameraCameraInfo {
    std::string id;
    std::string model;  // the sensor's name when the pipeline reports it, else ""
};

// The cameras libcamera sees, in its order (the indexes LibcameraConfig::camera accepts).
Result<std::vector<LibcameraCameraInfo>> listLibcameraCameras();

// A factory for CaptureThread, opening the camera anew on every call (after a failure).
FrameReaderFactory makeLibcameraReaderFactory(LibcameraConfig config);
// A CameraSource running the camera on its own thread, reopened whenever it fails.
std::unique_ptr<CameraSource> makeLibcameraSource(LibcameraConfig config, CaptureOptions options);

// The pieces of camera and format selection that need no libcamera, exposed for tests.

// Index of the camera `wanted` names in `ids` (libcamera's order): "" the first, an exact id,
// a decimal index, or a substring of exactly one id.
Result<size_t> selectLibcameraCamera(const std::string& wanted,
                                     const std::vector<std::string>& ids);

// The V4L2 fourcc convertToRgb takes for a libcamera (DRM) format, 0 when previs cannot
// convert it. DRM names RGB formats by their bits in a little-endian word, V4L2 by their bytes
// in memory: libcamera's BGR888 is V4L2's RGB24 (bytes R, G, B).
uint32_t v4l2FourccFromLibcamera(uint32_t fourcc, uint64_t modifier);

struct OfferedFormat {
    std::string name;     // libcamera's name ("BGR888")
    uint32_t v4l2Fourcc;  // v4l2FourccFromLibcamera(), 0 = not convertible
};

// Index of the format to stream among `offered`: `wanted` (libcamera's name, any case) if the
// camera offers it and previs converts it; for "" the camera's `preferred` one if convertible,
// else the first convertible one.
Result<size_t> selectLibcameraFormat(const std::string& cameraId, const std::string& wanted,
                                     const std::vector<OfferedFormat>& offered, size_t preferred);

}  // namespace previs
