// Light that matches the set (issue 51), checked against ground truth: the bundled demo's
// refined still frame, rendered by the real `previs render-session` from the take's own plate,
// tracked pose and fisheye brackets, against the truth the generator rendered at the frame's
// true pose with the true lighting (examples/demo/truth/, bench/light_truth.h): the virtual
// balls' shadows take as much light from the real table as they would on the set, in the same
// place, and the balls are as bright as the truth.

#include "bench/light_truth.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "tests/support/process.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

const std::string kDemoTake = testing::sourcePath("examples/demo/session");
const std::string kDemoTruth = testing::sourcePath("examples/demo/truth");

std::string fileText(const fs::path& path) {
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

// The box's final render of one frame at half the plate's size (the truth is box-filtered to
// it): 64 samples a pixel, whose noise on the regions' sums is below 1 % (their pixels number
// in the hundreds; the truth's own error is in truth.toml, 0.1–0.3 %).
constexpr int kFinalSpp = 64;
Result<BoxFrame> renderFrame(const std::string& take, int frame, const fs::path& dir,
                             int spp = kFinalSpp) {
    const fs::path out = dir / "render";
    const std::vector<std::string> argv{PREVIS_BINARY,
                                        "render-session",
                                        take,
                                        "--out",
                                        out.string(),
                                        "--frames",
                                        fmt::format("{}:{}", frame, frame + 1),
                                        "--spp",
                                        std::to_string(spp),
                                        "--width",
                                        "320",
                                        "--height",
                                        "180",
                                        "--aov",
                                        "mixed,real,mask",
                                        "--quiet"};
    if (int rc = testing::runProcess(argv, (dir / "render.log").string(), 600s); rc != 0)
        return makeError("render-session exited {}: {}", rc, fileText(dir / "render.log"));
    return loadBoxFrame((out / fmt::format("frame_{:06d}.exr", frame)).string());
}

// The demo take as a box with an 8-bit fisheye and no bracket would have recorded it: only the
// 0-stop frames of each bracket (their lamps clipped at 16), the config without its bracket and
// with `[lighting] fit_to_plate = FIT`. Its config's files are the demo's.
fs::path singleExposureTake(const fs::path& dir, const std::string& fit) {
    const fs::path take = dir / "single_exposure";
    fs::remove_all(take);
    fs::create_directories(dir);
    fs::copy(kDemoTake, take, fs::copy_options::recursive);
    const fs::path index = take / "cameras" / "fisheye" / "index.csv";
    std::istringstream lines(fileText(index));
    std::string kept, line;
    while (std::getline(lines, line))
        if (line.starts_with("#") || line.ends_with(",0")) kept += line + "\n";
    std::ofstream(index) << kept;
    std::string config = fileText(take / "config.toml");
    const size_t bracket = config.find("[cameras.fisheye.bracket]");
    EXPECT_NE(bracket, std::string::npos);
    config.erase(bracket, config.find("\n\n", bracket) - bracket);
    const std::string lighting = "[lighting]\n";
    config.insert(config.find(lighting) + lighting.size(),
                  fmt::format("fit_to_plate = \"{}\"\n", fit));
    std::ofstream(take / "config.toml") << config;
    return take;
}

const TruthFrame& stillFrame(const std::vector<TruthFrame>& truth) {
    const auto still =
        std::find_if(truth.begin(), truth.end(), [](const TruthFrame& f) { return f.still; });
    EXPECT_NE(still, truth.end()) << "truth.toml has no still frame";
    return *still;
}

void report(const char* what, const TruthScore& s) {
    std::string objects;
    for (size_t i = 0; i < s.objectRatios.size(); ++i)
        objects += fmt::format(" {:.3f} ({} px)", s.objectRatios[i], s.objectPixels[i]);
    std::printf("%s: shadow energy %.3f, IoU %.3f (truth %zu px, box %zu px), objects%s\n", what,
                s.shadowEnergyRatio, s.shadowIoU, s.shadowPixelsTruth, s.shadowPixelsBox,
                objects.c_str());
}

TEST(LightTruth, DemoRefinedStillFrameIsLitAndShadowedAsTheSet) {
    Result<std::vector<TruthFrame>> truth = loadTruth(kDemoTruth);
    ASSERT_TRUE(truth.ok()) << truth.message();
    const TruthFrame& still = stillFrame(*truth);
    const fs::path dir = testing::scratchDir("previs_light_truth") / "demo";
    Result<BoxFrame> box = renderFrame(kDemoTake, still.index, dir);
    ASSERT_TRUE(box.ok()) << box.message();
    Result<TruthScore> score = scoreAgainstTruth(*box, still);
    ASSERT_TRUE(score.ok()) << score.message();
    report("demo, bracketed fisheye", *score);
    // The issue's targets.
    EXPECT_GE(score->shadowEnergyRatio, 0.9);
    EXPECT_LE(score->shadowEnergyRatio, 1.1);
    EXPECT_GE(score->shadowIoU, 0.9);
    ASSERT_EQ(score->objectRatios.size(), 2u) << "the red and the chrome ball";
    for (double r : score->objectRatios) EXPECT_NEAR(r, 1.0, 0.10);
}

// The same frame from a single 8-bit fisheye exposure: the lamps clip, and only the fit to the
// plate (render/lighting_fit.h) can find their power. Without it the box is where the issue
// found it (balls at 0.2-0.3 of the truth), with it within the issue's targets.
TEST(LightTruth, ASingleClippedExposureIsFittedToThePlate) {
    Result<std::vector<TruthFrame>> truth = loadTruth(kDemoTruth);
    ASSERT_TRUE(truth.ok()) << truth.message();
    const TruthFrame& still = stillFrame(*truth);
    const fs::path dir = testing::scratchDir("previs_light_truth");
    std::map<std::string, TruthScore> scores;
    for (const std::string fit : {"off", "auto"}) {
        const fs::path take = singleExposureTake(dir / fit, fit);
        // Without the fit the ratios sit far below their bounds (0.09 of 0.3, 0.3 of 0.5): 8
        // samples, whose noise on the regions' sums is below 3 %, show it.
        Result<BoxFrame> box =
            renderFrame(take.string(), still.index, dir / fit, fit == "off" ? 8 : kFinalSpp);
        ASSERT_TRUE(box.ok()) << box.message();
        Result<TruthScore> score = scoreAgainstTruth(*box, still);
        ASSERT_TRUE(score.ok()) << score.message();
        report(fit == "off" ? "demo, one clipped exposure, no fit"
                            : "demo, one clipped exposure, fitted",
               *score);
        scores[fit] = *score;
    }
    // Without the fit the clipped lamps leave the balls and their shadows far too dim.
    EXPECT_LT(scores["off"].shadowEnergyRatio, 0.3);
    for (double r : scores["off"].objectRatios) EXPECT_LT(r, 0.5);
    // The issue's targets for the fit alone.
    const TruthScore& fitted = scores["auto"];
    EXPECT_GE(fitted.shadowEnergyRatio, 0.8);
    EXPECT_LE(fitted.shadowEnergyRatio, 1.2);
    ASSERT_EQ(fitted.objectRatios.size(), 2u);
    for (double r : fitted.objectRatios) EXPECT_NEAR(r, 1.0, 0.15);
}

// The demo's set under a second lighting, outdoors: Poly Haven's rooitou_park, whose sun (a few
// texels of radiance 65000) clips even at the bracket's −10 stops, so the merged map holds the
// sky but only a lower bound of the sun. The generator makes a short take of it (the camera's
// arc and the first still frame) with its truth; the box renders the still frame from the take.
TEST(LightTruth, AnOutdoorSunBeyondTheBracketIsFittedToThePlate) {
    const std::string data = testing::sharedDataDir();
    const std::string map = data + "/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr";
    if (data.empty() || !fs::exists(map)) GTEST_SKIP() << "no shared data (PREVIS_DATA_DIR)";
    const fs::path dir = testing::scratchDir("previs_light_truth") / "outdoor";
    fs::create_directories(dir);
    for (const char* file :
         {"previsd.toml", "previs.toml", "board.toml", "scene_camera.yaml", "fisheye.yaml"})
        fs::copy_file(fs::path(kDemoTake).parent_path() / file, dir / file,
                      fs::copy_options::overwrite_existing);
    // The first still frame (20) after the arc; few samples for the tracked arc's plates, the
    // still plate and the truth as a test needs them (region sums, not pixels).
    const std::vector<std::string> generate{MAKE_DEMO_SESSION_BINARY,
                                            "--demo-dir",
                                            dir.string(),
                                            "--env",
                                            map,
                                            "--env-name",
                                            "envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr",
                                            "--env-scale",
                                            "1.0",
                                            "--frames",
                                            "21",
                                            "--moving-spp",
                                            "2",
                                            "--still-spp",
                                            "32",
                                            "--truth-frames",
                                            "20",
                                            "--truth-spp",
                                            "128"};
    ASSERT_EQ(testing::runProcess(generate, (dir / "generate.log").string(), 600s), 0)
        << fileText(dir / "generate.log");
    Result<std::vector<TruthFrame>> truth = loadTruth((dir / "truth").string());
    ASSERT_TRUE(truth.ok()) << truth.message();
    const TruthFrame& still = stillFrame(*truth);
    Result<BoxFrame> box = renderFrame((dir / "session").string(), still.index, dir);
    ASSERT_TRUE(box.ok()) << box.message();
    Result<TruthScore> score = scoreAgainstTruth(*box, still);
    ASSERT_TRUE(score.ok()) << score.message();
    report("outdoor sun, bracketed and fitted", *score);
    EXPECT_GE(score->shadowEnergyRatio, 0.8);
    EXPECT_LE(score->shadowEnergyRatio, 1.2);
    EXPECT_GE(score->shadowIoU, 0.8);
    ASSERT_EQ(score->objectRatios.size(), 2u);
    for (double r : score->objectRatios) EXPECT_NEAR(r, 1.0, 0.15);
}

}  // namespace
}  // namespace previs
