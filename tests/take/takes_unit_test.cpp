// The pieces of a final render and a track hand-off that need no GPU: frame ranges as post tools
// write them, the farm's plan, the per-frame seed, Nuke's ZXY angles, and the track smoother on
// synthetic motion with known truth; what a take may name (TakeFiles).
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/calib3d.hpp>
#include <random>
#include <set>

#include "io/session.h"
#include "net/freed_calibration.h"
#include "take/take_files.h"
#include "take/take_render.h"
#include "take/take_track.h"
#include "take/track_export.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"
#include "vision/inverse_tone_map.h"
#include "vision/pose_filter.h"
#include "vision/track_smoother.h"

namespace previs {
namespace {

std::vector<size_t> range(const std::string& text, size_t count) {
    Result<std::vector<size_t>> r = parseFrameRange(text, count);
    EXPECT_TRUE(r) << text << ": " << r.message();
    return r ? *r : std::vector<size_t>{};
}

TEST(FrameRange, SlicesAndPostToolLists) {
    using V = std::vector<size_t>;
    EXPECT_EQ(range("", 3), (V{0, 1, 2}));
    EXPECT_EQ(range("2:5", 10), (V{2, 3, 4})) << "A:B excludes B, as a Python slice";
    EXPECT_EQ(range(":2", 10), (V{0, 1}));
    EXPECT_EQ(range("8:", 10), (V{8, 9}));
    EXPECT_EQ(range("1-4", 10), (V{1, 2, 3, 4})) << "a post tool's range includes its end";
    EXPECT_EQ(range("1-9x3", 10), (V{1, 4, 7}));
    EXPECT_EQ(range("1,5,7-9", 10), (V{1, 5, 7, 8, 9}));
    EXPECT_EQ(range("5,1,1-2", 10), (V{1, 2, 5})) << "sorted, without repeats";
    for (const char* bad : {"5-2", "x", "1-", "1-4x0", "a:b", "0:11", "10", "3,,4"}) {
        Result<std::vector<size_t>> r = parseFrameRange(bad, 10);
        ASSERT_FALSE(r) << bad;
        EXPECT_NE(r.message().find(bad), std::string::npos) << r.message();
    }
}

TEST(FrameRange, APlanCoversEveryFrameOnceInNearEqualParts) {
    const std::vector<std::string> plan = planFrameRanges(range("0:10", 10), 3);
    EXPECT_EQ(plan, (std::vector<std::string>{"0:3", "3:6", "6:10"}));
    // Every part reads back, and together they are the frames, once each.
    const std::vector<size_t> frames = range("0-20x2,25", 30);
    std::multiset<size_t> seen;
    for (const std::string& part : planFrameRanges(frames, 4))
        for (size_t f : range(part, 30)) seen.insert(f);
    EXPECT_EQ(std::vector<size_t>(seen.begin(), seen.end()), frames);
    EXPECT_EQ(planFrameRanges(range("0:2", 2), 4),
              (std::vector<std::string>{"0:1", "1:2", "2:2", "2:2"}))
        << "a task beyond the frames gets an empty slice";
    EXPECT_TRUE(range("2:2", 2).empty());
}

TEST(FrameRange, EachFrameHasItsOwnSeed) {
    std::set<uint32_t> seeds;
    for (uint64_t k = 0; k < 1000; ++k) seeds.insert(takeFrameSeed(7, k));
    EXPECT_EQ(seeds.size(), 1000u);
    EXPECT_NE(takeFrameSeed(7, 3), takeFrameSeed(8, 3));
    EXPECT_EQ(takeFrameSeed(7, 3), takeFrameSeed(7, 3));
}

cv::Matx33d rotation(char axis, double deg) {
    const double r = deg * CV_PI / 180.0, c = std::cos(r), s = std::sin(r);
    if (axis == 'x') return {1, 0, 0, 0, c, -s, 0, s, c};
    if (axis == 'y') return {c, 0, s, 0, 1, 0, -s, 0, c};
    return {c, -s, 0, s, c, 0, 0, 0, 1};
}

// A camera off the world's axes, looking at the origin (OpenCV axes: x right, y down, z ahead).
cv::Matx44d lookingAtTheOrigin(const cv::Vec3d& position) {
    const cv::Vec3d z = cv::normalize(-position);
    const cv::Vec3d x = cv::normalize(z.cross(cv::Vec3d(0, -1, 0)));
    const cv::Vec3d y = z.cross(x);
    return {x[0], y[0], z[0], position[0], x[1], y[1], z[1], position[1],
            x[2], y[2], z[2], position[2], 0,    0,    0,    1};
}

// Row vector times an Imath-layout matrix (OpenEXR's p' = p · M).
cv::Vec4d timesImath(const cv::Vec4d& p, const std::array<float, 16>& m) {
    cv::Vec4d out;
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r) out[c] += p[r] * double(m[size_t(r * 4 + c)]);
    return out;
}

// worldToNDC as OpenEXR defines it, against OpenCV's own projection of the same points with the
// calibration's pinhole: (0, 0) the frame's top-left corner, (1, 1) its bottom-right, y down.
TEST(ExrCamera, WorldToNdcIsOpenCvsProjectionOverTheFrame) {
    // No skew: OpenCV's projection has none.
    const cv::Matx33d k(554.26, 0, 321.5, 0, 550.1, 178.25, 0, 0, 1);
    const cv::Size size(640, 360);
    const cv::Matx44d worldFromCamera = lookingAtTheOrigin({0.7, 0.45, -0.9});
    const std::array<float, 16> ndc = exrWorldToNDC(worldFromCamera, k, size);
    const cv::Matx44d cameraFromWorld = worldFromCamera.inv();
    const cv::Matx33d r = cameraFromWorld.get_minor<3, 3>(0, 0);
    cv::Vec3d rvec;
    cv::Rodrigues(r, rvec);
    const cv::Vec3d t(cameraFromWorld(0, 3), cameraFromWorld(1, 3), cameraFromWorld(2, 3));
    const std::vector<cv::Point3d> points = {{0, 0, 0}, {0.1, 0.05, -0.02}, {-0.2, 0.1, 0.15}};
    std::vector<cv::Point2d> pixels;
    cv::projectPoints(points, rvec, t, k, cv::noArray(), pixels);
    for (size_t i = 0; i < points.size(); ++i) {
        const cv::Vec4d h = timesImath({points[i].x, points[i].y, points[i].z, 1.0}, ndc);
        EXPECT_NEAR(h[0] / h[3], (pixels[i].x + 0.5) / size.width, 1e-6) << i;
        EXPECT_NEAR(h[1] / h[3], (pixels[i].y + 0.5) / size.height, 1e-6) << i;
    }
    // The camera looks at the origin: it lands near the frame's centre (the principal point).
    const cv::Vec4d origin = timesImath({0, 0, 0, 1}, ndc);
    EXPECT_NEAR(origin[0] / origin[3], 322.0 / 640, 1e-6);
}

// worldToCamera as OpenEXR defines it (RenderMan's camera space): the camera at the origin, +z
// ahead, +y up in the picture, +x right.
TEST(ExrCamera, WorldToCameraIsRenderMansCameraSpace) {
    const cv::Matx44d worldFromCamera = lookingAtTheOrigin({0.7, 0.45, -0.9});
    const std::array<float, 16> m = exrWorldToCamera(worldFromCamera);
    const cv::Vec4d camera = timesImath({0.7, 0.45, -0.9, 1.0}, m);
    EXPECT_NEAR(cv::norm(cv::Vec3d(camera[0], camera[1], camera[2])), 0.0, 1e-6);
    const cv::Vec4d origin = timesImath({0, 0, 0, 1}, m);
    EXPECT_NEAR(origin[2], std::sqrt(0.7 * 0.7 + 0.45 * 0.45 + 0.9 * 0.9), 1e-6);
    EXPECT_NEAR(origin[0], 0.0, 1e-6);
    // A point one step along the OpenCV camera's "down" is below: negative y.
    const cv::Vec4d h = worldFromCamera * cv::Vec4d(0, 0.1, 1, 1);
    EXPECT_LT(timesImath(h, m)[1], -0.05);
}

TEST(ExrCamera, FramesPerSecondIsTheVideoRateItIs) {
    EXPECT_EQ(exrFramesPerSecond(15.0), (std::pair{15, 1}));
    EXPECT_EQ(exrFramesPerSecond(1e9 / 66666667.0), (std::pair{15, 1}));
    EXPECT_EQ(exrFramesPerSecond(30000.0 / 1001.0), (std::pair{30000, 1001}));
    EXPECT_EQ(exrFramesPerSecond(24000.0 / 1001.0), (std::pair{24000, 1001}));
    EXPECT_EQ(exrFramesPerSecond(25.0), (std::pair{25, 1}));
    EXPECT_EQ(exrFramesPerSecond(12.345), (std::pair{12345, 1000}));
    EXPECT_EQ(exrFramesPerSecond(0.0), (std::pair{0, 0}));
}

TEST(Chan, ZxyAnglesOfTheCameraLookingAlongMinusZ) {
    const cv::Matx33d flip(1, 0, 0, 0, -1, 0, 0, 0, -1);  // OpenCV camera → −Z forward, +Y up
    for (const cv::Vec3d& angles : {cv::Vec3d(-40, -35, 0.2), cv::Vec3d(10, 170, -30),
                                    cv::Vec3d(0, 0, 0), cv::Vec3d(89.9, 45, 5)}) {
        const cv::Matx33d gl =
            rotation('y', angles[1]) * rotation('x', angles[0]) * rotation('z', angles[2]);
        const cv::Vec3d back = chanRotationDegrees(gl * flip);
        EXPECT_LT(cv::norm(back - angles), 1e-9) << angles << " came back as " << back;
    }
    // Straight down (tilt −90°): only pan + roll is defined; the matrix must still match.
    const cv::Matx33d down = rotation('y', 30) * rotation('x', -90);
    const cv::Vec3d a = chanRotationDegrees(down * flip);
    const cv::Matx33d rebuilt = rotation('y', a[1]) * rotation('x', a[0]) * rotation('z', a[2]);
    EXPECT_LT(cv::norm(rebuilt - down), 1e-9);
}

// A camera dollying at 0.5 m/s and panning at 20°/s, seen by a tracker with 1 mm and 0.05°
// noise at 30 fps: the smoothed track is closer to the truth than the raw one.
TEST(TrackSmoother, ReducesTrackerNoiseOnSmoothMotionAndBridgesShortGaps) {
    std::mt19937 rng(5);
    std::normal_distribution<double> noise(0.0, 1.0);
    std::vector<TrackSample> samples;
    std::vector<cv::Matx44d> truth;
    for (int i = 0; i < 150; ++i) {
        const double t = i / 30.0;
        cv::Matx44d m = cv::Matx44d::eye();
        const cv::Matx33d r = rotation('y', 20.0 * t) * rotation('x', -30.0);
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) m(a, b) = r(a, b);
        m(0, 3) = 0.5 * t;
        m(1, 3) = 1.5;
        m(2, 3) = 2.0;
        truth.push_back(m);
        TrackSample s;
        s.timestampNs = uint64_t(i) * 33'333'333ull;
        s.positionStdM = 0.001;
        s.rotationStdDeg = 0.05;
        if (i < 60 || i >= 66) {  // six lost frames: 0.2 s
            cv::Matx44d measured = m;
            for (int a = 0; a < 3; ++a) measured(a, 3) += 0.001 * noise(rng);
            const cv::Matx33d jitter =
                rotation('x', 0.05 * noise(rng)) * rotation('y', 0.05 * noise(rng)) * r;
            for (int a = 0; a < 3; ++a)
                for (int b = 0; b < 3; ++b) measured(a, b) = jitter(a, b);
            s.worldFromCamera = measured;
        }
        samples.push_back(s);
    }
    const std::vector<std::optional<cv::Matx44d>> smoothed = smoothTrack(samples);
    ASSERT_EQ(smoothed.size(), samples.size());
    double raw = 0.0, smooth = 0.0;
    int n = 0;
    for (size_t i = 0; i < samples.size(); ++i) {
        ASSERT_TRUE(smoothed[i]) << "frame " << i << ": a 0.2 s gap is bridged";
        const cv::Vec3d t(truth[i](0, 3), truth[i](1, 3), truth[i](2, 3));
        const cv::Vec3d s((*smoothed[i])(0, 3), (*smoothed[i])(1, 3), (*smoothed[i])(2, 3));
        // Within 3 mm where tracked (3σ of the 1 mm noise per axis, before smoothing); across
        // the gap, the ends' error plus their velocity's error over 0.1 s: within 6 mm.
        EXPECT_LT(cv::norm(s - t), samples[i].worldFromCamera ? 0.003 : 0.006) << "frame " << i;
        if (!samples[i].worldFromCamera) continue;
        const cv::Matx44d& m = *samples[i].worldFromCamera;
        raw += std::pow(cv::norm(cv::Vec3d(m(0, 3), m(1, 3), m(2, 3)) - t), 2);
        smooth += std::pow(cv::norm(s - t), 2);
        ++n;
    }
    EXPECT_LT(std::sqrt(smooth / n), 0.6 * std::sqrt(raw / n))
        << "RMS error, smoothed vs raw (m): " << std::sqrt(smooth / n) << " vs "
        << std::sqrt(raw / n);

    // A gap longer than maxGapSeconds is not bridged; nothing before the first pose.
    SmootherSettings strict;
    strict.maxGapSeconds = 0.1;
    samples[0].worldFromCamera.reset();
    const std::vector<std::optional<cv::Matx44d>> gapped = smoothTrack(samples, strict);
    EXPECT_FALSE(gapped[0]);
    EXPECT_TRUE(gapped[1]);
    EXPECT_TRUE(gapped[59]);
    EXPECT_FALSE(gapped[62]);
    EXPECT_TRUE(gapped[66]);
}

// The tracker's bias (issue 38), on the bundled demo take tracked as the service tracks it (its
// config's radiometry included). Over the still stretch (frames 20–44: one camera pose, new
// sensor noise each frame) the tracked camera sat 2.2 mm from the truth on every frame:
// libapriltag put each corner 0.3 px inside its black square, where the frames' tone curve moves
// a blurred edge's midpoint. Without a bias, the stretch's mean error is what corners accurate
// to the rendered-board tests' quarter pixel allow: the tracker's own one sigma (positionStdM,
// for 0.5 px corner noise) halved.
namespace fs = std::filesystem;

std::string fileText(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

// The demo's config with its paths made absolute, as a box's /etc/previs config names them.
std::string demoConfigWithAbsolutePaths(const fs::path& demo) {
    std::string text = fileText(demo / "previsd.toml");
    for (const std::string name : {"previs.toml", "session/cameras/scene", "scene_camera.yaml",
                                   "session/cameras/fisheye", "fisheye.yaml", "board.toml"}) {
        const size_t at = text.find('"' + name + '"');
        EXPECT_NE(at, std::string::npos) << name;
        if (at != std::string::npos) text.replace(at + 1, name.size(), (demo / name).string());
    }
    return text;
}

// The shipped demo is a take like any other (issue 52): it holds copies of everything its config
// names, exactly as the recorder copies them from examples/demo/previsd.toml, so it replays,
// renders and exports under the untrusted-take rules, with no config_dir outside it.
TEST(TakeFiles, TheShippedDemoTakeHoldsWhatItsConfigNames) {
    const fs::path demo = testing::sourcePath("examples/demo");
    Result<ServiceConfig> live = loadServiceConfig((demo / "previsd.toml").string());
    ASSERT_TRUE(live) << live.message();
    const fs::path copy = testing::scratchDir("takes_unit") / "demo_config";
    fs::remove_all(copy);
    fs::create_directories(copy);
    Result<std::string> configToml = copyConfigIntoTake(*live, copy.string());
    ASSERT_TRUE(configToml) << configToml.message();
    const fs::path take = demo / "session";
    EXPECT_EQ(fileText(take / "config.toml"), *configToml)
        << "regenerate with scripts/make_demo_session.sh; the copy is in " << copy;
    size_t files = 0;
    for (const auto& entry : fs::recursive_directory_iterator(copy / "config")) {
        if (!entry.is_regular_file()) continue;
        ++files;
        const fs::path rel = entry.path().lexically_relative(copy);
        EXPECT_EQ(fileText(take / rel), fileText(entry.path())) << rel;
    }
    size_t shipped = 0;
    for (const auto& entry : fs::recursive_directory_iterator(take / "config"))
        shipped += entry.is_regular_file() ? 1 : 0;
    EXPECT_EQ(shipped, files);

    Result<SessionInfo> session = openSession(take.string());
    ASSERT_TRUE(session) << session.message();
    EXPECT_EQ(session->configDirInTake, "");
    Result<ServiceConfig> config = loadSessionConfig(*session);
    ASSERT_TRUE(config) << config.message();
    EXPECT_EQ(fs::path(config->scenePath).lexically_relative(take).begin()->string(), "config");
}

// A take is untrusted whatever version it declares (issue 52): a v2 take's config naming a file
// by an absolute path, through a link, or a FreeD calibration outside it is refused.
TEST(TakeFiles, AnyVersionNamesOnlyFilesInsideTheTake) {
    const fs::path take = testing::scratchDir("takes_unit") / "v2_hostile";
    fs::remove_all(take);
    for (const char* camera : {"scene", "fisheye"}) {
        fs::create_directories(take / "cameras" / camera);
        std::ofstream(take / "cameras" / camera / "index.csv") << "";
    }
    fs::copy(testing::sourcePath("examples/demo/session/config"), take / "config",
             fs::copy_options::recursive);
    const std::string demoConfig =
        fileText(testing::sourcePath("examples/demo/session/config.toml"));
    std::ofstream(take / "session.toml") << "format = \"previs-session\"\nversion = 2\n";
    auto refused = [&](const std::string& config, const std::string& named) {
        std::ofstream(take / "config.toml") << config;
        Result<SessionInfo> session = openSession(take.string());
        ASSERT_TRUE(session) << session.message();
        Result<ServiceConfig> loaded = loadSessionConfig(*session);
        ASSERT_FALSE(loaded) << named;
        EXPECT_NE(loaded.message().find(named), std::string::npos) << loaded.message();
    };
    auto replace = [&](std::string text, const std::string& from, const std::string& to) {
        const size_t at = text.find(from);
        EXPECT_NE(at, std::string::npos) << from;
        return text.replace(at, from.size(), to);
    };
    const std::string board = "config/board/board.toml";
    const std::string absolute = (take / board).string();
    // toml++ writes the recorder's strings in single quotes.
    refused(replace(demoConfig, "'" + board + "'", "'" + absolute + "'"), "absolute");
    fs::create_directory_symlink(take / "config", take / "linked");
    refused(replace(demoConfig, "'" + board + "'", "'linked/board/board.toml'"), "symbolic link");
    // A valid calibration, so only the check can refuse it (v3 did not check this key either).
    ASSERT_TRUE(writeFreedCalibration((take.parent_path() / "v2_freed.toml").string(), {}));
    refused(replace(demoConfig, "[tracking]\n",
                    "[tracking]\nfreed_calibration = \"../v2_freed.toml\"\n"),
            "leaves the folder");
}

// `text` as the box's previsd.toml in `dir`, loaded, and a take recorded with it in dir/take: the
// demo's camera frames and the config copyConfigIntoTake writes for it (in *configToml).
void recordTake(const fs::path& demo, const fs::path& dir, const std::string& text,
                std::string* configToml) {
    std::ofstream(dir / "previsd.toml") << text;
    Result<ServiceConfig> live = loadServiceConfig((dir / "previsd.toml").string());
    ASSERT_TRUE(live) << live.message();

    const fs::path take = dir / "take";
    fs::create_directories(take);
    fs::copy(demo / "session" / "cameras", take / "cameras", fs::copy_options::recursive);
    Result<std::string> copied = copyConfigIntoTake(*live, take.string());
    ASSERT_TRUE(copied) << copied.message();
    *configToml = *copied;
}

// The demo config's scene camera as a camera whose curve is `input` of the OCIO config `ocio`
// instead of its radiometry's tone curve.
void sceneCameraThroughOcio(std::string& text, const std::string& ocio, const std::string& input) {
    const std::string curve =
        "tone_curve = \"banterle\"\nexposure_stops = 0.0\nwhite_balance = [1.0, 1.0, 1.0]\n"
        "max_radiance = 16.0\nwhite_luminance = 16.0\n\n[cameras.fisheye]";
    const size_t at = text.find(curve);
    ASSERT_NE(at, std::string::npos);
    text.replace(at, curve.size(),
                 fmt::format("exposure_stops = 0.0\n[cameras.scene.colour]\nocio_config = \"{}\"\n"
                             "input = \"{}\"\n\n[cameras.fisheye]",
                             ocio, input));
}

// A take recorded with a FreeD tracker's calibration holds a copy of it, so the check above
// (which now covers freed_calibration) still lets the take replay on any machine.
TEST(TakeFiles, ARecordedTakeHoldsItsFreedCalibration) {
    const fs::path demo = testing::sourcePath("examples/demo");
    const fs::path dir = testing::scratchDir("takes_unit") / "freed_take";
    fs::remove_all(dir);
    fs::create_directories(dir);
    ASSERT_TRUE(writeFreedCalibration((dir / "freed_calibration.toml").string(), {}));
    std::string text = demoConfigWithAbsolutePaths(demo);
    text.insert(
        text.find("[tracking]\n") + 11,
        fmt::format("freed_calibration = \"{}\"\n", (dir / "freed_calibration.toml").string()));
    std::string configToml;
    ASSERT_NO_FATAL_FAILURE(recordTake(demo, dir, text, &configToml));
    const fs::path take = dir / "take";
    EXPECT_NE(configToml.find("config/freed/freed_calibration.toml"), std::string::npos)
        << configToml;
    std::ofstream(take / "config.toml") << configToml;
    std::ofstream(take / "session.toml") << "format = \"previs-session\"\nversion = 3\n";
    Result<SessionInfo> session = openSession(take.string());
    ASSERT_TRUE(session) << session.message();
    Result<ServiceConfig> config = loadSessionConfig(*session);
    ASSERT_TRUE(config) << config.message();
    EXPECT_TRUE(config->tracking.freedCalibration.has_value());
}

// A camera's OCIO config (issue 54) is copied into the take as the calibrations are, and a take
// whose ocio_config leaves its folder is refused.
TEST(TakeFiles, ARecordedTakeHoldsItsCamerasOcioConfig) {
    const fs::path demo = testing::sourcePath("examples/demo");
    const fs::path dir = testing::scratchDir("takes_unit") / "ocio_take";
    fs::remove_all(dir);
    fs::create_directories(dir);
    std::ofstream(dir / "studio.ocio")
        << "ocio_profile_version: 2.1\nroles:\n  aces_interchange: ACES2065-1\n"
           "  default: ACES2065-1\ndisplays:\n  sRGB:\n"
           "    - !<View> {name: Raw, colorspace: ACES2065-1}\ncolorspaces:\n"
           "  - !<ColorSpace>\n    name: ACES2065-1\n  - !<ColorSpace>\n    name: LogC3\n"
           "    to_scene_reference: !<BuiltinTransform> "
           "{style: ARRI_ALEXA-LOGC-EI800-AWG_to_ACES2065-1}\n";
    std::string text = demoConfigWithAbsolutePaths(demo);
    // The scene camera as a LogC3 camera: its curve from the OCIO config, not the radiometry.
    ASSERT_NO_FATAL_FAILURE(sceneCameraThroughOcio(text, (dir / "studio.ocio").string(), "LogC3"));
    std::string configToml;
    ASSERT_NO_FATAL_FAILURE(recordTake(demo, dir, text, &configToml));
    const fs::path take = dir / "take";
    EXPECT_NE(configToml.find("config/colour/scene/studio.ocio"), std::string::npos) << configToml;
    std::ofstream(take / "session.toml") << "format = \"previs-session\"\nversion = 3\n";
    std::ofstream(take / "config.toml") << configToml;
    fs::remove(dir / "studio.ocio");  // the take stands alone
    Result<SessionInfo> session = openSession(take.string());
    ASSERT_TRUE(session) << session.message();
    Result<ServiceConfig> config = loadSessionConfig(*session);
    ASSERT_TRUE(config) << config.message();
    EXPECT_TRUE(config->sceneCamera.radiometry.colour);

    std::string outside = configToml;
    const std::string copied = "config/colour/scene/studio.ocio";
    fs::copy_file(take / copied, dir / "studio.ocio");
    outside.replace(outside.find(copied), copied.size(), "../studio.ocio");
    std::ofstream(take / "config.toml") << outside;
    Result<ServiceConfig> refused = loadSessionConfig(*session);
    ASSERT_FALSE(refused);
    EXPECT_NE(refused.message().find("leaves the folder"), std::string::npos) << refused.message();
}

// What an OCIO config finds through its search_path (issue 54): a take copies those LUTs with
// the config, keeping their layout, and keeps [output.colour] (its config copied the same way)
// while the rest of [output] stays the box's. Moved to another folder with the originals gone,
// the take's config decodes the camera and shows the composite as the box did.
TEST(TakeFiles, AMovedTakeKeepsItsOcioConfigsLutsAndItsOutputColour) {
    const fs::path demo = testing::sourcePath("examples/demo");
    const fs::path dir = testing::scratchDir("takes_unit") / "ocio_lut_take";
    fs::remove_all(dir);
    fs::create_directories(dir / "ocio");
    fs::create_directories(dir / "luts");
    // Doubles each channel: a grey code of 0.25 is 0.5 in ACES2065-1, and in the working space.
    std::ofstream(dir / "luts" / "double.spi1d")
        << "Version 1\nFrom 0.0 1.0\nLength 2\nComponents 1\n{\n0.0\n2.0\n}\n";
    std::ofstream(dir / "ocio" / "studio.ocio")
        << "ocio_profile_version: 2.1\nsearch_path: ../luts\nroles:\n"
           "  aces_interchange: ACES2065-1\n  default: ACES2065-1\ndisplays:\n  sRGB:\n"
           "    - !<View> {name: Doubled, colorspace: Doubled display}\ncolorspaces:\n"
           "  - !<ColorSpace>\n    name: ACES2065-1\n"
           "  - !<ColorSpace>\n    name: Doubled\n"
           "    to_scene_reference: !<FileTransform> {src: double.spi1d, interpolation: linear}\n"
           "  - !<ColorSpace>\n    name: Doubled display\n"
           "    from_scene_reference: !<FileTransform> {src: double.spi1d, interpolation: "
           "linear}\n";
    const std::string ocio = (dir / "ocio" / "studio.ocio").string();
    std::string text = demoConfigWithAbsolutePaths(demo);
    ASSERT_NO_FATAL_FAILURE(sceneCameraThroughOcio(text, ocio, "Doubled"));
    text += fmt::format("\n[output.colour]\nocio_config = \"{}\"\ndisplay = \"sRGB\"\n", ocio);
    std::string configToml;
    ASSERT_NO_FATAL_FAILURE(recordTake(demo, dir, text, &configToml));
    const fs::path recorded = dir / "take";
    std::ofstream(recorded / "session.toml") << "format = \"previs-session\"\nversion = 3\n";
    std::ofstream(recorded / "config.toml") << configToml;
    const fs::path moved = testing::scratchDir("takes_unit") / "ocio_lut_take_moved";
    fs::remove_all(moved);
    fs::rename(recorded, moved);
    fs::remove_all(dir / "ocio");
    fs::remove_all(dir / "luts");

    Result<SessionInfo> session = openSession(moved.string());
    ASSERT_TRUE(session) << session.message();
    Result<ServiceConfig> config = loadSessionConfig(*session);
    ASSERT_TRUE(config) << config.message();
    ASSERT_TRUE(config->sceneCamera.radiometry.colour);
    const std::array<float, 3> grey =
        inverseToneMapRgb({0.25f, 0.25f, 0.25f}, config->sceneCamera.radiometry);
    for (float v : grey) EXPECT_NEAR(v, 0.5f, 2e-3f) << "the take's LUT doubles";
    ASSERT_TRUE(config->output.colour) << "previs replay shows the take through the box's view";
    EXPECT_NE(config->output.colour->description().find("view 'Doubled'"), std::string::npos)
        << config->output.colour->description();
    EXPECT_EQ(config->output.kind, OutputKind::None) << "the box's own output stays the box's";
    EXPECT_TRUE(fs::exists(moved / "config/colour/scene/luts/double.spi1d"));
    EXPECT_TRUE(fs::exists(moved / "config/colour/output/ocio/studio.ocio"));
}

TEST(TakeTrack, TheDemoTakesStillStretchIsTrackedWithoutBias) {
    Result<SessionInfo> session = openSession(testing::sourcePath("examples/demo/session"));
    ASSERT_TRUE(session) << session.message();
    Result<ServiceConfig> config = loadSessionConfig(*session);
    ASSERT_TRUE(config) << config.message();
    Result<TakeTrack> track = trackTake(*session, *config);
    ASSERT_TRUE(track) << track.message();
    Result<std::vector<PoseRecord>> poses = loadPoses(session->dir);
    ASSERT_TRUE(poses) << poses.message();
    std::map<uint64_t, cv::Vec3d> truth;
    for (const PoseRecord& p : *poses)
        if (p.kind == PoseKind::Truth && p.frame && p.worldFromCamera)
            truth[*p.frame] = {(*p.worldFromCamera)[3], (*p.worldFromCamera)[7],
                               (*p.worldFromCamera)[11]};

    cv::Vec3d sum(0, 0, 0);
    std::vector<double> sigmas;
    for (size_t i = 20; i <= 44; ++i) {
        const TakeFrame& f = track->frames.at(i);
        ASSERT_TRUE(f.tracked) << "frame " << i << ": " << f.problem;
        ASSERT_TRUE(truth.count(f.entry.sequence)) << "frame " << i << " has no truth";
        const cv::Matx44d& m = *f.tracked;
        sum += cv::Vec3d(m(0, 3), m(1, 3), m(2, 3)) - truth[f.entry.sequence];
        sigmas.push_back(f.positionStdM);
    }
    const double bias = cv::norm(sum / double(sigmas.size()));
    std::sort(sigmas.begin(), sigmas.end());
    const double budget = 0.5 * sigmas[sigmas.size() / 2];
    std::printf("still stretch: mean position error %.3f mm, budget %.3f mm\n", bias * 1e3,
                budget * 1e3);
    EXPECT_LT(bias, budget);
}

// The live pose filter (vision/pose_filter.h) on synthetic motion with known truth, 30 fps,
// the tracker's noise as measured on the demo take (σ = 0.15 mm, 0.01° per axis): a held camera's
// jitter falls to under half, a 0.3 m/s move (10 mm a frame) is followed within a fifth of a
// frame's travel once under way (a frame of lag would be 10 mm), a lost frame holds the last pose,
// and a long gap starts over at the next pose.
TEST(PoseFilter, SteadiesAHeldCameraAndFollowsAMove) {
    std::mt19937 rng(7);
    std::normal_distribution<double> noise(0.0, 1.0);
    const double dt = 1.0 / 30.0, sigmaM = 0.15e-3, sigmaRad = 0.01 * M_PI / 180.0;
    auto truthAt = [](int i) {
        const double moving = std::max(0, i - 60) / 30.0;  // still for 2 s, then moving
        cv::Matx33d r;
        cv::Rodrigues(cv::Vec3d(0.0, 0.5 * moving, 0.0), r);  // and turning at 28.6°/s
        cv::Matx44d m = cv::Matx44d::eye();
        for (int a = 0; a < 3; ++a)
            for (int b = 0; b < 3; ++b) m(a, b) = r(a, b);
        m(0, 3) = 0.3 * moving;
        m(2, 3) = 1.5;
        return m;
    };
    PoseFilter filter;
    std::vector<double> rawStill, filteredStill, movingErrors, movingRotErrors;
    for (int i = 0; i < 90; ++i) {
        const cv::Matx44d truth = truthAt(i);
        cv::Matx33d jitter;
        cv::Rodrigues(sigmaRad * cv::Vec3d(noise(rng), noise(rng), noise(rng)), jitter);
        cv::Matx44d measured = truth;
        const cv::Matx33d r = truth.get_minor<3, 3>(0, 0) * jitter;
        for (int a = 0; a < 3; ++a) {
            for (int b = 0; b < 3; ++b) measured(a, b) = r(a, b);
            measured(a, 3) += sigmaM * noise(rng);
        }
        const std::optional<cv::Matx44d> f =
            filter.update({uint64_t(std::llround(i * dt * 1e9)), measured, 1e-3, 0.05});
        ASSERT_TRUE(f.has_value());
        if (i >= 15 && i < 60) {
            rawStill.push_back(measured(0, 3));
            filteredStill.push_back((*f)(0, 3));
        }
        if (i >= 65) {
            movingErrors.push_back(std::abs((*f)(0, 3) - truth(0, 3)));
            const cv::Matx33d d = truth.get_minor<3, 3>(0, 0).t() * f->get_minor<3, 3>(0, 0);
            movingRotErrors.push_back(std::acos(std::clamp((cv::trace(d) - 1.0) / 2.0, -1.0, 1.0)) *
                                      180.0 / M_PI);
        }
    }
    auto stddev = [](const std::vector<double>& v) {
        double m = 0.0, m2 = 0.0;
        for (double x : v) m += x, m2 += x * x;
        m /= double(v.size());
        return std::sqrt(m2 / double(v.size()) - m * m);
    };
    std::sort(movingErrors.begin(), movingErrors.end());
    std::sort(movingRotErrors.begin(), movingRotErrors.end());
    const double medianMoving = movingErrors[movingErrors.size() / 2];
    std::printf("held: %.3f -> %.3f mm; moving: median %.2f mm, %.3f deg\n", stddev(rawStill) * 1e3,
                stddev(filteredStill) * 1e3, medianMoving * 1e3,
                movingRotErrors[movingRotErrors.size() / 2]);
    EXPECT_LT(stddev(filteredStill), 0.5 * stddev(rawStill));
    EXPECT_LT(medianMoving, 2e-3);
    EXPECT_LT(movingRotErrors[movingRotErrors.size() / 2], 0.2);

    // Lost: the last filtered pose is held; after a gap over maxGapSeconds, the next pose as is.
    const uint64_t t = uint64_t(std::llround(90 * dt * 1e9));
    const std::optional<cv::Matx44d> held = filter.update({t, std::nullopt, 0.0, 0.0});
    ASSERT_TRUE(held.has_value());
    const cv::Matx44d far = truthAt(200);
    const std::optional<cv::Matx44d> restarted =
        filter.update({t + 2'000'000'000ULL, far, 1e-3, 0.05});
    ASSERT_TRUE(restarted.has_value());
    EXPECT_EQ(cv::norm(*restarted - far), 0.0);
}

}  // namespace
}  // namespace previs
