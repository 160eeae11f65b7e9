// Service config tests: the shipped example box config, the defaults of a minimal file, and each
// kind of user error (one message naming the file, the line and the key, and what to do).
#include "config/service_config.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "config/network_config.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

const std::string kExamples = testing::sourcePath("examples/box");

fs::path tempDir() { return previs::testing::scratchDir("previs_service_config_test"); }

std::string writeFile(const std::string& name, const std::string& text) {
    const fs::path path = tempDir() / name;
    fs::create_directories(path.parent_path());
    std::ofstream(path) << text;
    return path.string();
}

// A valid minimal config; tests splice their error into it.
std::string minimal(const std::string& sceneCameraExtra = "", const std::string& extra = "") {
    return fmt::format(R"(version = 1
scene = "{0}/../cubes_spheres/scene.gltf"
[cameras.scene]
device = "/dev/video0"
width = 1280
height = 720
calibration = "{0}/scene_camera.yaml"
{1}
[tracking]
board = "{0}/board.toml"
{2}
)",
                       kExamples, sceneCameraExtra, extra);
}

std::string replaced(std::string text, const std::string& from, const std::string& to) {
    const size_t at = text.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    return text.replace(at, from.size(), to);
}

TEST(ServiceConfig, LoadsTheExampleBox) {
    Result<ServiceConfig> c = loadServiceConfig(kExamples + "/previsd.toml");
    ASSERT_TRUE(c) << c.message();
    EXPECT_TRUE(fs::equivalent(c->scenePath, kExamples + "/../cubes_spheres/previs.toml"));

    const CameraConfig& scene = c->sceneCamera;
    EXPECT_EQ(scene.name, "scene");
    EXPECT_EQ(scene.source, CameraSourceKind::V4L2);
    EXPECT_EQ(scene.device,
              "/dev/v4l/by-id/usb-Magewell_USB_Capture_HDMI_B208220905267-video-index0");
    EXPECT_EQ(scene.width, 1280u);
    EXPECT_EQ(scene.height, 720u);
    EXPECT_EQ(scene.pixelFormat, "YUYV");
    EXPECT_EQ(scene.fps, 30.0);
    ASSERT_EQ(scene.controls.size(), 4u);  // in file order: auto exposure off before the time
    EXPECT_EQ(scene.controls[0].first, "Auto Exposure");
    EXPECT_EQ(scene.controls[1].first, "Exposure Time, Absolute");
    EXPECT_EQ(scene.controls[1].second, 156);
    ASSERT_TRUE(scene.calibration);
    EXPECT_NEAR(scene.calibration->fx(), 1108.5125, 1e-3);
    EXPECT_EQ(scene.radiometry.op, InverseToneMapOperator::Banterle);
    EXPECT_EQ(scene.radiometry.maxRadiance, 16.0f);

    ASSERT_TRUE(c->fisheyeCamera);
    EXPECT_EQ(c->fisheyeCamera->device,
              "/dev/v4l/by-id/usb-ELP_USB_FHD_Fisheye_Camera_2021-video-index0");
    ASSERT_TRUE(c->fisheyeCamera->calibration);
    EXPECT_EQ(c->fisheyeCamera->calibration->model(), DistortionModel::Fisheye);
    EXPECT_EQ(c->lighting.fisheye.mountRotationDeg, cv::Vec3d(-90.0, 0.0, 0.0));
    EXPECT_EQ(c->lighting.fisheye.width, 512);
    EXPECT_EQ(c->lighting.mode, LightingMode::Environment);

    ASSERT_TRUE(c->tracking.board);
    EXPECT_EQ(c->tracking.board->tags().size(), 4u);
    EXPECT_EQ(c->tracking.detector.family, "tag36h11");
    EXPECT_EQ(c->tracking.tracker.maxReprojErrorPx, 3.0);
}

TEST(ServiceConfig, MinimalFileTakesTheLibraryDefaults) {
    Result<ServiceConfig> c = loadServiceConfig(writeFile("minimal.toml", minimal()));
    ASSERT_TRUE(c) << c.message();
    EXPECT_FALSE(c->fisheyeCamera);
    EXPECT_EQ(c->sceneCamera.pixelFormat, "");
    EXPECT_EQ(c->sceneCamera.fps, 0.0);
    EXPECT_TRUE(c->sceneCamera.controls.empty());
    const InverseToneMapSettings defaults;
    EXPECT_EQ(c->sceneCamera.radiometry.op, defaults.op);
    EXPECT_EQ(c->sceneCamera.radiometry.exposureStops, defaults.exposureStops);
    const TagDetectorSettings detector;
    EXPECT_EQ(c->tracking.detector.decimate, detector.decimate);
    EXPECT_EQ(c->tracking.detector.refineEdges, detector.refineEdges);
    const LightEstimatorSettings lights;
    EXPECT_EQ(c->lighting.lights.maxLights, lights.maxLights);
    EXPECT_EQ(c->lighting.mode, LightingMode::Environment);
}

TEST(ServiceConfig, RecordedCameraFolderResolvesAgainstTheConfig) {
    writeFile("session/cameras/scene/index.csv",
              "# previs-session camera index v1: sequence,timestampNs,file,width,height\n");
    const std::string text = fmt::format(R"(version = 1
scene = "{0}/../cubes_spheres/scene.gltf"
[cameras.scene]
source = "session"
device = "session/cameras/scene"
width = 1280
height = 720
calibration = "{0}/scene_camera.yaml"
[tracking]
board = "{0}/board.toml"
)",
                                         kExamples);
    Result<ServiceConfig> c = loadServiceConfig(writeFile("replay.toml", text));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(c->sceneCamera.source, CameraSourceKind::Session);
    EXPECT_TRUE(fs::equivalent(c->sceneCamera.device, tempDir() / "session/cameras/scene"));
}

TEST(ServiceConfig, LibcameraCameraTakesItsTypedControls) {
    const std::string text =
        replaced(minimal("format = \"BGR888\"\n[cameras.scene.controls]\nexposure_time_us = 8000\n"
                         "analogue_gain = 2.5\ncolour_gains = [1.9, 1.4]"),
                 "device = \"/dev/video0\"", "source = \"libcamera\"\ndevice = \"imx477\"");
    Result<ServiceConfig> c = loadServiceConfig(writeFile("libcamera.toml", text));
    ASSERT_TRUE(c) << c.message();
    const CameraConfig& camera = c->sceneCamera;
    EXPECT_EQ(camera.source, CameraSourceKind::Libcamera);
    EXPECT_EQ(camera.device, "imx477");
    EXPECT_EQ(camera.pixelFormat, "BGR888");  // libcamera's name, checked when it opens
    EXPECT_EQ(camera.exposureUs, 8000);
    EXPECT_EQ(camera.analogueGain, 2.5f);
    ASSERT_TRUE(camera.colourGains);
    EXPECT_EQ((*camera.colourGains)[0], 1.9f);
    EXPECT_TRUE(camera.controls.empty());

    // A V4L2 driver's control name means nothing to libcamera.
    const std::string v4l2Names = replaced(minimal("controls = { Gain = 3 }"),
                                           "device = \"/dev/video0\"", "source = \"libcamera\"");
    Result<ServiceConfig> bad = loadServiceConfig(writeFile("libcamera_bad.toml", v4l2Names));
    ASSERT_FALSE(bad);
    EXPECT_NE(bad.message().find("unknown key 'Gain' in [cameras.scene.controls]"),
              std::string::npos)
        << bad.message();
}

// A live fisheye (V4L2 unless `source` says otherwise) with `body` appended to its section.
std::string liveFisheye(const std::string& body, const std::string& source = "") {
    return "[cameras.fisheye]\n" + source + "device = \"/dev/video1\"\nwidth = 640\n" +
           "height = 480\ncalibration = \"" + kExamples + "/fisheye.yaml\"\n" + body;
}

TEST(ServiceConfig, LiveFisheyeBracketCyclesItsExposureControl) {
    Result<ServiceConfig> c = loadServiceConfig(writeFile(
        "bracket_v4l2.toml", minimal(liveFisheye("[cameras.fisheye.controls]\nauto_exposure = 1\n"
                                                 "\"Exposure Time, Absolute\" = 1000\n"
                                                 "[cameras.fisheye.bracket]\nstops = [0, -4, -8]\n"
                                                 "frames_per_step = 2"))));
    ASSERT_TRUE(c) << c.message();
    ASSERT_TRUE(c->fisheyeCamera && c->fisheyeCamera->bracket);
    EXPECT_EQ(c->fisheyeCamera->bracket->stops, (std::vector<float>{0.0f, -4.0f, -8.0f}));
    EXPECT_EQ(c->fisheyeCamera->bracketFramesPerStep, 2);
    // The default control, matched against the driver's name for it in `controls`.
    EXPECT_EQ(c->fisheyeCamera->bracketControl, "exposure_time_absolute");

    c = loadServiceConfig(writeFile(
        "bracket_libcamera.toml",
        minimal(liveFisheye("[cameras.fisheye.controls]\nexposure_time_us = 10000\n"
                            "analogue_gain = 1.0\n[cameras.fisheye.bracket]\nstops = [0, -4]",
                            "source = \"libcamera\"\n"))));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(c->fisheyeCamera->source, CameraSourceKind::Libcamera);
    ASSERT_TRUE(c->fisheyeCamera->bracket);
}

struct BadConfig {
    const char* name;
    std::string text;
    std::vector<std::string> expected;  // substrings of the one message
};

class ServiceConfigErrors : public ::testing::TestWithParam<BadConfig> {};

TEST_P(ServiceConfigErrors, NameTheFileTheKeyAndTheFix) {
    const BadConfig& bad = GetParam();
    const std::string path = writeFile(std::string(bad.name) + ".toml", bad.text);
    Result<ServiceConfig> c = loadServiceConfig(path);
    ASSERT_FALSE(c) << bad.name << " was accepted";
    EXPECT_NE(c.message().find(path), std::string::npos) << c.message();
    for (const std::string& s : bad.expected)
        EXPECT_NE(c.message().find(s), std::string::npos)
            << bad.name << ": '" << s << "' not in: " << c.message();
    EXPECT_EQ(c.message().find('\n'), std::string::npos) << "one line: " << c.message();
}

std::vector<BadConfig> badConfigs() {
    const std::string e = kExamples;
    // A calibration that exists but is broken, and a board with a duplicate id.
    const std::string brokenCalibration =
        writeFile("broken.yaml", "%YAML:1.0\n---\nimage_width: 3\n");
    const std::string duplicateBoard = writeFile("dup_board.toml", R"(tag_size_m = 0.1
[[tag]]
id = 4
position_m = [0, 0, 0]
[[tag]]
id = 4
position_m = [1, 0, 0]
)");
    return {
        {"syntax", "version = 1\nscene = \"x.gltf", {"line 2", "not valid TOML"}},
        {"no_version", replaced(minimal(), "version = 1", ""), {"missing key 'version'"}},
        {"new_version", replaced(minimal(), "version = 1", "version = 2"), {"line 1", "'version'"}},
        {"typo_top", "sceen = 1\n" + minimal(), {"unknown key 'sceen'", "valid top-level"}},
        {"typo_camera", minimal("widht = 3"), {"line 8", "unknown key 'widht' in [cameras.scene]"}},
        {"no_scene_camera",
         fmt::format("version = 1\nscene = \"{}/../cubes_spheres/scene.gltf\"\n", e),
         {"missing [cameras.scene]"}},
        {"missing_scene_file",
         replaced(minimal(), "scene.gltf", "nothere.gltf"),
         {"'scene'", "does not exist"}},
        {"bad_source", minimal("source = \"usb\""), {"'cameras.scene.source' is 'usb'", "v4l2"}},
        {"no_device",
         replaced(minimal(), "device = \"/dev/video0\"", ""),
         {"[cameras.scene] needs 'device'"}},
        {"zero_width",
         replaced(minimal(), "width = 1280", "width = 0"),
         {"'cameras.scene.width' is 0"}},
        {"string_width",
         replaced(minimal(), "width = 1280", "width = \"1280\""),
         {"'cameras.scene.width' must be an integer, not a string"}},
        {"bad_format",
         minimal("format = \"RGGB\""),
         {"'cameras.scene.format' is 'RGGB'", "supported:"}},
        {"negative_fps", minimal("fps = -1"), {"'cameras.scene.fps' is -1"}},
        {"control_not_int",
         minimal("controls = { Gain = \"high\" }"),
         {"'cameras.scene.controls.\"Gain\"' must be an integer"}},
        {"no_calibration",
         replaced(minimal(), fmt::format("calibration = \"{}/scene_camera.yaml\"", e), ""),
         {"[cameras.scene] needs 'calibration'"}},
        {"broken_calibration",
         replaced(minimal(), fmt::format("{}/scene_camera.yaml", e), brokenCalibration),
         {"'cameras.scene.calibration'", brokenCalibration}},
        {"calibration_size",
         replaced(minimal(), "width = 1280", "width = 1920"),
         {"made at 1280x720", "configured 1920x720", "calibrate at the capture size"}},
        {"bad_tone_curve",
         minimal("[cameras.scene.radiometry]\ntone_curve = \"aces\""),
         {"'cameras.scene.radiometry.tone_curve' is 'aces'", "banterle"}},
        {"negative_gain",
         minimal("[cameras.scene.radiometry]\nwhite_balance = [1, -1, 1]"),
         {"'cameras.scene.radiometry.white_balance'", "for G", "> 0"}},
        {"short_gain",
         minimal("[cameras.scene.radiometry]\nwhite_balance = [1, 1]"),
         {"array of 3 numbers", "2 elements"}},
        {"zero_max_radiance",
         minimal("[cameras.scene.radiometry]\nmax_radiance = 0"),
         {"'cameras.scene.radiometry.max_radiance' is 0", "(0,"}},
        // Camera and display colour through OpenColorIO (issue 54).
        {"unknown_colour_space",
         minimal("[cameras.scene.colour]\ninput = \"LogC\""),
         {"line 9", "'cameras.scene.colour.input' is 'LogC'", "\"ARRI LogC3 (EI800)\""}},
        {"colour_without_input",
         minimal("[cameras.scene.colour]\nocio_config = \"\""),
         {"[cameras.scene.colour] needs 'input'", "\"Sony S-Log3 S-Gamut3\""}},
        {"unreadable_ocio_config",
         minimal("[cameras.scene.colour]\nocio_config = \"studio.ocio\"\ninput = \"LogC3\""),
         {"line 9", "'cameras.scene.colour.ocio_config': cannot read", "studio.ocio"}},
        {"colour_and_tone_curve",
         minimal("[cameras.scene.radiometry]\ntone_curve = \"banterle\"\n"
                 "[cameras.scene.colour]\ninput = \"Sony S-Log3 S-Gamut3\""),
         {"'cameras.scene.radiometry.tone_curve' and [cameras.scene.colour]", "keep one"}},
        {"unknown_view",
         minimal("", "[output.colour]\ndisplay = \"sRGB\"\nview = \"Filmic\""),
         {"'output.colour.view' is 'Filmic'", "\"ACES 1.0 - SDR Video\""}},
        {"unknown_range",
         minimal("[cameras.scene.colour]\ninput = \"Rec.709 - Camera\"\nrange = \"video\""),
         {"line 10", "'cameras.scene.colour.range' is 'video'", "\"legal\""}},
        {"colour_typo",
         minimal("[cameras.scene.colour]\ninput_space = \"ACEScct\""),
         {"unknown key 'input_space' in [cameras.scene.colour]"}},
        {"no_board",
         replaced(minimal(), fmt::format("board = \"{}/board.toml\"", e), ""),
         {"[tracking] needs 'board'"}},
        {"duplicate_board",
         replaced(minimal(), fmt::format("{}/board.toml", e), duplicateBoard),
         {"'tracking.board'", "id 4"}},
        {"unknown_family",
         minimal("", "family = \"tag99h99\""),
         {"'tracking.family' is 'tag99h99'", "tag36h11"}},
        {"family_mismatch", minimal("", "family = \"tag25h9\""), {"made of tag36h11 tags"}},
        {"bad_decimate", minimal("", "decimate = 0.5"), {"'tracking.decimate' is 0.5"}},
        {"bad_lighting_mode",
         minimal("", "[lighting]\nmode = \"sun\""),
         {"'lighting.mode' is 'sun'", "environment or lights"}},
        {"odd_map",
         minimal("", "[lighting]\nmap_width = 511"),
         {"'lighting.map_width' is 511", "even"}},
        {"same_device",
         minimal("[cameras.fisheye]\ndevice = \"/dev/video0\"\nwidth = 640\nheight = 480\n"
                 "calibration = \"" +
                 e + "/fisheye.yaml\""),
         {"both use '/dev/video0'"}},
        {"mount_on_scene",
         minimal("mount_rotation_deg = [0, 0, 0]"),
         {"unknown key 'mount_rotation_deg' in [cameras.scene]"}},
        {"session_without_index",
         minimal("source = \"session\""),
         {"not a recorded camera folder", "index.csv"}},
        // The service's own sections (issue 7).
        {"render_half_size",
         minimal("", "[render]\nwidth = 320"),
         {"[render] needs both 'width' and 'height'"}},
        {"render_zero_spp",
         minimal("", "[render]\nsamples_per_frame = 0"),
         {"'render.samples_per_frame' is 0"}},
        {"render_typo", minimal("", "[render]\nspp = 4"), {"unknown key 'spp' in [render]"}},
        {"render_photons",
         minimal("", "[render]\nphotons = \"lots\""),
         {"'render.photons'", "auto, on, off or a count"}},
        {"render_photon_alpha",
         minimal("", "[render]\nphoton_alpha = 0"),
         {"'render.photon_alpha' is 0"}},
        {"render_photon_neighbours_negative",
         minimal("", "[render]\nphoton_neighbours = -1"),
         {"'render.photon_neighbours' is -1"}},
        {"render_resolution_scale_zero",
         minimal("", "[render]\nresolution_scale = 0"),
         {"'render.resolution_scale' is 0"}},
        {"render_resolution_scale_above_one",
         minimal("", "[render]\nresolution_scale = 1.5"),
         {"'render.resolution_scale' is 1.5"}},
        {"render_preview_fps_negative",
         minimal("", "[render]\npreview_fps = -1"),
         {"'render.preview_fps' is -1"}},
        {"render_denoise_mode",
         minimal("", "[render]\ndenoise = \"sometimes\""),
         {"'render.denoise' is 'sometimes'", "\"off\", \"on\" or \"auto\""}},
        {"render_preview_resampling_type",
         minimal("", "[render]\npreview_resampling = \"on\""),
         {"'render.preview_resampling'", "true or false"}},
        {"render_preview_phases_type",
         minimal("", "[render]\npreview_phases = 1"),
         {"'render.preview_phases'", "true or false"}},
        {"render_preview_outline_test_type",
         minimal("", "[render]\npreview_outline_test = \"yes\""),
         {"'render.preview_outline_test'", "true or false"}},
        {"render_denoise_levels_zero",
         minimal("", "[render]\ndenoise_levels = 0"),
         {"'render.denoise_levels' is 0"}},
        {"render_hold_depth_not_a_boolean",
         minimal("", "[render]\npreview_hold_depth = 1"),
         {"preview_hold_depth"}},
        {"refine_negative",
         minimal("", "[refine]\npose_threshold_m = -1"),
         {"'refine.pose_threshold_m' is -1"}},
        {"refine_restart_after_zero",
         minimal("", "[refine]\nrestart_after = 0"),
         {"'refine.restart_after' is 0"}},
        {"refine_target_noise_negative",
         minimal("", "[refine]\ntarget_noise = -0.01"),
         {"'refine.target_noise' is -0.01"}},
        {"output_kind",
         minimal("", "[output]\nkind = \"hdmi\""),
         {"'output.kind' is 'hdmi'", "kms, files or none"}},
        {"output_files_no_folder", minimal("", "[output]\nkind = \"files\""), {"needs 'folder'"}},
        {"output_mode",
         minimal("", "[output]\nkind = \"kms\"\nmode = \"big\""),
         {"'output.mode' is 'big'", "WIDTHxHEIGHT"}},
        {"button_no_line",
         minimal("", "[button]\nchip = \"gpiochip0\""),
         {"[button] needs 'chip'", "'line'"}},
        {"button_long_short",
         minimal("",
                 "[button]\nchip = \"c\"\nline = \"l\"\n"
                 "debounce_ms = 200\nlong_press_ms = 150"),
         {"'button.long_press_ms' (150) must be longer"}},
        {"until_tracked",
         minimal("", "until_tracked = \"guess\""),
         {"'tracking.until_tracked' is 'guess'"}},
        {"session_loop_type", minimal("", "[session]\nloop = 1"), {"'session.loop'"}},
        // Live bracketing (capture/exposure_bracket.h) needs the exposure it scales.
        {"bracket_v4l2_without_base",
         minimal(liveFisheye("[cameras.fisheye.bracket]\nstops = [0, -4]")),
         {"[cameras.fisheye.bracket] cycles 'exposure_time_absolute'",
          "[cameras.fisheye.controls] does not set it"}},
        {"bracket_frames_per_step",
         minimal(liveFisheye("controls = { gain = 100 }\n[cameras.fisheye.bracket]\n"
                             "stops = [0, -4]\ncontrol = \"gain\"\nframes_per_step = 9")),
         {"'cameras.fisheye.bracket.frames_per_step' is 9"}},
        {"bracket_libcamera_without_base",
         minimal(
             liveFisheye("[cameras.fisheye.bracket]\nstops = [0, -4]", "source = \"libcamera\"\n")),
         {"needs the base exposure", "exposure_time_us and analogue_gain"}},
        {"bracket_libcamera_control",
         minimal(liveFisheye("[cameras.fisheye.controls]\nexposure_time_us = 10000\n"
                             "analogue_gain = 1.0\n[cameras.fisheye.bracket]\nstops = [0, -4]\n"
                             "control = \"gain\"",
                             "source = \"libcamera\"\n")),
         {"'cameras.fisheye.bracket.control' has no meaning for a libcamera camera"}},
        // Written into the generated socket units (issue 52): a newline would add a setting.
        {"web_listen_newline",
         minimal("", "[web]\nlisten = \"127.0.0.1\\nExecStartPre=/bin/sh:8080\""),
         {"'web.listen' holds a control character"}},
        {"tracking_listen_newline",
         minimal("", "listen = \"0.0.0.0\\n[Socket]\\nFreeBind=no:40000\""),
         {"'tracking.listen' holds a control character"}},
        {"web_host_names_not_a_name",
         minimal("", "[web]\nlisten = \"0.0.0.0:8080\"\nhost_names = [\"evil.example/x\"]"),
         {"'web.host_names' holds 'evil.example/x', not a host name"}},
        {"web_host_names_not_strings",
         minimal("", "[web]\nlisten = \"0.0.0.0:8080\"\nhost_names = [3]"),
         {"'web.host_names[0]' must be a string"}},
        {"freed_out_tab",
         minimal("", "[freed]\nout = \"10.0.0.\\t2:40000\""),
         {"'freed.out' holds a control character"}},
        {"render_photon_splat_type",
         minimal("", "[render]\nphoton_splat = \"yes\""),
         {"'render.photon_splat'"}},
    };
}

INSTANTIATE_TEST_SUITE_P(Config, ServiceConfigErrors, ::testing::ValuesIn(badConfigs()),
                         [](const auto& p) { return std::string(p.param.name); });

TEST(ServiceConfig, CameraAndDisplayColourBuildOcioOnlyWhenConfigured) {
    Result<ServiceConfig> plain = loadServiceConfig(writeFile("plain.toml", minimal()));
    ASSERT_TRUE(plain) << plain.message();
    EXPECT_FALSE(plain->sceneCamera.radiometry.colour);
    EXPECT_FALSE(plain->output.colour);

    Result<ServiceConfig> c = loadServiceConfig(
        writeFile("colour.toml", minimal("[cameras.scene.radiometry]\nexposure_stops = 1.0\n"
                                         "[cameras.scene.colour]\ninput = \"ARRI LogC3 (EI800)\"",
                                         "[output.colour]\ndisplay = \"Rec.1886 Rec.709\"")));
    ASSERT_TRUE(c) << c.message();
    ASSERT_TRUE(c->sceneCamera.radiometry.colour);
    EXPECT_TRUE(c->sceneCamera.encodingGiven()) << "the curve is known: the edge refit uses it";
    EXPECT_EQ(c->sceneCamera.colourInput, "ARRI LogC3 (EI800)");
    EXPECT_EQ(c->sceneCamera.radiometry.exposureStops, 1.0f);
    ASSERT_TRUE(c->output.colour);
    EXPECT_NE(c->output.colour->description().find("'Rec.1886 Rec.709', view 'ACES 1.0"),
              std::string::npos)
        << c->output.colour->description();
    // LogC3's 18 % grey code (0.391 ≈ 100/255) decodes near 0.18, halved by the exposure.
    const std::array<float, 3> grey =
        inverseToneMapRgb({0.391f, 0.391f, 0.391f}, c->sceneCamera.radiometry);
    EXPECT_NEAR(grey[1], 0.09f, 0.001f);
}

// previsd --check's OK line says which cameras OpenColorIO decodes and from what (issue 54).
TEST(ServiceConfig, CameraColourSummaryNamesEachCamerasInput) {
    Result<ServiceConfig> plain = loadServiceConfig(writeFile("plain_summary.toml", minimal()));
    ASSERT_TRUE(plain) << plain.message();
    EXPECT_EQ(cameraColourSummary(*plain), "");
    Result<ServiceConfig> c = loadServiceConfig(
        writeFile("colour_summary.toml",
                  minimal("[cameras.scene.colour]\ninput = \"Sony S-Log3 S-Gamut3\"")));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(cameraColourSummary(*c),
              "scene camera 'Sony S-Log3 S-Gamut3' from OCIO's built-in transforms");
    EXPECT_TRUE(c->sceneCamera.encodingGiven()) << "[colour] alone: the edge refit uses it";
    EXPECT_FALSE(plain->sceneCamera.encodingGiven());
}

// [cameras.<name>.colour] range = "legal": video levels undone before the input transform.
TEST(ServiceConfig, ALegalRangeCameraDecodesVideoLevels) {
    Result<ServiceConfig> c = loadServiceConfig(
        writeFile("colour_legal.toml", minimal("[cameras.scene.colour]\ninput = \"Rec.709 - "
                                               "Camera\"\nrange = \"legal\"")));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(c->sceneCamera.colourRange, CodeRange::Legal);
    EXPECT_EQ(cameraColourSummary(*c),
              "scene camera 'Rec.709 - Camera' from OCIO's built-in transforms, legal range "
              "(16-235)");
    const std::array<float, 3> black =
        inverseToneMapRgb({16 / 255.0f, 16 / 255.0f, 16 / 255.0f}, c->sceneCamera.radiometry);
    const std::array<float, 3> white =
        inverseToneMapRgb({235 / 255.0f, 235 / 255.0f, 235 / 255.0f}, c->sceneCamera.radiometry);
    EXPECT_NEAR(black[1], 0.0f, 1e-5f);
    EXPECT_NEAR(white[1], 1.0f, 1e-4f);
}

TEST(ServiceConfig, ServiceSectionsParse) {
    const std::string path =
        writeFile("service_sections.toml", minimal("", R"(until_tracked = "scene-camera"
[render]
width = 320
height = 180
samples_per_frame = 2
max_depth = 5
preview_max_depth = 2
preview_hold_depth = false
photons = 20000
preview_photons = 4096
photon_radius_m = 0.004
photon_alpha = 0.75
photon_neighbours = 48
photon_splat = false
resolution_scale = 0.3333
preview_fps = 12.5
denoise = "auto"
denoise_levels = 3
preview_resampling = true
preview_phases = false
preview_outline_test = false
[refine]
samples_per_step = 8
max_samples = 0
pose_threshold_deg = 1.5
target_noise = 0.02
restart_after = 5
[output]
kind = "files"
folder = "frames"
[button]
chip = "vmtest"
line = "mode-button"
led_line = "status-led"
[control]
socket = "ctl/previsd.sock"
[session]
loop = false
)"));
    Result<ServiceConfig> c = loadServiceConfig(path);
    ASSERT_TRUE(c) << c.message();
    EXPECT_TRUE(c->tracking.sceneCameraUntilTracked);
    EXPECT_EQ(c->render.width, 320u);
    EXPECT_EQ(c->liveRender.samplesPerFrame, 2u);
    EXPECT_EQ(c->render.maxDepth, 5u);
    EXPECT_EQ(c->render.previewMaxDepth, 2u);
    EXPECT_FALSE(c->render.previewHoldDepth);
    EXPECT_EQ(c->render.photons.mode, PhotonMode::On);
    EXPECT_EQ(c->render.photons.perIteration, 20000u);
    EXPECT_EQ(c->render.photons.previewPerIteration, 4096u);
    EXPECT_FLOAT_EQ(c->render.photons.initialRadius, 0.004f);
    EXPECT_FLOAT_EQ(c->render.photons.alpha, 0.75f);
    EXPECT_EQ(c->render.photons.gatherNeighbours, 48u);
    EXPECT_FALSE(c->render.photons.splatToCamera);
    EXPECT_FLOAT_EQ(c->render.resolutionScale, 0.3333f);
    EXPECT_DOUBLE_EQ(c->render.previewFps, 12.5);
    EXPECT_EQ(c->render.denoise, "auto");
    EXPECT_EQ(c->render.denoiseLevels, 3u);
    EXPECT_TRUE(c->render.previewResampling);
    EXPECT_FALSE(c->render.previewPhases);
    EXPECT_FALSE(c->render.previewOutlineTest);
    EXPECT_EQ(c->refine.samplesPerStep, 8u);
    EXPECT_EQ(c->refine.maxSamples, 0u);
    EXPECT_DOUBLE_EQ(c->refine.poseThresholdDeg, 1.5);
    EXPECT_DOUBLE_EQ(c->refine.targetNoise, 0.02);
    EXPECT_EQ(c->refine.restartAfter, 5);
    EXPECT_EQ(c->output.kind, OutputKind::Files);
    // Relative paths start at the config's folder.
    EXPECT_EQ(c->output.folder, (tempDir() / "frames").string());
    ASSERT_TRUE(c->button);
    EXPECT_EQ(c->button->ledChip, "vmtest");  // defaults to the button's chip
    EXPECT_EQ(c->button->debounceMs, 20);
    EXPECT_EQ(controlSocketPath(c->control), (tempDir() / "ctl/previsd.sock").string());
    EXPECT_FALSE(c->loopSession);
    // Live playback leaves the mode to the crew unless the session's presses are asked for
    // (issue 54: the demo undid every toggle within a second).
    EXPECT_FALSE(c->replaySessionEvents);
    Result<ServiceConfig> withEvents =
        loadServiceConfig(writeFile("events.toml", minimal("", "[session]\nevents = true")));
    ASSERT_TRUE(withEvents) << withEvents.message();
    EXPECT_TRUE(withEvents->replaySessionEvents);
}

TEST(ServiceConfig, DefaultControlSocketFollowsRuntimeDirectory) {
    ControlConfig none;
    ::setenv("RUNTIME_DIRECTORY", "/run/previs:/run/other", 1);
    EXPECT_EQ(controlSocketPath(none), "/run/previs/previsd.sock");
    ::setenv("RUNTIME_DIRECTORY", "/tmp/rt", 1);
    EXPECT_EQ(controlSocketPath(none), "/tmp/rt/previsd.sock");
    ::unsetenv("RUNTIME_DIRECTORY");
    EXPECT_EQ(controlSocketPath(none), "/run/previs/previsd.sock");
}

// [lighting] saved: a path relative to the config, "" off, unset the state directory's file.
TEST(ServiceConfig, SavedLightingPath) {
    LightingConfig unset;
    ::setenv("STATE_DIRECTORY", "/var/lib/previs:/var/lib/other", 1);
    EXPECT_EQ(savedLightingPath(unset), "/var/lib/previs/last_lighting.exr");
    ::unsetenv("STATE_DIRECTORY");
    EXPECT_EQ(savedLightingPath(unset), "");
    LightingConfig off;
    off.savedPath = "";
    EXPECT_EQ(savedLightingPath(off), "");
    const std::string path = writeFile("saved_lighting.toml", minimal("", R"([lighting]
saved = "state/lighting.exr"
)"));
    Result<ServiceConfig> c = loadServiceConfig(path);
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(savedLightingPath(c->lighting), (tempDir() / "state/lighting.exr").string());
}

TEST(ServiceConfig, MissingFileAndFolder) {
    Result<ServiceConfig> missing = loadServiceConfig("/nonexistent/previsd.toml");
    ASSERT_FALSE(missing);
    EXPECT_NE(missing.message().find("/nonexistent/previsd.toml"), std::string::npos);
    EXPECT_NE(missing.message().find("no such file"), std::string::npos);
    Result<ServiceConfig> folder = loadServiceConfig(tempDir().string());
    ASSERT_FALSE(folder);
    EXPECT_NE(folder.message().find("not a regular file"), std::string::npos);
}

}  // namespace
}  // namespace previs

namespace previs {
namespace {

// The web token (issue 52): one line ending is allowed; a short token, white space at either
// end (which no Authorization header carries) and control characters are refused in one line
// naming the config, the key and the token file.
TEST(WebToken, ShortPaddedOrControlTokensAreRefusedNamingTheConfigAndKey) {
    const std::string config = "/etc/previs/previsd.toml";
    WebConfig web;
    web.tokenFile = writeFile("token_ok", "0123456789abcdef0123\n");
    Result<std::string> ok = readWebToken(web, config);
    ASSERT_TRUE(ok) << ok.message();
    EXPECT_EQ(*ok, "0123456789abcdef0123");
    web.tokenFile = writeFile("token_crlf", "0123456789abcdef\r\n");
    ok = readWebToken(web, config);
    ASSERT_TRUE(ok) << ok.message();
    EXPECT_EQ(*ok, "0123456789abcdef");
    const std::pair<const char*, const char*> bad[] = {
        {"token_short", "s3cret-token\n"},
        {"token_leading_space", " 0123456789abcdef0123\n"},
        {"token_trailing_space", "0123456789abcdef0123 \n"},
        {"token_tab", "0123456789\tabcdef0123\n"},
        {"token_two_lines", "0123456789abcdef0123\n\n"},
        {"token_empty", ""},
    };
    for (const auto& [name, text] : bad) {
        web.tokenFile = writeFile(name, text);
        Result<std::string> token = readWebToken(web, config);
        ASSERT_FALSE(token) << name << " was accepted";
        for (const std::string& part : {config, std::string("[web] token_file"), web.tokenFile})
            EXPECT_NE(token.message().find(part), std::string::npos)
                << name << ": '" << part << "' not in: " << token.message();
        EXPECT_EQ(token.message().find('\n'), std::string::npos) << token.message();
    }
    web.tokenFile = writeFile("token_short", "s3cret-token\n");
    EXPECT_NE(readWebToken(web, config).message().find("at least 16 characters"),
              std::string::npos);
}

// Issue 52: the files output's ring and free-space floor are configurable, with bounded defaults.
TEST(ServiceConfig, FilesOutputRingAndFloor) {
    const std::string files = "[output]\nkind = \"files\"\nfolder = \"f\"\n";
    Result<ServiceConfig> c = loadServiceConfig(writeFile(
        "files_ring.toml", minimal("", files + "keep_frames = 50\nmax_mb = 20\nmin_free_mb = 0")));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(c->output.keepFrames, 50u);
    EXPECT_EQ(c->output.maxMb, 20u);
    EXPECT_EQ(c->output.minFreeMb, 0u);
    c = loadServiceConfig(writeFile("files_default.toml", minimal("", files)));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(c->output.keepFrames, 1000u);
    EXPECT_EQ(c->output.maxMb, 1024u);
    EXPECT_EQ(c->output.minFreeMb, 256u);
    Result<ServiceConfig> bad =
        loadServiceConfig(writeFile("files_zero.toml", minimal("", files + "keep_frames = 0")));
    ASSERT_FALSE(bad);
    EXPECT_NE(bad.message().find("output.keep_frames"), std::string::npos) << bad.message();
}

// The names the monitor page is opened by pass to its Host check (docs/web-monitor.md).
TEST(ServiceConfig, WebHostNames) {
    const std::string web = "[web]\nlisten = \"0.0.0.0:8080\"\n";
    Result<ServiceConfig> c = loadServiceConfig(writeFile(
        "host_names.toml", minimal("", web + "host_names = [\"previs.local\", \"box-3\"]")));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(c->network.web.hostNames, (std::vector<std::string>{"previs.local", "box-3"}));
    c = loadServiceConfig(writeFile("host_names_default.toml", minimal("", web)));
    ASSERT_TRUE(c) << c.message();
    EXPECT_TRUE(c->network.web.hostNames.empty());
}

// docs/config-format.md: token_file = "" means the unit's credential (web-token), as no key does;
// it was read as the config's folder, and previsd refused to start ("the token in '/etc/previs/'
// is empty").
TEST(ServiceConfig, AnEmptyWebTokenFileMeansTheUnitsCredential) {
    const std::string web = "[web]\nlisten = \"0.0.0.0:8080\"\n";
    Result<ServiceConfig> c = loadServiceConfig(
        writeFile("token_file_empty.toml", minimal("", web + "token_file = \"\"")));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(c->network.web.tokenFile, "");
    c = loadServiceConfig(
        writeFile("token_file_named.toml", minimal("", web + "token_file = \"t\"")));
    ASSERT_TRUE(c) << c.message();
    EXPECT_EQ(fs::path(c->network.web.tokenFile).filename(), "t");
}

// A reload (Service::reload) names what only a restart applies and nothing else (issue 55): the
// same file read again (new calibration, board and OpenColorIO objects) needs none; the live part
// ([refine], samples_per_frame) none; each startup section by its name, a colour change only as
// its colour; a key no restart name lists still needs a restart.
TEST(ServiceConfig, AReloadNamesWhatNeedsARestart) {
    const std::string colour = "[cameras.scene.colour]\ninput = \"ARRI LogC3 (EI800)\"\n";
    const std::string outputColour = "[output.colour]\ndisplay = \"sRGB\"\n";
    Result<ServiceConfig> running =
        loadServiceConfig(writeFile("reload.toml", minimal(colour, outputColour)));
    ASSERT_TRUE(running) << running.message();
    // The file edited in place, as a reload reads it.
    auto namesFor = [&](const std::string& text) {
        Result<ServiceConfig> fresh = loadServiceConfig(writeFile("reload.toml", text));
        EXPECT_TRUE(fresh) << fresh.message();
        return fresh ? restartNeeded(*running, *fresh) : std::vector<std::string>{"unread"};
    };
    using Names = std::vector<std::string>;
    EXPECT_EQ(namesFor(minimal(colour, outputColour)), Names{});
    EXPECT_EQ(
        namesFor(minimal(colour, outputColour + "[refine]\nmax_samples = 64\ntarget_noise = 0.05\n"
                                                "[render]\nsamples_per_frame = 4\n")),
        Names{});
    EXPECT_EQ(namesFor(minimal("[cameras.scene.colour]\ninput = \"Sony S-Log3 S-Gamut3\"\n",
                               outputColour)),
              Names{"cameras.scene.colour"});
    EXPECT_EQ(namesFor(minimal(colour, outputColour + "[render]\nwidth = 640\nheight = 360\n")),
              Names{"render (size, max_depth, seed, photons, preview_fps, resolution_scale)"});
    EXPECT_EQ(namesFor(minimal(colour, outputColour + "[render]\ndenoise = \"off\"\n")),
              Names{"render"});
    EXPECT_EQ(
        namesFor(minimal(colour, outputColour + "[record]\nmin_free_mb = 10\n[timecode]\nrate = "
                                                "\"25\"\n")),
        (Names{"record", "timecode"}));
    EXPECT_EQ(namesFor(replaced(minimal(colour, outputColour), "width = 1280\nheight = 720",
                                "width = 1280\nheight = 720\nformat = \"MJPG\"")),
              Names{"cameras.scene"});
    // Every startup section compares whole: a field no name covers is still named.
    ServiceConfig fresh = *running;
    fresh.tracking.detector.decodeSharpening = 0.5;
    fresh.lighting.updateHz = 1.0;
    EXPECT_EQ(restartNeeded(*running, fresh), (Names{"tracking", "lighting"}));
}

// A colour section added or removed is named as its colour alone: the camera's other settings
// did not change, though [colour] makes its encoding known as [radiometry] does; and an
// [output.colour] of the defaults alone is still a colour section.
TEST(ServiceConfig, AReloadNamesAColourSectionAddedOrRemovedAsItsColourAlone) {
    const std::string colour = "[cameras.scene.colour]\ninput = \"ARRI LogC3 (EI800)\"\n";
    const std::string fisheye = liveFisheye("");
    const std::string fisheyeColour = "[cameras.fisheye.colour]\ninput = \"ARRI LogC3 (EI800)\"\n";
    using Names = std::vector<std::string>;
    auto namesFor = [](const std::string& running, const std::string& fresh) {
        // The file edited in place, as a reload reads it.
        Result<ServiceConfig> a = loadServiceConfig(writeFile("colour.toml", running));
        Result<ServiceConfig> b = loadServiceConfig(writeFile("colour.toml", fresh));
        EXPECT_TRUE(a && b) << (a ? b.message() : a.message());
        return a && b ? restartNeeded(*a, *b) : Names{"unread"};
    };
    EXPECT_EQ(namesFor(minimal(), minimal(colour)), Names{"cameras.scene.colour"});
    EXPECT_EQ(namesFor(minimal(colour), minimal()), Names{"cameras.scene.colour"});
    EXPECT_EQ(namesFor(minimal(fisheye), minimal(fisheye + fisheyeColour)),
              Names{"cameras.fisheye.colour"});
    EXPECT_EQ(namesFor(minimal(fisheye + fisheyeColour), minimal(fisheye)),
              Names{"cameras.fisheye.colour"});
    EXPECT_EQ(namesFor(minimal(), minimal("", "[output.colour]\n")), Names{"output.colour"});
    EXPECT_EQ(namesFor(minimal("", "[output.colour]\n"), minimal()), Names{"output.colour"});
}

}  // namespace
}  // namespace previs
