// The measured camera rate (timecode/frame_rate.h, issue 54): a 15 fps camera whose config names
// no fps is sent and labelled as 15 fps, not the box's old fallback of 30, whatever frames its
// consumer skipped, and a replay that loops does not disturb it.
#include "timecode/frame_rate.h"

#include <gtest/gtest.h>

#include "timecode/timecode.h"
#include "timecode/timecode_source.h"

namespace previs {
namespace {

constexpr int64_t k15FpsNs = 66'666'667;

TEST(FrameRate, SnapsToTheStandardRateNearby) {
    EXPECT_EQ(snapFrameRate(15.02), (FrameRate{15, 1}));
    EXPECT_EQ(snapFrameRate(29.97), (FrameRate{30000, 1001}));
    EXPECT_EQ(snapFrameRate(23.98), (FrameRate{24000, 1001}));
    EXPECT_EQ(snapFrameRate(24.0), (FrameRate{24, 1}));
    EXPECT_EQ(snapFrameRate(12.5), (FrameRate{25, 2}));
    EXPECT_EQ(snapFrameRate(17.3), (FrameRate{17300, 1000})) << "no standard rate near";
}

TEST(FrameRate, MeasuresTheMedianIntervalPerFrameRobustly) {
    FrameRateMeter meter;
    EXPECT_FALSE(meter.rate());
    const int64_t start = 1'000'000'000'000;
    uint64_t sequence = 0;
    meter.add(start, sequence);
    EXPECT_FALSE(meter.rate()) << "one frame has no interval";
    uint32_t noise = 12345;
    for (int i = 1; i < 40; ++i) {
        // Timestamps within ±0.5 ms of the frame's instant, every third frame skipped by the
        // consumer, and one frame stamped 30 ms late.
        sequence += i % 3 == 0 ? 2 : 1;
        noise = noise * 1103515245u + 12345u;
        const int64_t jitter = int64_t(noise % 1'000'001) - 500'000;
        const int64_t t =
            start + int64_t(sequence) * k15FpsNs + jitter + (i == 17 ? 30'000'000 : 0);
        meter.add(t, sequence);
        meter.add(t, sequence);  // a second caller asking for the same frame
    }
    ASSERT_TRUE(meter.rate());
    EXPECT_EQ(*meter.rate(), (FrameRate{15, 1}));
    // The replay loops: its timestamps start over while the count goes on.
    meter.add(1'000'000'000'000, sequence + 1);
    for (int i = 0; i < 5; ++i) meter.add(1'000'000'000'000 + (i + 1) * k15FpsNs, sequence + 2 + i);
    EXPECT_EQ(*meter.rate(), (FrameRate{15, 1}));
}

TEST(FrameRate, ASlowCameraIsLabelledAtTheTimecodeRateItDivides) {
    EXPECT_EQ(TimecodeRate::fromFps(15.0), TimecodeRate::fps30()) << "not the nearest, 23.976";
    EXPECT_EQ(TimecodeRate::fromFps(12.5), TimecodeRate::fps25());
    EXPECT_EQ(TimecodeRate::fromFps(15000.0 / 1001), TimecodeRate::fps29_97());
    EXPECT_EQ(TimecodeRate::fromFps(24.0), TimecodeRate::fps24());
    EXPECT_EQ(TimecodeRate::fromFps(25.0), TimecodeRate::fps25());
    EXPECT_EQ(TimecodeRate::fps29_97Df().name(), "29.97df");
    EXPECT_EQ(TimecodeRate::fps23_976().name(), "23.976");
    for (const char* name : {"23.976", "24", "25", "29.97", "29.97df", "30", "50", "59.94df", "60"})
        EXPECT_EQ(TimecodeRate::parse(name)->name(), name);
}

// The one rule for the rate a take's labels count at (issue 54): the recorded rate, else the
// box's: [timecode] rate, else the camera's fps, else 30; drop-frame from the label.
TEST(FrameRate, ALabelCountsAtTheRateTheTakeRecorded) {
    EXPECT_EQ(labelRate("10:00:00:28", "30", {std::nullopt, 0.0}), TimecodeRate::fps30());
    EXPECT_EQ(labelRate("10:00:00:20", "25", {TimecodeRate::fps24(), 15.0}), TimecodeRate::fps25());
    EXPECT_EQ(labelRate("10:00:00:28", "", {std::nullopt, 0.0}), TimecodeRate::fps30())
        << "an older take without the column, camera fps not configured";
    EXPECT_EQ(labelRate("10:00:00:28", "", {std::nullopt, 15.0}), TimecodeRate::fps30());
    EXPECT_EQ(labelRate("10:00:00:20", "", {TimecodeRate::fps25(), 0.0}), TimecodeRate::fps25());
    EXPECT_EQ(labelRate("10:00:00;28", "", {std::nullopt, 30000.0 / 1001}),
              TimecodeRate::fps29_97Df());
    EXPECT_EQ(labelRate("10:00:00:10", "12", {std::nullopt, 0.0}), TimecodeRate::fps30())
        << "a name this previs does not know: the fallback";
}

// The rule the source, the recorder and the export share (issue 55): [timecode] rate, else the
// camera's fps, else the measured fps, else 30; each fps through fromFps.
TEST(FrameRate, ALabelRateRuleTakesTheConfigThenTheCameraThenTheMeasuredRate) {
    const LabelRateRule configured{TimecodeRate::fps25(), 30.0};
    EXPECT_EQ(configured.fromConfig(), TimecodeRate::fps25());
    EXPECT_EQ(configured.rate(15.0), TimecodeRate::fps25()) << "the config, not the camera";
    const LabelRateRule camera{std::nullopt, 15.0};
    EXPECT_EQ(camera.fromConfig(), TimecodeRate::fps30()) << "15 fps counts at 30";
    EXPECT_EQ(camera.rate(25.0), TimecodeRate::fps30());
    const LabelRateRule measured{std::nullopt, 0.0};
    EXPECT_EQ(measured.fromConfig(), std::nullopt);
    EXPECT_EQ(measured.rate(25.0), TimecodeRate::fps25());
    EXPECT_EQ(measured.rate(12.5), TimecodeRate::fps25());
    EXPECT_EQ(measured.rate(), TimecodeRate::fps30()) << "nothing measured yet";
    EXPECT_EQ(measured.rate(0.0), TimecodeRate::fps30());
}

TEST(FrameRate, TheClockSourceWithoutARateMeasuresTheCamera) {
    TimecodeSourceConfig config;
    config.rate = {};  // no [timecode] rate, no camera fps
    Result<std::unique_ptr<TimecodeSource>> source = TimecodeSource::create(config);
    ASSERT_TRUE(source) << source.message();
    int64_t t = 2'000'000'000;
    for (uint64_t sequence = 0; sequence < 10; ++sequence, t += 40'000'000)
        (*source)->frameTimecode(t, 1'700'000'000'000'000'000ull + uint64_t(t), sequence);
    const FrameTimecode tc =
        (*source)->frameTimecode(t, 1'700'000'000'000'000'000ull + uint64_t(t), 10);
    EXPECT_EQ(tc.timecode.rate(), TimecodeRate::fps25()) << "a 25 fps camera, not the old 30";
    EXPECT_EQ((*source)->status().rate, TimecodeRate::fps25());
}

}  // namespace
}  // namespace previs
