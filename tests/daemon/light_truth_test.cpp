// Light that matches the set (issue 51), checked against ground truth: the bundled demo's
// refined still frame, rendered by the real `previs render-session` from the take's own plate,
// tracked pose and fisheye brackets, against the truth the generator rendered at the frame's
// true pose with the true lighting (examples/demo/truth/, bench/light_truth.h): the virtual
// balls' shadows take as much light from the real table as they would on the set, in the same
// place, and the balls are as bright as the truth.

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "bench/light_truth.h"
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
Result<BoxFrame> renderFrame(const std::string& take, int frame, const fs::path& dir) {
    const fs::path out = dir / "render";
    const std::vector<std::string> argv{
        PREVIS_BINARY, "render-session", take, "--out", out.string(), "--frames",
        fmt::format("{}:{}", frame, frame + 1), "--spp", "64", "--width", "320", "--height",
        "180", "--aov", "mixed,real,mask", "--quiet"};
    if (int rc = testing::runProcess(argv, (dir / "render.log").string(), 600s); rc != 0)
        return makeError("render-session exited {}: {}", rc, fileText(dir / "render.log"));
    return loadBoxFrame((out / fmt::format("frame_{:06d}.exr", frame)).string());
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
    const auto still = std::find_if(truth->begin(), truth->end(),
                                    [](const TruthFrame& f) { return f.still; });
    ASSERT_NE(still, truth->end()) << "truth.toml has no still frame";
    const fs::path dir = testing::scratchDir("previs_light_truth") / "demo";
    Result<BoxFrame> box = renderFrame(kDemoTake, still->index, dir);
    ASSERT_TRUE(box.ok()) << box.message();
    Result<TruthScore> score = scoreAgainstTruth(*box, *still);
    ASSERT_TRUE(score.ok()) << score.message();
    report("demo, bracketed fisheye", *score);
    // The targets.
    EXPECT_GE(score->shadowEnergyRatio, 0.9);
    EXPECT_LE(score->shadowEnergyRatio, 1.1);
    EXPECT_GE(score->shadowIoU, 0.9);
    ASSERT_EQ(score->objectRatios.size(), 2u) << "the red and the chrome ball";
    for (double r : score->objectRatios) EXPECT_NEAR(r, 1.0, 0.10);
}

}  // namespace
}  // namespace previs
