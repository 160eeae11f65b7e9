#pragma once

// The service's configuration file (`previsd --config FILE`, DESIGN.md §3; the format is in
// docs/config-format.md): which cameras to open and how, how their 8-bit frames become radiance,
// the tag board to track, and how lighting is estimated. Everything a file names — the scene,
// calibrations, the board — is loaded and checked here, so a bad file is reported once, at
// start, naming the file, line and key, instead of failing minutes later on set.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "base/result.h"
#include "vision/board_pose.h"
#include "vision/camera_calibration.h"
#include "vision/fisheye_to_equirect.h"
#include "vision/inverse_tone_map.h"
#include "vision/light_estimator.h"
#include "vision/tag_board.h"
#include "vision/tag_detector.h"

namespace previs {

enum class CameraSourceKind {
    V4L2,       // a V4L2 capture node (UVC webcams, HDMI grabbers)
    Libcamera,  // a libcamera camera (CSI sensors)
    Session,    // a recorded camera folder of a session (docs/session-format.md)
};
const char* toString(CameraSourceKind kind);

struct CameraConfig {
    std::string name;  // the table's name: "scene", "fisheye"
    CameraSourceKind source = CameraSourceKind::V4L2;
    // V4L2: the device node; libcamera: the camera id ("" = the first camera); session: the
    // recorded camera folder (absolute, resolved against the config's folder).
    std::string device;
    uint32_t width = 0;
    uint32_t height = 0;
    // v4l2: the fourcc name ("YUYV", "MJPG", "NV12"); libcamera: its format name ("BGR888",
    // "NV12"), checked when the camera opens; "" = the device's choice.
    std::string pixelFormat;
    double fps = 0.0;  // 0 = the device's default rate
    // v4l2: controls set after opening, in file order, by the driver's name for them
    // (`v4l2-ctl --list-ctrls` shows them; case-insensitive): exposure, gain, white balance.
    std::vector<std::pair<std::string, int64_t>> controls;
    // libcamera: its typed controls (capture/libcamera_camera.h); each turns its auto mode off.
    std::optional<int32_t> exposureUs;
    std::optional<float> analogueGain;
    std::optional<std::array<float, 2>> colourGains;  // red, blue
    std::string calibrationPath;
    // Loaded from calibrationPath; always set in a config loadServiceConfig returned
    // (optional only because a calibration has no meaningful empty state).
    std::optional<CameraCalibration> calibration;
    // 8-bit frames → linear radiance in the scene's units (docs/camera-calibration.md §2).
    InverseToneMapSettings radiometry;
};

struct TrackingConfig {
    std::string boardPath;
    std::optional<TagBoard> board;  // loaded from boardPath; always set, as calibration
    TagDetectorSettings detector;
    TrackerSettings tracker;
};

enum class LightingMode {
    Environment,  // the fisheye's environment map lights the scene
    Lights,       // light sources extracted from it plus the residual map (the paper's 2nd mode)
};
const char* toString(LightingMode mode);

struct LightingConfig {
    LightingMode mode = LightingMode::Environment;
    FisheyeToEquirectSettings fisheye;  // mount rotation, map width, field of view, fill ring
    LightEstimatorSettings lights;
};

struct ServiceConfig {
    std::string path;       // the file this came from
    std::string scenePath;  // a .gltf/.glb or previs.toml scene description (resolved)
    CameraConfig sceneCamera;
    // Without a fisheye the scene's own environment map and lights are used.
    std::optional<CameraConfig> fisheyeCamera;
    TrackingConfig tracking;
    LightingConfig lighting;
};

// Reads and validates the config at `path`; also loads the calibrations and the board it names
// (not the scene: that is the renderer's, and slow). Any user error — TOML syntax, an unknown
// key, a wrong type or range, a missing or broken file, a calibration whose image size is not
// the camera's — is one message naming the file, the line and the key.
Result<ServiceConfig> loadServiceConfig(const std::string& path);

}  // namespace previs
