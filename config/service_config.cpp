#include "config/service_config.h"

#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <functional>
#include <limits>
#include <tuple>

#include "base/toml_reader.h"
#include "capture/exposure_bracket.h"
#include "capture/pixel_format.h"
#include "capture/v4l2_device.h"
#include "config/network_config_reader.h"
#include "net/udp_socket.h"
#include "vision/board_file.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

constexpr int64_t kFormatVersion = 1;
constexpr const char* kWhat = "service config";

// Reads one config file; each failure names the file, the line and the dotted key.
class ConfigReader {
public:
    explicit ConfigReader(const std::string& path) : r_(path, kWhat) {}
    void setFolder(const std::string& folder) { r_.setFolder(folder); }

    Result<ServiceConfig> read(const toml::table& root);

private:
    Status checkTopLevel(const toml::table& root) const;
    Status parseScenePath(const toml::table& root, ServiceConfig& config) const;
    Status parseCameras(const toml::table& root, ServiceConfig& config) const;
    Status parseTrackingAndLighting(const toml::table& root, ServiceConfig& config) const;
    Status parseOptionalSections(const toml::table& root, ServiceConfig& config) const;
    template <typename... Args>
    Error fail(const toml::node* at, fmt::format_string<Args...> format, Args&&... args) const {
        return r_.fail(at, format, std::forward<Args>(args)...);
    }

    Status parseCamera(const toml::table& t, const std::string& name, CameraConfig& c) const;
    Status parseCameraSource(const toml::table& t, const std::string& section,
                             CameraConfig& c) const;
    Status parseCameraFormat(const toml::table& t, const std::string& section,
                             CameraConfig& c) const;
    Status parseCameraControls(const toml::table& t, const std::string& section,
                               CameraConfig& c) const;
    Status parseCameraCalibration(const toml::table& t, const std::string& section,
                                  CameraConfig& c) const;
    Status parseBracket(const toml::table& camera, const std::string& cameraSection,
                        CameraConfig& c) const;
    Status parseLibcameraControls(const toml::table& t, const std::string& section,
                                  CameraConfig& c) const;
    Status parseRadiometry(const toml::table& t, std::string_view section,
                           InverseToneMapSettings& s) const;
    Status parseCameraColour(const toml::table& camera, const std::string& cameraSection,
                             CameraConfig& c) const;
    Status parseOutputColour(const toml::table& output, OutputConfig& c) const;
    Result<std::string> ocioConfigPath(const toml::table& t, const std::string& section) const;
    Result<CodeRange> codeRange(const toml::table& t, const std::string& section) const;
    Status parseTracking(const toml::table& t, TrackingConfig& c) const;
    Status parseFreedIn(const toml::table& t, TrackingConfig& c) const;
    Status parseLighting(const toml::table& t, LightingConfig& c) const;
    Status parseRender(const toml::table& t, RenderConfig& c, LiveRenderConfig& live) const;
    Status parseRefine(const toml::table& t, RefineConfig& c) const;
    Status parseOutput(const toml::table& t, OutputConfig& c) const;
    Status parseButton(const toml::table& t, ButtonConfig& c) const;
    Status parseControl(const toml::table& t, ControlConfig& c) const;
    Status parseRecord(const toml::table& t, RecordConfig& c) const;
    Status stringKey(const toml::table& t, std::string_view section, std::string_view key,
                     std::string& value) const;

    TomlReader r_;
};

Status ConfigReader::parseRadiometry(const toml::table& t, std::string_view section,
                                     InverseToneMapSettings& s) const {
    if (Status st = r_.checkKeys(
            t, section,
            {"tone_curve", "exposure_stops", "white_balance", "max_radiance", "white_luminance"});
        !st)
        return st;
    Result<std::optional<std::string>> curve = r_.string(t, section, "tone_curve");
    if (!curve) return curve.error();
    if (*curve) {
        const std::optional<InverseToneMapOperator> op = parseInverseToneMapOperator(**curve);
        if (!op)
            return fail(t.get("tone_curve"),
                        "'{}.tone_curve' is '{}'; use srgb, reinhard or banterle", section,
                        **curve);
        s.op = *op;
    }
    if (Status st = r_.numberIn(t, section, "exposure_stops", s.exposureStops, -64.0, 64.0); !st)
        return st;
    Result<std::optional<std::vector<double>>> wb = r_.numbers(t, section, "white_balance", 3);
    if (!wb) return wb.error();
    if (*wb) {
        for (size_t i = 0; i < 3; ++i) {
            if (!((**wb)[i] > 0.0))
                return fail(t.get("white_balance"),
                            "'{}.white_balance' has {} for {}; each gain must be > 0", section,
                            (**wb)[i], "RGB"[i]);
            s.whiteBalance[i] = float((**wb)[i]);
        }
    }
    const double big = std::numeric_limits<float>::max();
    if (Status st = r_.numberIn(t, section, "max_radiance", s.maxRadiance, 0.0, big, true); !st)
        return st;
    if (Status st = r_.numberIn(t, section, "white_luminance", s.whiteLuminance, 0.0, big, true);
        !st)
        return st;
    return {};
}

// [<section>] ocio_config: "" or absent = OCIO's built-in transforms; else an OCIO config file,
// relative to the config's folder.
Result<std::string> ConfigReader::ocioConfigPath(const toml::table& t,
                                                 const std::string& section) const {
    Result<std::optional<std::string>> path = r_.string(t, section, "ocio_config");
    if (!path) return path.error();
    if (!*path || (*path)->empty()) return std::string();
    return (r_.folder() / fs::path(**path)).lexically_normal().string();
}

// [<section>] range: "full" (absent) or "legal" (video levels, 16–235).
Result<CodeRange> ConfigReader::codeRange(const toml::table& t, const std::string& section) const {
    Result<std::optional<std::string>> range = r_.string(t, section, "range");
    if (!range) return range.error();
    if (!*range || **range == "full") return CodeRange::Full;
    if (**range == "legal") return CodeRange::Legal;
    return fail(t.get("range"),
                "'{}.range' is '{}'; use \"full\" (codes 0-255) or \"legal\" (video levels, "
                "black at 16 and white at 235)",
                section, **range);
}

// [cameras.<name>.colour]: the camera's encoding through OpenColorIO (colour/ocio_colour.h), in
// place of the radiometry's tone curve; its exposure and white balance still apply.
Status ConfigReader::parseCameraColour(const toml::table& camera, const std::string& cameraSection,
                                       CameraConfig& c) const {
    Result<const toml::table*> table = r_.table(camera, cameraSection, "colour");
    if (!table) return table.error();
    if (!*table) return {};
    const toml::table& t = **table;
    const std::string section = cameraSection + ".colour";
    if (Status st = r_.checkKeys(t, section, {"ocio_config", "input", "range"}); !st) return st;
    if (const toml::table* radiometry = camera["radiometry"].as_table())
        for (const char* curveKey : {"tone_curve", "max_radiance", "white_luminance"})
            if (radiometry->get(curveKey))
                return fail(radiometry->get(curveKey),
                            "'{}.radiometry.{}' and [{}] both say how the camera encodes light; "
                            "keep one (with [{}] the radiometry keeps exposure_stops and "
                            "white_balance only)",
                            cameraSection, curveKey, section, section);
    Result<std::string> configPath = ocioConfigPath(t, section);
    if (!configPath) return configPath.error();
    Result<std::optional<std::string>> input = r_.string(t, section, "input");
    if (!input) return input.error();
    c.colourConfigPath = *configPath;
    c.colourInput = input->value_or("");
    Result<CodeRange> range = codeRange(t, section);
    if (!range) return range.error();
    c.colourRange = *range;
    Result<std::shared_ptr<const CameraColourTransform>> transform =
        CameraColourTransform::create({c.colourConfigPath, section}, c.colourInput, *range);
    if (!transform) {
        const bool aboutFile = transform.message().find(".ocio_config'") != std::string::npos;
        const toml::node* at = t.get(aboutFile ? "ocio_config" : "input");
        return fail(at ? at : &t, "{}", transform.message());
    }
    c.radiometry.colour = std::move(*transform);
    c.colourGiven = true;
    return {};
}

// [output.colour]: the working space through an OpenColorIO display and view.
Status ConfigReader::parseOutputColour(const toml::table& output, OutputConfig& c) const {
    Result<const toml::table*> table = r_.table(output, "output", "colour");
    if (!table) return table.error();
    if (!*table) return {};
    const toml::table& t = **table;
    const std::string section = "output.colour";
    if (Status st = r_.checkKeys(t, section, {"ocio_config", "display", "view"}); !st) return st;
    Result<std::string> configPath = ocioConfigPath(t, section);
    if (!configPath) return configPath.error();
    c.colourConfigPath = *configPath;
    if (Status st = stringKey(t, section, "display", c.colourDisplay); !st) return st;
    if (Status st = stringKey(t, section, "view", c.colourView); !st) return st;
    Result<std::shared_ptr<const DisplayColourTransform>> transform =
        DisplayColourTransform::create({c.colourConfigPath, section}, c.colourDisplay,
                                       c.colourView);
    if (!transform) return fail(&t, "{}", transform.message());
    c.colour = std::move(*transform);
    c.colourGiven = true;
    return {};
}

// libcamera's controls are typed and named by libcamera, not by a driver.
Status ConfigReader::parseLibcameraControls(const toml::table& t, const std::string& section,
                                            CameraConfig& c) const {
    if (Status st = r_.checkKeys(t, section, {"exposure_time_us", "analogue_gain", "colour_gains"});
        !st)
        return st;
    int64_t exposure = 0;
    if (Status st = r_.integerIn(t, section, "exposure_time_us", exposure, 1, 60'000'000); !st)
        return st;
    if (exposure > 0) c.exposureUs = int32_t(exposure);
    float gain = 0.0f;
    if (Status st = r_.numberIn(t, section, "analogue_gain", gain, 0.0, 1024.0, true); !st)
        return st;
    if (gain > 0.0f) c.analogueGain = gain;
    Result<std::optional<std::vector<double>>> gains = r_.numbers(t, section, "colour_gains", 2);
    if (!gains) return gains.error();
    if (*gains) {
        if (!((**gains)[0] > 0.0 && (**gains)[1] > 0.0))
            return fail(t.get("colour_gains"),
                        "'{}.colour_gains' must be two gains > 0 (red, "
                        "blue)",
                        section);
        c.colourGains = std::array<float, 2>{float((**gains)[0]), float((**gains)[1])};
    }
    return {};
}

// Where the frames come from: the source kind and its device (a recorded camera's folder made
// absolute).
Status ConfigReader::parseCameraSource(const toml::table& t, const std::string& section,
                                       CameraConfig& c) const {
    Result<std::optional<std::string>> source = r_.string(t, section, "source");
    if (!source) return source.error();
    const std::string kind = source->value_or("v4l2");
    if (kind == "v4l2")
        c.source = CameraSourceKind::V4L2;
    else if (kind == "libcamera") {
#ifndef PREVIS_HAVE_LIBCAMERA
        return fail(t.get("source"),
                    "'{}.source' is libcamera, but this previs was built without libcamera "
                    "(Debian's libcamera-dev); use v4l2, or rebuild with libcamera",
                    section);
#endif
        c.source = CameraSourceKind::Libcamera;
    } else if (kind == "session")
        c.source = CameraSourceKind::Session;
    else
        return fail(t.get("source"), "'{}.source' is '{}'; use v4l2, libcamera or session", section,
                    kind);

    Result<std::optional<std::string>> device = r_.string(t, section, "device");
    if (!device) return device.error();
    if (c.source != CameraSourceKind::Libcamera && (!*device || (*device)->empty()))
        return fail(*device ? t.get("device") : &t, "[{}] needs 'device' ({})", section,
                    c.source == CameraSourceKind::V4L2
                        ? "the V4L2 node, e.g. device = \"/dev/video0\""
                        : "the recorded camera folder, e.g. device = \"session/cameras/scene\"");
    c.device = device->value_or("");
    if (c.source == CameraSourceKind::Session) {
        const fs::path folder = r_.folder() / fs::path(c.device);
        std::error_code ec;
        if (!fs::is_regular_file(folder / "index.csv", ec))
            return fail(t.get("device"),
                        "'{}.device' is '{}', but '{}' is not a recorded camera folder (no "
                        "index.csv; docs/session-format.md)",
                        section, c.device, folder.string());
        c.device = folder.string();
    }
    return {};
}

// The capture size (required: it must be the calibrated one, and a camera's default size is
// whatever the last program left it at), pixel format and rate.
Status ConfigReader::parseCameraFormat(const toml::table& t, const std::string& section,
                                       CameraConfig& c) const {
    for (auto [key, field] : {std::pair<const char*, uint32_t*>{"width", &c.width},
                              std::pair<const char*, uint32_t*>{"height", &c.height}}) {
        int64_t v = 0;
        if (Status st = r_.integerIn(t, section, key, v, 1, 16384); !st) return st;
        if (v == 0)
            return fail(&t, "[{}] needs '{}' (pixels; the size the calibration was made at)",
                        section, key);
        *field = uint32_t(v);
    }

    Result<std::optional<std::string>> format = r_.string(t, section, "format");
    if (!format) return format.error();
    if (*format) {
        if (c.source == CameraSourceKind::Session)
            return fail(t.get("format"), "'{}.format' has no meaning for a recorded camera",
                        section);
        // libcamera's names differ from V4L2's; its camera checks them when it opens.
        if (c.source == CameraSourceKind::V4L2 && !isSupportedFormat(fourccFromString(**format)))
            return fail(t.get("format"), "'{}.format' is '{}'; supported: {}", section, **format,
                        supportedFormatList());
        c.pixelFormat = **format;
    }
    if (Status st = r_.numberIn(t, section, "fps", c.fps, 0.0, 1000.0); !st) return st;
    return {};
}

Status ConfigReader::parseCameraControls(const toml::table& t, const std::string& section,
                                         CameraConfig& c) const {
    Result<const toml::table*> controls = r_.table(t, section, "controls");
    if (!controls) return controls.error();
    if (*controls) {
        if (c.source == CameraSourceKind::Session)
            return fail(*controls, "'{}.controls' has no meaning for a recorded camera", section);
        if (c.source == CameraSourceKind::Libcamera) {
            if (Status st = parseLibcameraControls(**controls, section + ".controls", c); !st)
                return st;
        } else {
            for (auto&& [key, node] : **controls) {
                const toml::value<int64_t>* v = node.as_integer();
                if (!v)
                    return fail(&node, "'{}.controls.\"{}\"' must be an integer, not {}", section,
                                key.str(), tomlTypeName(node));
                c.controls.emplace_back(std::string(key.str()), v->get());
            }
        }
    }
    return {};
}

// The OpenCV calibration, which must have been made at the configured size.
Status ConfigReader::parseCameraCalibration(const toml::table& t, const std::string& section,
                                            CameraConfig& c) const {
    Result<std::optional<std::string>> calibration = r_.string(t, section, "calibration");
    if (!calibration) return calibration.error();
    if (!*calibration)
        return fail(&t,
                    "[{}] needs 'calibration' (an OpenCV calibration .yaml; "
                    "docs/camera-calibration.md)",
                    section);
    Result<std::string> calibrationPath =
        r_.file(*t.get("calibration"), section + ".calibration", **calibration,
                {".yaml", ".yml", ".xml"}, "OpenCV calibration");
    if (!calibrationPath) return calibrationPath.error();
    Result<CameraCalibration> loaded = CameraCalibration::load(*calibrationPath);
    if (!loaded)
        return fail(t.get("calibration"), "'{}.calibration': {}", section, loaded.message());
    const cv::Size size = loaded->imageSize();
    if (size.width != int(c.width) || size.height != int(c.height))
        return fail(t.get("calibration"),
                    "'{}.calibration' was made at {}x{}, but the camera is configured {}x{}; "
                    "calibrate at the capture size (intrinsics do not carry over between sizes "
                    "a sensor crops or bins)",
                    section, size.width, size.height, c.width, c.height);
    c.calibrationPath = *calibrationPath;
    c.calibration = std::move(*loaded);
    return {};
}

Status ConfigReader::parseCamera(const toml::table& t, const std::string& name,
                                 CameraConfig& c) const {
    const std::string section = "cameras." + name;
    const bool fisheye = name == "fisheye";
    Status keys =
        fisheye
            ? r_.checkKeys(t, section,
                           {"source", "device", "width", "height", "format", "fps", "controls",
                            "calibration", "radiometry", "colour", "mount_rotation_deg", "bracket"})
            : r_.checkKeys(t, section,
                           {"source", "device", "width", "height", "format", "fps", "controls",
                            "calibration", "radiometry", "colour"});
    if (!keys) return keys;
    c.name = name;
    if (Status st = parseCameraSource(t, section, c); !st) return st;
    if (Status st = parseCameraFormat(t, section, c); !st) return st;
    if (Status st = parseCameraControls(t, section, c); !st) return st;
    if (Status st = parseCameraCalibration(t, section, c); !st) return st;
    Result<const toml::table*> radiometry = r_.table(t, section, "radiometry");
    if (!radiometry) return radiometry.error();
    if (*radiometry) {
        if (Status st = parseRadiometry(**radiometry, section + ".radiometry", c.radiometry); !st)
            return st;
        c.radiometryGiven = true;
    }
    if (Status st = parseCameraColour(t, section, c); !st) return st;
    if (fisheye) return parseBracket(t, section, c);
    return {};
}

Status ConfigReader::parseBracket(const toml::table& camera, const std::string& cameraSection,
                                  CameraConfig& c) const {
    Result<const toml::table*> table = r_.table(camera, cameraSection, "bracket");
    if (!table) return table.error();
    if (!*table) return {};
    const toml::table& t = **table;
    const std::string section = cameraSection + ".bracket";
    if (Status st =
            r_.checkKeys(t, section, {"stops", "tolerance_stops", "frames_per_step", "control"});
        !st)
        return st;
    // How a live camera cycles its exposure (capture/exposure_bracket.h): V4L2 holds each step
    // for frames_per_step frames of a control; libcamera labels each frame from its metadata.
    for (const char* key : {"frames_per_step", "control"})
        if (t.get(key) && c.source != CameraSourceKind::V4L2)
            return fail(t.get(key), "'{}.{}' has no meaning for a {} camera (V4L2 only{})", section,
                        key, toString(c.source),
                        c.source == CameraSourceKind::Libcamera
                            ? ": libcamera labels each frame from its metadata"
                            : ": a recording's frames carry their exposures");
    if (Status st = r_.integerIn(t, section, "frames_per_step", c.bracketFramesPerStep, 1,
                                 kMaxFramesPerStep);
        !st)
        return st;
    Result<std::optional<std::string>> control = r_.string(t, section, "control");
    if (!control) return control.error();
    if (*control) c.bracketControl = **control;
    if (c.source == CameraSourceKind::V4L2) {
        bool hasBase = false;
        for (const auto& [name, value] : c.controls)
            hasBase = hasBase || v4l2ControlKey(name) == v4l2ControlKey(c.bracketControl);
        if (!hasBase)
            return fail(&t,
                        "[{}] cycles '{}' from the camera's configured value, but [{}.controls] "
                        "does not set it; add it (the exposure the radiometry was calibrated at) "
                        "with the camera in manual exposure (e.g. auto_exposure = 1)",
                        section, c.bracketControl, cameraSection);
    } else if (c.source == CameraSourceKind::Libcamera && (!c.exposureUs || !c.analogueGain)) {
        return fail(&t,
                    "[{}] needs the base exposure: set exposure_time_us and analogue_gain in "
                    "[{}.controls] (those the radiometry was calibrated at)",
                    section, cameraSection);
    }
    Result<std::optional<std::vector<double>>> stops = r_.numbers(t, section, "stops", 0);
    if (!stops) return stops.error();
    if (!*stops) return fail(&t, "[{}] needs 'stops', e.g. stops = [0, -4, -8]", section);
    BracketSettings b;
    for (double v : **stops) b.stops.push_back(float(v));
    if (Status st = checkBracketStops(b.stops, section + ".stops"); !st)
        return fail(t.get("stops"), "{}", st.message());
    if (Status st =
            r_.numberIn(t, section, "tolerance_stops", b.ratioToleranceStops, 0.0, 4.0, true);
        !st)
        return st;
    c.bracket = std::move(b);
    return {};
}

Status ConfigReader::parseTracking(const toml::table& t, TrackingConfig& c) const {
    if (Status st = r_.checkKeys(
            t, "tracking",
            {"board", "family", "decimate", "sigma", "refine_edges", "decode_sharpening", "threads",
             "max_reproj_error_px", "min_tags", "max_position_std_fraction", "max_rotation_std_deg",
             "min_ambiguity_ratio", "linear_edges", "pose_filter", "until_tracked", "source",
             "listen", "freed_camera_id", "freed_calibration"});
        !st)
        return st;
    Result<std::optional<std::string>> board = r_.string(t, "tracking", "board");
    if (!board) return board.error();
    if (!*board)
        return fail(&t,
                    "[tracking] needs 'board' (the tag board layout .toml; "
                    "docs/board-format.md)");
    Result<std::string> boardPath =
        r_.file(*t.get("board"), "tracking.board", **board, {".toml"}, "tag board");
    if (!boardPath) return boardPath.error();
    Result<TagBoard> loaded = loadTagBoard(*boardPath);
    if (!loaded) return fail(t.get("board"), "'tracking.board': {}", loaded.message());

    Result<std::optional<std::string>> family = r_.string(t, "tracking", "family");
    if (!family) return family.error();
    if (*family) {
        const std::vector<std::string>& known = supportedTagFamilies();
        if (std::find(known.begin(), known.end(), **family) == known.end()) {
            return fail(t.get("family"), "'tracking.family' is '{}'; supported: {}", **family,
                        joined(known));
        }
        c.detector.family = **family;
    } else if (!loaded->family().empty()) {
        c.detector.family = loaded->family();
    }
    if (!loaded->family().empty() && loaded->family() != c.detector.family)
        return fail(t.get("family"),
                    "'tracking.family' is '{}', but the board '{}' is made of {} tags",
                    c.detector.family, *boardPath, loaded->family());
    c.boardPath = *boardPath;
    c.board = std::move(*loaded);

    Result<std::optional<std::string>> until = r_.string(t, "tracking", "until_tracked");
    if (!until) return until.error();
    if (*until) {
        if (**until == "plate")
            c.sceneCameraUntilTracked = false;
        else if (**until == "scene-camera")
            c.sceneCameraUntilTracked = true;
        else
            return fail(t.get("until_tracked"),
                        "'tracking.until_tracked' is '{}'; use plate or scene-camera", **until);
    }

    if (Status st = r_.numberIn(t, "tracking", "decimate", c.detector.decimate, 0.0, 16.0); !st)
        return st;
    if (c.detector.decimate > 0.0f && c.detector.decimate < 1.0f)
        return fail(t.get("decimate"), "'tracking.decimate' is {}; use 0 (automatic) or 1 to 16",
                    c.detector.decimate);
    if (Status st = r_.numberIn(t, "tracking", "sigma", c.detector.sigma, 0.0, 16.0); !st)
        return st;
    Result<std::optional<bool>> refine = r_.boolean(t, "tracking", "refine_edges");
    if (!refine) return refine.error();
    c.detector.refineEdges = refine->value_or(c.detector.refineEdges);
    if (Status st =
            r_.numberIn(t, "tracking", "decode_sharpening", c.detector.decodeSharpening, 0.0, 16.0);
        !st)
        return st;
    if (Status st = r_.integerIn(t, "tracking", "threads", c.detector.threads, 1, 64); !st)
        return st;
    if (Status st = r_.numberIn(t, "tracking", "max_reproj_error_px", c.tracker.maxReprojErrorPx,
                                0.0, 1e6, true);
        !st)
        return st;
    if (Status st = r_.integerIn(t, "tracking", "min_tags", c.tracker.minTags, 1, 1024); !st)
        return st;
    if (Status st = r_.numberIn(t, "tracking", "max_position_std_fraction",
                                c.tracker.maxPositionStdFraction, 0.0, 1e6, true);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "tracking", "max_rotation_std_deg", c.tracker.maxRotationStdDeg,
                                0.0, 1e6, true);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "tracking", "min_ambiguity_ratio", c.tracker.minAmbiguityRatio,
                                0.0, 1e6);
        !st)
        return st;
    Result<std::optional<bool>> linearEdges = r_.boolean(t, "tracking", "linear_edges");
    if (!linearEdges) return linearEdges.error();
    c.tracker.linearEdges = linearEdges->value_or(c.tracker.linearEdges);
    Result<std::optional<bool>> poseFilter = r_.boolean(t, "tracking", "pose_filter");
    if (!poseFilter) return poseFilter.error();
    c.poseFilter = poseFilter->value_or(c.poseFilter);
    return parseFreedIn(t, c);
}

Status ConfigReader::parseFreedIn(const toml::table& t, TrackingConfig& c) const {
    Result<std::optional<std::string>> source = r_.string(t, "tracking", "source");
    if (!source) return source.error();
    if (*source && **source != "tags" && **source != "freed")
        return fail(t.get("source"), "'tracking.source' is '{}'; use tags or freed", **source);
    c.freedSource = *source && **source == "freed";
    Result<std::optional<std::string>> listen = r_.string(t, "tracking", "listen");
    if (!listen) return listen.error();
    if (*listen) {
        if (hasControlCharacter(**listen))
            return fail(t.get("listen"),
                        "'tracking.listen' holds a control character (a newline?); write "
                        "HOST:PORT alone, e.g. \"0.0.0.0:40000\"");
        if (Result<std::pair<std::string, std::string>> split = splitHostPort(**listen); !split)
            return fail(t.get("listen"), "'tracking.listen': {} (e.g. \"0.0.0.0:40000\")",
                        split.message());
        c.freedListen = **listen;
    }
    int64_t id = -1;
    if (Status st = r_.integerIn(t, "tracking", "freed_camera_id", id, 0, 255); !st) return st;
    if (id >= 0) c.freedCameraId = uint8_t(id);
    Result<std::optional<std::string>> calibration = r_.string(t, "tracking", "freed_calibration");
    if (!calibration) return calibration.error();
    if (*calibration) {
        Result<std::string> path =
            r_.file(*t.get("freed_calibration"), "tracking.freed_calibration", **calibration,
                    {".toml"}, "FreeD calibration");
        if (!path) return path.error();
        Result<FreedCalibration> loaded = loadFreedCalibration(*path);
        if (!loaded) return fail(t.get("freed_calibration"), "{}", loaded.message());
        c.freedCalibrationPath = *path;
        c.freedCalibration = std::move(*loaded);
    }
    return {};
}

Status ConfigReader::parseLighting(const toml::table& t, LightingConfig& c) const {
    if (Status st = r_.checkKeys(t, "lighting",
                                 {"mode", "map_width", "max_field_angle_deg", "fill_ring_deg",
                                  "mean_factor", "max_fraction", "max_lights", "min_power_fraction",
                                  "update_hz", "saved", "fit_to_plate"});
        !st)
        return st;
    Result<std::optional<std::string>> mode = r_.string(t, "lighting", "mode");
    if (!mode) return mode.error();
    if (*mode) {
        if (**mode == "environment")
            c.mode = LightingMode::Environment;
        else if (**mode == "lights")
            c.mode = LightingMode::Lights;
        else
            return fail(t.get("mode"), "'lighting.mode' is '{}'; use environment or lights",
                        **mode);
    }
    int64_t width = c.fisheye.width;
    if (Status st = r_.integerIn(t, "lighting", "map_width", width, 16, 16384); !st) return st;
    if (width % 2 != 0)
        return fail(t.get("map_width"),
                    "'lighting.map_width' is {}; it must be even (the map "
                    "is width x width/2)",
                    width);
    c.fisheye.width = int(width);
    if (Status st = r_.numberIn(t, "lighting", "max_field_angle_deg", c.fisheye.maxFieldAngleDeg,
                                0.0, 180.0, true);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "lighting", "fill_ring_deg", c.fisheye.fillRingDeg, 0.0,
                                c.fisheye.maxFieldAngleDeg, true);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "lighting", "mean_factor", c.lights.meanFactor, 0.0, 1e12, true);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "lighting", "max_fraction", c.lights.maxFraction, 0.0, 1.0); !st)
        return st;
    if (Status st = r_.numberIn(t, "lighting", "update_hz", c.updateHz, 0.0, 1000.0); !st)
        return st;
    if (Status st = r_.integerIn(t, "lighting", "max_lights", c.lights.maxLights, 0, 256); !st)
        return st;
    Result<std::optional<std::string>> saved = r_.string(t, "lighting", "saved");
    if (!saved) return saved.error();
    if (*saved && !(*saved)->empty())
        c.savedPath = (r_.folder() / fs::path(**saved)).lexically_normal().string();
    else if (*saved)
        c.savedPath = "";
    if (Status st =
            r_.numberIn(t, "lighting", "min_power_fraction", c.lights.minPowerFraction, 0.0, 1.0);
        !st)
        return st;
    Result<std::optional<std::string>> fit = r_.string(t, "lighting", "fit_to_plate");
    if (!fit) return fit.error();
    if (*fit) {
        if (**fit == "auto")
            c.fitToPlate = FitToPlate::Auto;
        else if (**fit == "on")
            c.fitToPlate = FitToPlate::On;
        else if (**fit == "off")
            c.fitToPlate = FitToPlate::Off;
        else
            return fail(t.get("fit_to_plate"),
                        "'lighting.fit_to_plate' is '{}'; use auto, on or off", **fit);
    }
    return {};
}

Status ConfigReader::stringKey(const toml::table& t, std::string_view section, std::string_view key,
                               std::string& value) const {
    Result<std::optional<std::string>> v = r_.string(t, section, key);
    if (!v) return v.error();
    if (*v) value = **v;
    return {};
}

Status ConfigReader::parseRender(const toml::table& t, RenderConfig& c,
                                 LiveRenderConfig& live) const {
    // Past 20 keys clang-format would put one a line.
    // clang-format off
    if (Status st = r_.checkKeys(t, "render",
            {"width", "height", "samples_per_frame", "max_depth", "preview_max_depth", "seed",
             "photons", "preview_photons", "photon_radius_m", "photon_alpha", "photon_neighbours",
             "photon_splat", "resolution_scale", "preview_fps", "denoise", "denoise_levels",
             "preview_accumulate", "preview_history_frames", "preview_object_samples",
             "preview_sample_clamp", "preview_hold_depth", "preview_follow",
             "preview_resampling", "preview_phases", "preview_outline_test"});
        !st)
        return st;
    // clang-format on
    if (Status st = r_.integerIn(t, "render", "width", c.width, 0, 16384); !st) return st;
    if (Status st = r_.integerIn(t, "render", "height", c.height, 0, 16384); !st) return st;
    if ((c.width == 0) != (c.height == 0))
        return fail(&t,
                    "[render] needs both 'width' and 'height', or neither (the scene "
                    "camera's size)");
    if (Status st = r_.integerIn(t, "render", "samples_per_frame", live.samplesPerFrame, 1, 65536);
        !st)
        return st;
    if (Status st = r_.integerIn(t, "render", "max_depth", c.maxDepth, 1, 1024); !st) return st;
    if (Status st = r_.integerIn(t, "render", "preview_max_depth", c.previewMaxDepth, 0, 1024); !st)
        return st;
    if (Status st = r_.integerIn(t, "render", "seed", c.seed, 0, 0xffffffffLL); !st) return st;
    // photons: "auto" | "on" | "off" | a count per iteration (a TOML integer or string).
    if (const toml::node* node = t.get("photons")) {
        std::string spec;
        if (auto n = node->value_exact<int64_t>())
            spec = std::to_string(*n);
        else if (Status st = stringKey(t, "render", "photons", spec); !st)
            return st;
        if (Status st = applyPhotonSpec(spec, c.photons); !st)
            return fail(node, "'render.photons': {}", st.message());
    }
    if (Status st = r_.integerIn(t, "render", "preview_photons", c.photons.previewPerIteration, 128,
                                 kMaxPhotonsPerIteration);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "render", "photon_radius_m", c.photons.initialRadius, 0.0, 1e3);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "render", "photon_alpha", c.photons.alpha, 0.0, 1.0, true); !st)
        return st;
    if (Status st =
            r_.integerIn(t, "render", "photon_neighbours", c.photons.gatherNeighbours, 0, 1 << 20);
        !st)
        return st;
    Result<std::optional<bool>> splat = r_.boolean(t, "render", "photon_splat");
    if (!splat) return splat.error();
    c.photons.splatToCamera = splat->value_or(c.photons.splatToCamera);
    if (Status st = r_.numberIn(t, "render", "resolution_scale", c.resolutionScale, 0.0, 1.0, true);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "render", "preview_fps", c.previewFps, 0.0, 240.0); !st)
        return st;
    if (Status st = stringKey(t, "render", "denoise", c.denoise); !st) return st;
    if (c.denoise != "off" && c.denoise != "on" && c.denoise != "auto")
        return fail(t.get("denoise"), "'render.denoise' is '{}': use \"off\", \"on\" or \"auto\"",
                    c.denoise);
    if (Status st = r_.integerIn(t, "render", "denoise_levels", c.denoiseLevels, 1, 10); !st)
        return st;
    Result<std::optional<bool>> accumulate = r_.boolean(t, "render", "preview_accumulate");
    if (!accumulate) return accumulate.error();
    c.previewAccumulate = accumulate->value_or(c.previewAccumulate);
    if (Status st =
            r_.integerIn(t, "render", "preview_history_frames", c.previewHistoryFrames, 1, 1024);
        !st)
        return st;
    if (Status st =
            r_.numberIn(t, "render", "preview_object_samples", c.previewObjectSamples, 0.0, 16.0);
        !st)
        return st;
    if (Status st =
            r_.numberIn(t, "render", "preview_sample_clamp", c.previewSampleClamp, 0.0, 1e6);
        !st)
        return st;
    if (Status st = r_.booleanIn(t, "render", "preview_hold_depth", c.previewHoldDepth); !st)
        return st;
    if (Status st = r_.booleanIn(t, "render", "preview_follow", c.previewFollow); !st) return st;
    if (Status st = r_.booleanIn(t, "render", "preview_resampling", c.previewResampling); !st)
        return st;
    if (Status st = r_.booleanIn(t, "render", "preview_phases", c.previewPhases); !st) return st;
    if (Status st = r_.booleanIn(t, "render", "preview_outline_test", c.previewOutlineTest); !st)
        return st;
    return {};
}

Status ConfigReader::parseRefine(const toml::table& t, RefineConfig& c) const {
    if (Status st = r_.checkKeys(
            t, "refine",
            {"samples_per_step", "max_samples", "pose_threshold_m", "pose_threshold_deg",
             "lighting_threshold", "restart_after", "target_noise"});
        !st)
        return st;
    if (Status st = r_.integerIn(t, "refine", "samples_per_step", c.samplesPerStep, 1, 65536); !st)
        return st;
    if (Status st = r_.integerIn(t, "refine", "max_samples", c.maxSamples, 0, int64_t(1) << 40);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "refine", "pose_threshold_m", c.poseThresholdM, 0.0, 1e6); !st)
        return st;
    if (Status st = r_.numberIn(t, "refine", "pose_threshold_deg", c.poseThresholdDeg, 0.0, 180.0);
        !st)
        return st;
    if (Status st = r_.numberIn(t, "refine", "lighting_threshold", c.lightingThreshold, 0.0, 1e6);
        !st)
        return st;
    if (Status st = r_.integerIn(t, "refine", "restart_after", c.restartAfter, 1, 1000); !st)
        return st;
    if (Status st = r_.numberIn(t, "refine", "target_noise", c.targetNoise, 0.0, 1e6); !st)
        return st;
    return {};
}

Status ConfigReader::parseOutput(const toml::table& t, OutputConfig& c) const {
    if (Status st = r_.checkKeys(t, "output",
                                 {"kind", "folder", "card", "connector", "mode", "keep_frames",
                                  "max_mb", "min_free_mb", "colour"});
        !st)
        return st;
    std::string kind = "none";
    if (Status st = stringKey(t, "output", "kind", kind); !st) return st;
    if (kind == "none")
        c.kind = OutputKind::None;
    else if (kind == "files")
        c.kind = OutputKind::Files;
    else if (kind == "kms")
        c.kind = OutputKind::Kms;
    else
        return fail(t.get("kind"), "'output.kind' is '{}'; use kms, files or none", kind);
    for (auto [key, field] : {std::pair<const char*, std::string*>{"folder", &c.folder},
                              std::pair<const char*, std::string*>{"card", &c.card},
                              std::pair<const char*, std::string*>{"connector", &c.connector},
                              std::pair<const char*, std::string*>{"mode", &c.mode}}) {
        if (Status st = stringKey(t, "output", key, *field); !st) return st;
    }
    if (c.kind == OutputKind::Files) {
        if (c.folder.empty())
            return fail(&t, "[output] kind = \"files\" needs 'folder' (where the PNG frames go)");
        c.folder = (r_.folder() / fs::path(c.folder)).lexically_normal().string();
    }
    if (Status st = r_.integerIn(t, "output", "keep_frames", c.keepFrames, 1, 10'000'000); !st)
        return st;
    if (Status st = r_.integerIn(t, "output", "max_mb", c.maxMb, 1, 1 << 24); !st) return st;
    if (Status st = r_.integerIn(t, "output", "min_free_mb", c.minFreeMb, 0, 1 << 24); !st)
        return st;
    if (!c.mode.empty()) {
        unsigned w = 0, h = 0, hz = 0;
        char tail = 0;
        const int n = std::sscanf(c.mode.c_str(), "%ux%u@%u%c", &w, &h, &hz, &tail);
        if (!(n == 2 || n == 3) || w == 0 || h == 0)
            return fail(t.get("mode"),
                        "'output.mode' is '{}'; use WIDTHxHEIGHT or "
                        "WIDTHxHEIGHT@HZ, e.g. \"1920x1080@60\"",
                        c.mode);
    }
    return parseOutputColour(t, c);
}

Status ConfigReader::parseButton(const toml::table& t, ButtonConfig& c) const {
    if (Status st = r_.checkKeys(t, "button",
                                 {"chip", "line", "active_low", "debounce_ms", "long_press_ms",
                                  "led_chip", "led_line", "led_active_low"});
        !st)
        return st;
    for (auto [key, field] : {std::pair<const char*, std::string*>{"chip", &c.chip},
                              std::pair<const char*, std::string*>{"line", &c.line},
                              std::pair<const char*, std::string*>{"led_chip", &c.ledChip},
                              std::pair<const char*, std::string*>{"led_line", &c.ledLine}}) {
        if (Status st = stringKey(t, "button", key, *field); !st) return st;
    }
    if (c.chip.empty() || c.line.empty())
        return fail(&t,
                    "[button] needs 'chip' (path, name or label, e.g. \"gpiochip0\") and "
                    "'line' (name or offset, e.g. \"mode-button\")");
    for (auto [key, field] : {std::pair<const char*, bool*>{"active_low", &c.activeLow},
                              std::pair<const char*, bool*>{"led_active_low", &c.ledActiveLow}}) {
        Result<std::optional<bool>> b = r_.boolean(t, "button", key);
        if (!b) return b.error();
        if (*b) *field = **b;
    }
    if (Status st = r_.integerIn(t, "button", "debounce_ms", c.debounceMs, 0, 1000); !st) return st;
    if (Status st = r_.integerIn(t, "button", "long_press_ms", c.longPressMs, 100, 60000); !st)
        return st;
    if (c.longPressMs <= c.debounceMs)
        return fail(t.get("long_press_ms"),
                    "'button.long_press_ms' ({}) must be longer than "
                    "'button.debounce_ms' ({})",
                    c.longPressMs, c.debounceMs);
    if (c.ledChip.empty()) c.ledChip = c.chip;
    return {};
}

Status ConfigReader::parseControl(const toml::table& t, ControlConfig& c) const {
    if (Status st = r_.checkKeys(t, "control", {"socket"}); !st) return st;
    if (Status st = stringKey(t, "control", "socket", c.socketPath); !st) return st;
    if (!c.socketPath.empty())
        c.socketPath = (r_.folder() / fs::path(c.socketPath)).lexically_normal().string();
    return {};
}

Status ConfigReader::parseRecord(const toml::table& t, RecordConfig& c) const {
    if (Status st = r_.checkKeys(t, "record",
                                 {"dir", "auto", "min_free_mb", "flush_interval_ms", "queue_mb"});
        !st)
        return st;
    if (Status st = stringKey(t, "record", "dir", c.dir); !st) return st;
    // Absolute: `record start` prints the take's folder, and a relative one would depend on
    // where previsd was started.
    if (!c.dir.empty())
        c.dir = fs::absolute(r_.folder() / fs::path(c.dir)).lexically_normal().string();
    Result<std::optional<bool>> autoStart = r_.boolean(t, "record", "auto");
    if (!autoStart) return autoStart.error();
    c.autoStart = autoStart->value_or(false);
    if (Status st = r_.integerIn(t, "record", "min_free_mb", c.minFreeMb, 0, 1 << 24); !st)
        return st;
    if (Status st = r_.integerIn(t, "record", "flush_interval_ms", c.flushIntervalMs, 10, 60000);
        !st)
        return st;
    if (Status st = r_.integerIn(t, "record", "queue_mb", c.queueMb, 16, 16384); !st) return st;
    return {};
}

// The top level's keys, and the version this previs reads.
Status ConfigReader::checkTopLevel(const toml::table& root) const {
    if (Status st = r_.checkKeys(
            root, "",
            {"version", "scene", "cameras", "tracking", "lighting", "render", "refine", "output",
             "button", "control", "session", "record", "freed", "opentrackio", "timecode", "web"});
        !st)
        return st;
    const toml::node* version = root.get("version");
    if (!version)
        return fail(nullptr, "missing key 'version' (start the file with `version = {}`)",
                    kFormatVersion);
    const toml::value<int64_t>* v = version->as_integer();
    if (!v || v->get() != kFormatVersion)
        return fail(version, "'version' must be {} (this previs reads config version {} only)",
                    kFormatVersion, kFormatVersion);
    return {};
}

Status ConfigReader::parseScenePath(const toml::table& root, ServiceConfig& config) const {
    Result<std::optional<std::string>> scene = r_.string(root, "", "scene");
    if (!scene) return scene.error();
    if (!*scene)
        return fail(nullptr,
                    "missing key 'scene' (a .gltf/.glb or previs.toml scene, e.g. "
                    "scene = \"scene/previs.toml\")");
    Result<std::string> scenePath =
        r_.file(*root.get("scene"), "scene", **scene, {".gltf", ".glb", ".toml"}, "scene");
    if (!scenePath) return scenePath.error();
    config.scenePath = *scenePath;
    return {};
}

// [cameras.scene] (required) and [cameras.fisheye], each on its own device.
Status ConfigReader::parseCameras(const toml::table& root, ServiceConfig& config) const {
    Result<const toml::table*> cameras = r_.table(root, "", "cameras");
    if (!cameras) return cameras.error();
    if (!*cameras) return fail(nullptr, "missing [cameras.scene] (the camera that films the set)");
    if (Status st = r_.checkKeys(**cameras, "cameras", {"scene", "fisheye"}); !st) return st;
    Result<const toml::table*> sceneCamera = r_.table(**cameras, "cameras", "scene");
    if (!sceneCamera) return sceneCamera.error();
    if (!*sceneCamera)
        return fail(*cameras, "missing [cameras.scene] (the camera that films the set)");
    if (Status st = parseCamera(**sceneCamera, "scene", config.sceneCamera); !st) return st;
    Result<const toml::table*> fisheye = r_.table(**cameras, "cameras", "fisheye");
    if (!fisheye) return fisheye.error();
    if (*fisheye) {
        CameraConfig camera;
        if (Status st = parseCamera(**fisheye, "fisheye", camera); !st) return st;
        Result<std::optional<std::vector<double>>> mount =
            r_.numbers(**fisheye, "cameras.fisheye", "mount_rotation_deg", 3);
        if (!mount) return mount.error();
        if (*mount)
            config.lighting.fisheye.mountRotationDeg = {(**mount)[0], (**mount)[1], (**mount)[2]};
        if (!config.sceneCamera.device.empty() && camera.source == config.sceneCamera.source &&
            camera.device == config.sceneCamera.device)
            return fail(*fisheye,
                        "[cameras.fisheye] and [cameras.scene] both use '{}'; each "
                        "camera needs its own device",
                        camera.device);
        config.fisheyeCamera = std::move(camera);
    }
    return {};
}

// [tracking] (required) and [lighting].
Status ConfigReader::parseTrackingAndLighting(const toml::table& root,
                                              ServiceConfig& config) const {
    Result<const toml::table*> tracking = r_.table(root, "", "tracking");
    if (!tracking) return tracking.error();
    if (!*tracking)
        return fail(nullptr,
                    "missing [tracking] (at least board = \"board.toml\", the tag "
                    "layout; docs/board-format.md)");
    if (Status st = parseTracking(**tracking, config.tracking); !st) return st;
    // A recorded camera replays its take's own packets (freed.csv); a live one needs them sent.
    if (config.tracking.freedSource && config.tracking.freedListen.empty() &&
        config.sceneCamera.source != CameraSourceKind::Session)
        return fail(*tracking,
                    "[tracking] source = \"freed\" needs listen = \"HOST:PORT\" (where the "
                    "tracker sends its packets)");

    Result<const toml::table*> lighting = r_.table(root, "", "lighting");
    if (!lighting) return lighting.error();
    if (*lighting) {
        if (Status st = parseLighting(**lighting, config.lighting); !st) return st;
    }
    return {};
}

Status ConfigReader::parseOptionalSections(const toml::table& root, ServiceConfig& config) const {
    // Optional sections: absent means the defaults (no button, no display).
    struct Optional {
        const char* key;
        std::function<Status(const toml::table&)> parse;
    };
    ButtonConfig button;
    bool hasButton = false;
    const Optional sections[] = {
        {"render",
         [&](const toml::table& t) { return parseRender(t, config.render, config.liveRender); }},
        {"refine", [&](const toml::table& t) { return parseRefine(t, config.refine); }},
        {"output", [&](const toml::table& t) { return parseOutput(t, config.output); }},
        {"button",
         [&](const toml::table& t) {
             hasButton = true;
             return parseButton(t, button);
         }},
        {"control", [&](const toml::table& t) { return parseControl(t, config.control); }},
        {"record", [&](const toml::table& t) { return parseRecord(t, config.record); }},
        {"session",
         [&](const toml::table& t) -> Status {
             if (Status st = r_.checkKeys(t, "session", {"loop", "events"}); !st) return st;
             Result<std::optional<bool>> loop = r_.boolean(t, "session", "loop");
             if (!loop) return loop.error();
             config.loopSession = loop->value_or(true);
             Result<std::optional<bool>> events = r_.boolean(t, "session", "events");
             if (!events) return events.error();
             config.replaySessionEvents = events->value_or(false);
             return {};
         }},
    };
    for (const Optional& section : sections) {
        Result<const toml::table*> t = r_.table(root, "", section.key);
        if (!t) return t.error();
        if (*t) {
            if (Status st = section.parse(**t); !st) return st;
        }
    }
    if (hasButton) config.button = std::move(button);
    return {};
}

Result<ServiceConfig> ConfigReader::read(const toml::table& root) {
    if (Status st = checkTopLevel(root); !st) return st.error();
    ServiceConfig config;
    config.path = r_.path();
    if (Status st = parseScenePath(root, config); !st) return st.error();
    if (Status st = parseCameras(root, config); !st) return st.error();
    if (Status st = parseTrackingAndLighting(root, config); !st) return st.error();
    // The dial aims at the scene camera's rate unless [render] preview_fps says otherwise: a
    // preview cannot show more frames than the camera delivers.
    config.render.previewFps =
        config.sceneCamera.fps > 0.0 ? config.sceneCamera.fps : RenderConfig::kDefaultPreviewFps;
    if (Status st = parseOptionalSections(root, config); !st) return st.error();
    if (Status st = parseNetworkConfig(r_, root, config.network); !st) return st.error();
    return config;
}

}  // namespace

const char* toString(CameraSourceKind kind) {
    switch (kind) {
        case CameraSourceKind::V4L2:
            return "v4l2";
        case CameraSourceKind::Libcamera:
            return "libcamera";
        case CameraSourceKind::Session:
            return "session";
    }
    return "?";
}

const char* toString(OutputKind kind) {
    switch (kind) {
        case OutputKind::None:
            return "none";
        case OutputKind::Files:
            return "files";
        case OutputKind::Kms:
            return "kms";
    }
    return "?";
}

namespace {

// The startup part as a reload compares it: OpenColorIO transforms built from the file by the
// paths and names given beside them, the control socket as resolved.
StartupConfig comparedAtReload(const ServiceConfig& config) {
    StartupConfig c = config;
    c.sceneCamera.radiometry.colour = nullptr;
    if (c.fisheyeCamera) c.fisheyeCamera->radiometry.colour = nullptr;
    c.output.colour = nullptr;
    c.control.socketPath = controlSocketPath(config.control);
    return c;
}

// [cameras.<name>.colour] as given.
auto cameraColour(const CameraConfig& c) {
    return std::tie(c.colourGiven, c.colourConfigPath, c.colourInput, c.colourRange);
}

CameraConfig withoutColour(CameraConfig c) {
    c.colourGiven = false;
    c.colourConfigPath.clear();
    c.colourInput.clear();
    c.colourRange = CodeRange::Full;
    return c;
}

std::optional<CameraConfig> withoutColour(const std::optional<CameraConfig>& c) {
    return c ? std::optional(withoutColour(*c)) : std::nullopt;
}

auto outputColour(const OutputConfig& o) {
    return std::tie(o.colourGiven, o.colourConfigPath, o.colourDisplay, o.colourView);
}

OutputConfig withoutColour(OutputConfig o) {
    o.colourGiven = false;
    o.colourConfigPath.clear();
    o.colourDisplay.clear();
    o.colourView.clear();
    return o;
}

// The render keys a restart was always named for; a change of the others is named "render".
bool renderSizeOrSamplingDiffers(const RenderConfig& a, const RenderConfig& b) {
    return std::tie(a.width, a.height, a.maxDepth, a.seed, a.photons, a.previewFps,
                    a.resolutionScale) != std::tie(b.width, b.height, b.maxDepth, b.seed, b.photons,
                                                   b.previewFps, b.resolutionScale);
}

}  // namespace

std::vector<std::string> restartNeeded(const ServiceConfig& running, const ServiceConfig& fresh) {
    const StartupConfig a = comparedAtReload(running);
    const StartupConfig b = comparedAtReload(fresh);
    if (a == b) return {};
    std::vector<std::string> names;
    auto name = [&](bool differs, const char* what) {
        if (differs) names.emplace_back(what);
    };
    name(a.scenePath != b.scenePath, "scene");
    name(withoutColour(a.sceneCamera) != withoutColour(b.sceneCamera), "cameras.scene");
    name(withoutColour(a.fisheyeCamera) != withoutColour(b.fisheyeCamera), "cameras.fisheye");
    name(a.tracking != b.tracking, "tracking");
    name(a.lighting != b.lighting, "lighting");
    if (renderSizeOrSamplingDiffers(a.render, b.render))
        names.emplace_back(
            "render (size, max_depth, seed, photons, preview_fps, resolution_scale)");
    else
        name(a.render != b.render, "render");
    name(withoutColour(a.output) != withoutColour(b.output), "output");
    // OpenColorIO's transforms are built into the stages, the renderer and the display at start
    // (issue 54): a colour change is named, never silently ignored.
    name(cameraColour(a.sceneCamera) != cameraColour(b.sceneCamera), "cameras.scene.colour");
    name(a.fisheyeCamera && b.fisheyeCamera &&
             cameraColour(*a.fisheyeCamera) != cameraColour(*b.fisheyeCamera),
         "cameras.fisheye.colour");
    name(outputColour(a.output) != outputColour(b.output), "output.colour");
    name(a.button != b.button, "button");
    name(a.control != b.control, "control");
    name(a.record != b.record, "record");
    name(a.network.freed != b.network.freed, "freed");
    name(a.network.opentrackio != b.network.opentrackio, "opentrackio");
    name(a.network.timecode != b.network.timecode, "timecode");
    name(a.network.web != b.network.web, "web");
    name(a.loopSession != b.loopSession || a.replaySessionEvents != b.replaySessionEvents,
         "session");
    // A setting added to StartupConfig without a name here still needs the restart.
    if (names.empty()) names.emplace_back("settings read at start");
    return names;
}

Result<LabelRateRule> labelRateRule(const ServiceConfig& config, const CameraConfig& camera) {
    LabelRateRule rule{std::nullopt, camera.fps};
    const std::string& rate = config.network.timecode.rate;
    if (rate.empty()) return rule;
    Result<TimecodeRate> parsed = TimecodeRate::parse(rate);
    if (!parsed) return makeError("[timecode] rate: {}", parsed.message());
    rule.configured = *parsed;
    return rule;
}

std::string controlSocketPath(const ControlConfig& control) {
    if (!control.socketPath.empty()) return control.socketPath;
    const char* runtime = std::getenv("RUNTIME_DIRECTORY");
    // systemd may pass several folders separated by ':'; the first is ours.
    if (runtime && *runtime) {
        std::string first(runtime);
        first = first.substr(0, first.find(':'));
        return (fs::path(first) / "previsd.sock").string();
    }
    return "/run/previs/previsd.sock";
}

std::string takesFolder(const RecordConfig& record) {
    if (!record.dir.empty()) return record.dir;
    const char* state = std::getenv("STATE_DIRECTORY");
    if (!state || !*state) return (fs::current_path() / "takes").string();
    const std::string first = std::string(state).substr(0, std::string(state).find(':'));
    return (fs::path(first) / "takes").string();
}

std::string cameraColourSummary(const ServiceConfig& config) {
    std::string summary;
    auto add = [&](const char* name, const CameraConfig& camera) {
        if (!camera.radiometry.colour) return;
        summary += fmt::format("{}{} camera {}", summary.empty() ? "" : "; ", name,
                               camera.radiometry.colour->description());
    };
    add("scene", config.sceneCamera);
    if (config.fisheyeCamera) add("fisheye", *config.fisheyeCamera);
    return summary;
}

std::string savedLightingPath(const LightingConfig& lighting) {
    if (lighting.savedPath) return *lighting.savedPath;
    const char* state = std::getenv("STATE_DIRECTORY");
    if (!state || !*state) return "";
    // As RUNTIME_DIRECTORY: the first of several folders is ours.
    const std::string first = std::string(state).substr(0, std::string(state).find(':'));
    return (fs::path(first) / "last_lighting.exr").string();
}

const char* toString(LightingMode mode) {
    switch (mode) {
        case LightingMode::Environment:
            return "environment";
        case LightingMode::Lights:
            return "lights";
    }
    return "?";
}

Result<ServiceConfig> loadServiceConfig(const std::string& path, const std::string& relativeTo) {
    Result<toml::table> root = parseTomlFile(path, kWhat);
    if (!root) return root.error();
    try {
        ConfigReader reader(path);
        if (!relativeTo.empty()) reader.setFolder(relativeTo);
        return reader.read(*root);
    } catch (const std::exception& e) {  // toml++, OpenCV and the standard library throw
        return makeError("cannot load {} '{}': {}", kWhat, path, e.what());
    }
}

}  // namespace previs
