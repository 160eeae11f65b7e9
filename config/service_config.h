#pragma once

// The service's configuration file (`previsd --config FILE`, DESIGN.md §3; the format is in
// docs/config-format.md): which cameras to open and how, how their 8-bit frames become radiance,
// the tag board to track, and how lighting is estimated. Everything a file names — the scene,
// calibrations, the board — is loaded and checked here, so a bad file is reported once, at
// start, naming the file, line and key, instead of failing minutes later on set.

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "base/result.h"
#include "colour/ocio_colour.h"
#include "config/network_config.h"
#include "net/freed_calibration.h"
#include "render/render_settings.h"
#include "timecode/timecode.h"
#include "vision/board_pose.h"
#include "vision/camera_calibration.h"
#include "vision/fisheye_to_equirect.h"
#include "vision/hdr_bracket.h"
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

// A value loaded from a file when the config is read, held beside the path it came from. Configs
// compare by that path (a reload does not re-read the file), so this compares equal always.
template <class T>
struct LoadedFromPath : std::optional<T> {
    using std::optional<T>::optional;
    using std::optional<T>::operator=;
    bool operator==(const LoadedFromPath&) const { return true; }
};

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
    LoadedFromPath<CameraCalibration> calibration;
    // 8-bit frames → linear radiance in the scene's units (docs/camera-calibration.md §2).
    // [cameras.<name>.colour] sets radiometry.colour: the camera's encoding through OpenColorIO
    // in place of the tone curve (built when the config is read, so a bad name fails --check).
    InverseToneMapSettings radiometry;
    // [cameras.<name>.colour] as given: whether it is there, its ocio_config ("" = the built-in
    // transforms), input and range (how the 8-bit codes span the signal: colour/ocio_colour.h).
    bool colourGiven = false;
    std::string colourConfigPath;
    std::string colourInput;
    CodeRange colourRange = CodeRange::Full;
    // Whether the config gave [cameras.<name>.radiometry].
    bool radiometryGiven = false;
    // Whether the config says how the camera encodes light ([cameras.<name>.radiometry] or
    // [cameras.<name>.colour]); without either `radiometry` holds the sRGB defaults, a guess the
    // tag-edge refit does not build on (vision/tag_edges.h).
    bool encodingGiven() const { return radiometryGiven || colourGiven; }
    // [cameras.fisheye.bracket]: the exposures the camera cycles through, each complete bracket
    // merged to radiance (vision/hdr_bracket.h); none: every frame is lit on its own.
    std::optional<BracketSettings> bracket;
    // [cameras.fisheye.bracket] frames_per_step and control: how a live V4L2 camera cycles its
    // exposure (capture/exposure_bracket.h); libcamera labels from metadata and needs neither.
    int bracketFramesPerStep = 3;
    std::string bracketControl = "exposure_time_absolute";

    bool operator==(const CameraConfig&) const = default;
};

struct TrackingConfig {
    std::string boardPath;
    LoadedFromPath<TagBoard> board;  // loaded from boardPath; always set, as calibration
    TagDetectorSettings detector;
    TrackerSettings tracker;
    // Before the first tracked pose: false = show the camera picture alone; true = composite
    // from the scene file's camera (a locked-off camera whose pose was measured, or a test rig
    // whose cameras see no board).
    bool sceneCameraUntilTracked = false;
    // Composite with the live pose filter's pose (vision/pose_filter.h) instead of each frame's
    // own: no shimmer on a held camera. The take records both.
    bool poseFilter = true;
    // FreeD in (shot/freed_input.h, docs/freed.md): `listen` receives a tracker's packets
    // ("" = none; a take records them either way, so one with the board in view calibrates
    // the tracker), and `source = "freed"` takes the pose from them instead of the tags.
    bool freedSource = false;
    std::string freedListen;
    std::optional<uint8_t> freedCameraId;  // packets of other cameras are refused (counted)
    std::string freedCalibrationPath;      // `previs freed-calibrate`'s result; "" = none
    LoadedFromPath<FreedCalibration> freedCalibration;  // loaded from it

    bool operator==(const TrackingConfig&) const = default;
};

enum class LightingMode {
    Environment,  // the fisheye's environment map lights the scene
    Lights,       // light sources extracted from it plus the residual map (the paper's 2nd mode)
};
const char* toString(LightingMode mode);

// Lighting fitted to the plate (render/lighting_fit.h): Auto fits when the lighting has clipped
// light or the plate-consistency meter is off, On whenever the lighting or the view changes,
// Off never.
enum class FitToPlate { Auto, On, Off };

struct LightingConfig {
    LightingMode mode = LightingMode::Environment;
    FitToPlate fitToPlate = FitToPlate::Auto;
    FisheyeToEquirectSettings fisheye;  // mount rotation, map width, field of view, fill ring
    LightEstimatorSettings lights;
    // Lighting snapshots per second at most (0 = every fisheye frame): a room's light changes
    // slowly, and each snapshot costs a map conversion and an upload. Timed on the frames' own
    // timestamps, so a replay picks the same frames.
    double updateHz = 2.0;
    // [lighting] saved: where the service keeps the set's last captured lighting (an OpenEXR
    // environment map), so that after a restart the virtual objects are lit by the set as last
    // seen until the fisheye's first snapshot. Unset: savedLightingPath()'s default; "": off.
    std::optional<std::string> savedPath;

    bool operator==(const LightingConfig&) const = default;
};

// The saved lighting's file: [lighting] saved, else $STATE_DIRECTORY/last_lighting.exr under
// systemd (/var/lib/previs), else none (an empty string).
std::string savedLightingPath(const LightingConfig& lighting);

// What the render thread does per frame (issue 7: preview and refinement), read at start; the
// [render] key a reload applies is LiveRenderConfig's.
struct RenderConfig {
    uint32_t width = 0;   // 0 = the scene camera's width (the plate's resolution)
    uint32_t height = 0;  // 0 = the scene camera's height
    uint32_t maxDepth = 8;
    // Preview's depth without the dial (the dial chooses its own, ≤ max_depth); 0 = max_depth.
    uint32_t previewMaxDepth = 0;
    uint32_t seed = 0;  // preview's fixed random sequence
    // Preview traces this fraction of the width and height and upsamples it guided by the plate
    // (RenderSettings::resolutionScale); refinement always traces every pixel. (0, 1].
    float resolutionScale = 1.0f;
    // The dial (render/quality_dial.h): a preview frame rate to reach. When set (> 0) the
    // service times every preview setting on the scene at start and picks the most accurate one
    // that fits — samples per frame, resolution scale and max depth (≤ max_depth) — in place of
    // samples_per_frame and resolution_scale. 0 = off. A config without the key gets the scene
    // camera's fps, else kDefaultPreviewFps (this struct's own 0 is for code that builds one).
    static constexpr double kDefaultPreviewFps = 30.0;
    double previewFps = 0.0;
    // The denoiser (render/denoiser.h) on what the renderer adds to the plate, never the plate:
    // "off" (no guide buffers either), "on" (every frame, denoise_levels strong), "auto" (preview:
    // the dial's choice of strength with preview_fps, else below 64 spp; refinement: while the
    // meter's estimate is above target_noise, 1 % without one).
    std::string denoise = "auto";
    uint32_t denoiseLevels = 5;  // à-trous levels for "on" and for "auto" without the dial, [1, 10]
    // Preview's temporal accumulation (issue 35): each preview frame draws new samples, and the
    // frames are averaged through reprojection along the tracked camera (Denoiser::
    // applyTemporal: kept where depth, normal and mask agree, started afresh where disoccluded,
    // and everywhere on a lighting change), so a held camera converges toward refinement and a
    // moving one stays clean. false: the paper's fixed sequence (the noise stays put).
    bool previewAccumulate = true;
    // The frames the accumulation averages at most (a plain mean up to this many, then an
    // exponential average with weight 1/N): longer converges further, shorter follows a change
    // of shading sooner. [1, 1024].
    uint32_t previewHistoryFrames = 32;
    // Below full resolution, samples per output pixel each preview frame adds where the virtual
    // objects are (RenderSettings::objectSamplesPerOutputPixel), [0, 16]; 0: none.
    double previewObjectSamples = 1.0;
    // Preview's estimate scales a sample brighter than this (luminance) down to it
    // (RenderSettings::previewSampleClamp); 0: off.
    double previewSampleClamp = 4.0;
    // While the camera holds still (the held view: render/held_view.h), preview frames trace
    // refinement's depth (max_depth), so a held preview converges toward refinement's picture,
    // not the dial's shallower one; false: preview's depth throughout.
    bool previewHoldDepth = true;
    // While the camera moves, the held view's samples at the output's resolution follow it
    // (render/held_reprojection.h) and fade, instead of being dropped at every move; false: the
    // held view starts afresh whenever the camera holds again.
    bool previewFollow = true;
    // Preview frames resample the first rough hit's distant light across candidates, the last
    // frame and neighbouring pixels (ReSTIR; RenderSettings::previewResampling). Off by default:
    // it cuts a lone frame's noise (by 4/5 among 12 estimated lights), but on the demo, through
    // the denoiser and the held view, whose averages its correlated samples defeat, the error
    // rose in both lighting modes for a third more frame time (BENCHMARKS.md, "Resampling the
    // distant light").
    bool previewResampling = false;
    // While the held view keeps samples, each traced pixel's samples visit the output pixels of
    // its footprint by a phase schedule (RenderSettings::previewPhases); false: at random.
    bool previewPhases = true;
    // While the camera holds, the held view's samples overrule the estimate's outline where
    // their mask disagrees with it (RenderSettings::previewOutlineTest).
    bool previewOutlineTest = true;
    // Caustics (render/photon_map.h): mode and photons per iteration, first radius, alpha.
    PhotonSettings photons;

    bool operator==(const RenderConfig&) const = default;
};

// Refinement: the frame, pose and lighting freeze and samples accumulate.
struct RefineConfig {
    uint32_t samplesPerStep = 4;  // samples added between two shown frames
    uint64_t maxSamples = 4096;   // the sample target: refinement stops adding here (0 = none)
    // The convergence meter's relative RMSE (DESIGN.md §4) at which refinement stops adding
    // samples, if before max_samples (0 = none).
    double targetNoise = 0.01;
    // A change beyond these, seen in `restartAfter` consecutive observations (tracked frames;
    // lighting snapshots), re-freezes the shot on the newest frame and lighting and restarts
    // the accumulation (shot/refine_watch.h). Defaults: docs/config-format.md.
    double poseThresholdM = 0.01;
    double poseThresholdDeg = 0.5;
    double lightingThreshold = 0.06;  // relative change of the lighting (LightingDelta::change)
    int restartAfter = 3;

    bool operator==(const RefineConfig&) const = default;
};

enum class OutputKind { None, Files, Kms };
const char* toString(OutputKind kind);

struct OutputConfig {
    OutputKind kind = OutputKind::None;
    std::string folder;     // files: where frame_NNNNNN.png go (resolved against the config)
    std::string card;       // kms: "/dev/dri/card0"; "" = the first card with a connected display
    std::string connector;  // kms: "Virtual-1", "HDMI-A-1"; "" = the first connected
    std::string mode;       // kms: "1920x1080" or "1920x1080@60"; "" = the preferred mode
    // files: a ring of the newest frames, at most so many and so many MiB, and none written
    // while the folder's disk has less than min_free_mb free (display/files_output.h).
    uint64_t keepFrames = 1000;
    uint64_t maxMb = 1024;
    uint64_t minFreeMb = 256;
    // [output.colour]: the working space shown through an OpenColorIO display and view on every
    // output (KMS, files, the monitor page) in place of the camera's tone curve. Null: the tone
    // curve (today's default); nothing of OCIO is built.
    std::shared_ptr<const DisplayColourTransform> colour;
    // [output.colour] as given: whether it is there, its ocio_config, display and view.
    bool colourGiven = false;
    std::string colourConfigPath, colourDisplay, colourView;

    bool operator==(const OutputConfig&) const = default;
};

// The mode button and the status LED (libgpiod). Absent: no button (the socket still works).
struct ButtonConfig {
    std::string chip;  // "/dev/gpiochip0", "gpiochip0" or the chip's label ("vmtest")
    std::string line;  // a line name ("mode-button") or offset ("5")
    bool activeLow = false;
    int debounceMs = 20;
    int longPressMs = 1500;
    std::string ledChip;  // "" = the button's chip
    std::string ledLine;  // "" = no LED
    bool ledActiveLow = false;

    bool operator==(const ButtonConfig&) const = default;
};

struct ControlConfig {
    // The control socket; "" = $RUNTIME_DIRECTORY/previsd.sock, else /run/previs/previsd.sock.
    std::string socketPath;

    bool operator==(const ControlConfig&) const = default;
};

// Takes (DESIGN.md §3 "Recording", docs/takes.md).
struct RecordConfig {
    // Where take folders go; "" = takesFolder()'s default.
    std::string dir;
    bool autoStart = false;     // [record] auto: record whenever previsd runs
    uint64_t minFreeMb = 1024;  // refuse to start, and stop, below this much free space
    // The take's index files are made durable at least this often: a power cut loses at most
    // this much of the take (docs/session-format.md, write order).
    uint32_t flushIntervalMs = 1000;
    // Frames waiting for the disk at most (MiB of frame data) before the recorder drops one.
    uint32_t queueMb = 512;

    bool operator==(const RecordConfig&) const = default;
};

// [record] dir, else $STATE_DIRECTORY/takes under systemd (/var/lib/previs/takes), else
// ./takes.
std::string takesFolder(const RecordConfig& record);

// What previsd reads only at start (everything but LiveConfig): the cameras, the scene, the
// pipeline and its outputs are built from it, so a reload names a change of it as needing a
// restart (restartNeeded). A field added here needs a restart without more code.
struct StartupConfig {
    std::string path;       // the file this came from
    std::string scenePath;  // a .gltf/.glb or previs.toml scene description (resolved)
    CameraConfig sceneCamera;
    // Without a fisheye the scene's own environment map and lights are used.
    std::optional<CameraConfig> fisheyeCamera;
    TrackingConfig tracking;
    LightingConfig lighting;
    RenderConfig render;
    OutputConfig output;
    std::optional<ButtonConfig> button;
    ControlConfig control;
    RecordConfig record;
    // The set's network: FreeD and OpenTrackIO out, the timecode source, the web monitor.
    NetworkConfig network;
    // Recorded cameras (source = "session"): start over at the end (a demo loop) or stop the
    // service there (exit 0).
    bool loopSession = true;
    // Recorded cameras: replay the session's button and ctl events (events.csv) with its frames.
    // Off by default: live playback leaves the mode to the crew (`previs replay` follows them).
    bool replaySessionEvents = false;

    bool operator==(const StartupConfig&) const = default;
};

// The [render] keys a reload applies at once (read from [render] with RenderConfig's).
struct LiveRenderConfig {
    // [render] samples_per_frame: preview's samples per pixel of each live frame; where the dial
    // runs ([render] preview_fps), its choice in place of this.
    uint32_t samplesPerFrame = 1;

    bool operator==(const LiveRenderConfig&) const = default;
};

// What a reload applies while previsd runs (Service::reload, ShotController::setConfig).
struct LiveConfig {
    RefineConfig refine;
    LiveRenderConfig liveRender;

    bool operator==(const LiveConfig&) const = default;
};

// The whole file: the part read at start and the part a reload applies.
struct ServiceConfig : StartupConfig, LiveConfig {};

// What of `fresh` differs from the `running` config in a way only a restart applies, by the
// config's names ("scene", "cameras.scene", "cameras.scene.colour", "render (size, ...)",
// "output.colour", "record", "timecode", ...), in a fixed order; empty when nothing does. Files
// (calibrations, the board, OpenColorIO configs) compare by their paths, the control socket as
// resolved; the live part (LiveConfig) is not compared.
std::vector<std::string> restartNeeded(const ServiceConfig& running, const ServiceConfig& fresh);

// The rule `camera`'s timecode labels count at under this config (timecode/timecode.h): its
// [timecode] rate, else the camera's fps. An unknown rate is an error naming [timecode] rate
// (loadServiceConfig refuses it first; a config built in code may hold one).
Result<LabelRateRule> labelRateRule(const ServiceConfig& config, const CameraConfig& camera);

// The control socket the config names, or the default (DESIGN.md §3).
std::string controlSocketPath(const ControlConfig& control);

// Reads and validates the config at `path`; also loads the calibrations and the board it names
// (not the scene: that is the renderer's, and slow). Any user error — TOML syntax, an unknown
// key, a wrong type or range, a missing or broken file, a calibration whose image size is not
// the camera's — is one message naming the file, the line and the key.
// `relativeTo`: the folder relative paths start from, when not the file's own (a session's copy
// of its config, docs/session-format.md `config_dir`).
Result<ServiceConfig> loadServiceConfig(const std::string& path,
                                        const std::string& relativeTo = "");

// The cameras OpenColorIO decodes, for previsd --check: "scene camera 'ARRI LogC3 (EI800)' from
// OCIO's built-in transforms" ("; fisheye camera …" after it); "" when none has a colour section.
std::string cameraColourSummary(const ServiceConfig& config);

}  // namespace previs
