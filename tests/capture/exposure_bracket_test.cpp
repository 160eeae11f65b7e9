// Live exposure bracketing's logic (capture/exposure_bracket.h) on the host: the control values
// of each stop, which V4L2 frames are withheld and which labelled, and — against a simulated
// sensor whose control lands late — that what the cycle delivers merges when it waits long
// enough and is dropped by the bracket assembler (vision/hdr_bracket.h) when it does not.

#include "capture/exposure_bracket.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/core.hpp>

#include "vision/hdr_bracket.h"

namespace previs {
namespace {

bool contains(const std::string& s, const std::string& part) {
    return s.find(part) != std::string::npos;
}

TEST(PlanExposureSteps, ScalesTheBaseByEachStopOnTheControlsGrid) {
    // UVC's exposure_time_absolute: 100 µs units, [1, 5000].
    Result<std::vector<int64_t>> v =
        planExposureSteps({0.0f, -4.0f, -8.0f}, 1000, {1, 5000, 1}, "/dev/video1", "Exposure");
    ASSERT_TRUE(v) << v.message();
    // 62.5 → 63 (−3.99 stops), 3.9 → 4 (−7.97 stops): within kMaxStepErrorStops.
    EXPECT_EQ(*v, (std::vector<int64_t>{1000, 63, 4}));
    // A grid from the minimum: 1, 3, 5, ...
    v = planExposureSteps({0.0f, -2.0f}, 401, {1, 5001, 2}, "/dev/video1", "Exposure");
    ASSERT_TRUE(v) << v.message();
    EXPECT_EQ(*v, (std::vector<int64_t>{401, 101}));
}

TEST(PlanExposureSteps, RefusesAStopTheControlCannotReachNamingDeviceAndRange) {
    // 333 × 2^-8 = 1.3, and the nearest value, 1, is 8.38 stops down: refused, not mislabelled.
    Result<std::vector<int64_t>> v = planExposureSteps({0.0f, -4.0f, -8.0f}, 333, {1, 5000, 1},
                                                       "/dev/video1", "Exposure Time, Absolute");
    ASSERT_FALSE(v);
    EXPECT_TRUE(contains(v.message(), "/dev/video1")) << v.message();
    EXPECT_TRUE(contains(v.message(), "Exposure Time, Absolute")) << v.message();
    EXPECT_TRUE(contains(v.message(), "1 to 5000")) << v.message();
    EXPECT_TRUE(contains(v.message(), "-8.38")) << v.message();
    // Above the range: clamped to 2000, a stop short of +2.
    v = planExposureSteps({0.0f, 2.0f}, 1000, {1, 2000, 1}, "/dev/video1", "Exposure");
    ASSERT_FALSE(v);
    EXPECT_TRUE(contains(v.message(), "1 to 2000")) << v.message();
    // No base exposure to scale.
    EXPECT_FALSE(planExposureSteps({0.0f, -4.0f}, 0, {0, 2000, 1}, "/dev/video1", "Exposure"));
}

// Feeds frames with consecutive driver sequence numbers, each taken well after the control was
// set; returns per frame the label (−1 when withheld) and the step set after it (−1: none).
struct Step {
    int label = -1;
    int set = -1;
};
std::vector<Step> run(ExposureCycle& cycle, uint32_t firstSeq, int frames, uint64_t& nowNs) {
    std::vector<Step> out;
    for (int i = 0; i < frames; ++i) {
        nowNs += 33'000'000;
        const ExposureCycle::Decision d = cycle.onFrame(firstSeq + uint32_t(i), nowNs - 1, nowNs);
        out.push_back({d.label ? int(*d.label) : -1, d.set ? int(*d.set) : -1});
    }
    return out;
}

TEST(ExposureCycle, HoldsEachStepAndLabelsOnlyItsLastFrame) {
    ExposureCycle cycle(3, 3);
    uint64_t now = 1'000'000'000;
    EXPECT_EQ(cycle.start(now), 0u);
    const std::vector<Step> s = run(cycle, 0, 12, now);
    const int labels[12] = {-1, -1, 0, -1, -1, 1, -1, -1, 2, -1, -1, 0};
    const int sets[12] = {-1, -1, 1, -1, -1, 2, -1, -1, 0, -1, -1, 1};
    for (int i = 0; i < 12; ++i) {
        EXPECT_EQ(s[i].label, labels[i]) << "frame " << i;
        EXPECT_EQ(s[i].set, sets[i]) << "frame " << i;
    }
    EXPECT_EQ(cycle.settleFrames(), 8u);
    EXPECT_EQ(cycle.restarts(), 0u);
}

TEST(ExposureCycle, OneFramePerStepLabelsEveryFrame) {
    ExposureCycle cycle(2, 1);
    uint64_t now = 1'000'000'000;
    cycle.start(now);
    // The driver's count need not start at 0 (a device opened before).
    const std::vector<Step> s = run(cycle, 500, 4, now);
    for (int i = 0; i < 4; ++i) {
        EXPECT_EQ(s[i].label, i % 2);
        EXPECT_EQ(s[i].set, (i + 1) % 2);
    }
}

TEST(ExposureCycle, ADroppedFrameRestartsTheCycleAtTheFirstStep) {
    ExposureCycle cycle(3, 2);
    uint64_t now = 1'000'000'000;
    cycle.start(now);
    std::vector<Step> s = run(cycle, 0, 4, now);  // labels step 0 at 1, step 1 at 3
    EXPECT_EQ(s[1].label, 0);
    EXPECT_EQ(s[3].label, 1);
    EXPECT_EQ(s[3].set, 2);
    // Frame 4 is lost by the driver: frame 5 cannot be counted into step 2.
    s = run(cycle, 5, 3, now);
    EXPECT_EQ(s[0].label, -1);
    EXPECT_EQ(s[0].set, 0);
    EXPECT_EQ(s[1].label, -1);
    EXPECT_EQ(s[2].label, 0);  // frame 7: two frames after step 0 was set again
    EXPECT_EQ(cycle.restarts(), 1u);
}

TEST(ExposureCycle, AFrameTakenBeforeItsControlWasSetExtendsTheStep) {
    ExposureCycle cycle(2, 2);
    cycle.start(1000);
    EXPECT_FALSE(cycle.onFrame(0, 1500, 1600).label);
    const ExposureCycle::Decision first = cycle.onFrame(1, 2000, 2100);
    ASSERT_TRUE(first.label);
    ASSERT_TRUE(first.set);  // step 1 set at 2100
    EXPECT_FALSE(cycle.onFrame(2, 2050, 2200).label);
    // At the label's place but exposed (stamped) before 2100: the capture thread is behind.
    EXPECT_FALSE(cycle.onFrame(3, 2090, 2300).label);
    EXPECT_EQ(cycle.extended(), 1u);
    EXPECT_FALSE(cycle.onFrame(4, 2400, 2500).label);
    const ExposureCycle::Decision late = cycle.onFrame(5, 2600, 2700);
    ASSERT_TRUE(late.label);
    EXPECT_EQ(*late.label, 1u);
    // A timestamp not on CLOCK_MONOTONIC (0) is not compared.
    EXPECT_FALSE(cycle.onFrame(6, 0, 2800).label);
    EXPECT_TRUE(cycle.onFrame(7, 0, 2900).label);
}

TEST(ExposureStopsFromMetadata, LabelsWhatTheSensorReported) {
    const std::vector<float> stops = {0.0f, -4.0f, -8.0f};
    // Base 10 ms at gain 2.
    EXPECT_EQ(exposureStopsFromMetadata(stops, 10000.0, 2.0, 10000.0, 2.0), 0.0f);
    EXPECT_EQ(exposureStopsFromMetadata(stops, 625.0, 2.0, 10000.0, 2.0), -4.0f);
    // The sensor's line time rounds 39.06 µs to 40: 7.97 stops, labelled −8.
    EXPECT_EQ(exposureStopsFromMetadata(stops, 40.0, 2.0, 10000.0, 2.0), -8.0f);
    // Exposure and gain both count: half the time at twice the gain is the base's light.
    EXPECT_EQ(exposureStopsFromMetadata(stops, 5000.0, 4.0, 10000.0, 2.0), 0.0f);
    // A control that has not landed yet: its real exposure, not a configured one.
    const std::optional<float> other = exposureStopsFromMetadata(stops, 2500.0, 2.0, 10000.0, 2.0);
    ASSERT_TRUE(other);
    EXPECT_FLOAT_EQ(*other, -2.0f);
    // Not reported: never labelled.
    EXPECT_FALSE(exposureStopsFromMetadata(stops, std::nullopt, 2.0, 10000.0, 2.0));
    EXPECT_FALSE(exposureStopsFromMetadata(stops, 10000.0, std::nullopt, 10000.0, 2.0));
    EXPECT_FALSE(exposureStopsFromMetadata(stops, 0.0, 2.0, 10000.0, 2.0));
}

// A sensor whose exposure control lands `latency` frames after the frame it was set behind
// (0: on the very next frame), seeing a grey scene whose radiance runs over 14 stops, encoded
// through sRGB to 8 bits (the radiometry below inverts it).
class LateSensor {
public:
    LateSensor(std::vector<float> stopsOfSteps, int latency)
        : stops_(std::move(stopsOfSteps)), latency_(latency) {}

    // The frame `sequence` at the exposure in effect then.
    cv::Mat frame(uint32_t sequence) const {
        float stop = stops_[0];
        for (const auto& [afterSeq, step] : sets_)
            if (sequence > afterSeq + uint32_t(latency_)) stop = stops_[step];
        cv::Mat m(16, 96, CV_8UC3);
        for (int x = 0; x < m.cols; ++x) {
            const double radiance = std::exp2(-10.0 + 14.0 * x / (m.cols - 1));
            const double v = std::min(1.0, radiance * std::exp2(stop));
            const double encoded =
                v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
            const uint8_t code = uint8_t(std::lround(255.0 * encoded));
            for (int y = 0; y < m.rows; ++y) m.at<cv::Vec3b>(y, x) = {code, code, code};
        }
        return m;
    }
    // The control of `step` was set right after frame `sequence` was dequeued.
    void set(uint32_t sequence, size_t step) { sets_.emplace_back(sequence, step); }

private:
    std::vector<float> stops_;
    int latency_;
    std::vector<std::pair<uint32_t, size_t>> sets_;
};

// Streams `frames` sensor frames through the cycle into the assembler, as V4L2Device and the
// capture thread do: withheld frames never reach it, delivered ones are numbered consecutively.
BracketCounts stream(int latency, int framesPerStep, int frames) {
    const std::vector<float> stops = {0.0f, -4.0f, -8.0f};
    LateSensor sensor(stops, latency);
    ExposureCycle cycle(stops.size(), framesPerStep);
    BracketSettings settings;
    settings.stops = stops;
    Result<BracketAssembler> assembler = BracketAssembler::create(settings, {});
    EXPECT_TRUE(assembler);
    uint64_t now = 1'000'000'000;
    cycle.start(now);
    uint64_t delivered = 0;
    for (uint32_t seq = 0; seq < uint32_t(frames); ++seq) {
        now += 33'000'000;
        const ExposureCycle::Decision d = cycle.onFrame(seq, now - 1, now);
        const cv::Mat picture = sensor.frame(seq);  // taken before the new control is set
        if (d.set) sensor.set(seq, *d.set);
        if (!d.label) continue;
        std::optional<MergedBracket> merged =
            assembler->add(picture, delivered++, now, stops[*d.label]);
        if (merged) {
            // The scene's radiance at a column every exposure sees below clipping.
            const int x = 40;
            const double truth = std::exp2(-10.0 + 14.0 * x / 95.0);
            EXPECT_NEAR(merged->radiance.at<cv::Vec3f>(8, x)[1], truth, 0.05 * truth);
        }
    }
    return assembler->counts();
}

TEST(ExposureCycle, BracketsMergeWhenEachStepOutlastsTheControlsLatency) {
    // Lands two frames late; held three frames: every label is right.
    const BracketCounts c = stream(2, 3, 3 * 3 * 6);
    EXPECT_EQ(c.merged, 6u);
    EXPECT_EQ(c.dropped(), 0u);
    EXPECT_EQ(c.unchecked, 0u);  // every pair was checked on its pictures
}

TEST(ExposureCycle, BracketsLabelledBeforeTheControlLandedAreDroppedNotMerged) {
    // Lands two frames late; held two: each labelled frame still shows the previous exposure.
    const BracketCounts c = stream(2, 2, 2 * 3 * 6);
    EXPECT_EQ(c.merged, 0u);
    EXPECT_GE(c.droppedMismatch, 5u);
}

}  // namespace
}  // namespace previs
