// The per-frame timecode source (timecode/timecode_source.h), driven with explicit timestamps:
// audio chunks stamped as an input would stamp them, camera frames asked after the audio of their
// time has been fed. Locking to LTC, freewheel through a dropout and re-jam, the clock fallback,
// bit errors in the status, and concurrent feeding and asking.
#include "timecode/timecode_source.h"

#include <gtest/gtest.h>

#include <atomic>
#include <thread>

#include "tests/timecode/ltc_test_signal.h"

namespace previs {
namespace {

using testing::encodeLtc;
using testing::LtcSignal;

constexpr int64_t kAudioStartNs = 5'000'000'000;  // CLOCK_MONOTONIC of the first audio sample
constexpr uint64_t kRealtimeNs = 1796391907ull * 1'000'000'000ull;
constexpr size_t kChunk = 480;  // 10 ms

std::unique_ptr<TimecodeSource> makeSource(TimecodeSourceKind kind, TimecodeRate rate,
                                           std::optional<TimecodeRate> ltcRate = std::nullopt) {
    TimecodeSourceConfig config;
    config.kind = kind;
    config.rate.configured = rate;
    config.ltcRate = ltcRate;
    Result<std::unique_ptr<TimecodeSource>> source = TimecodeSource::create(config);
    EXPECT_TRUE(source) << (source ? "" : source.message());
    return std::move(source).value();
}

// Plays `audio` into the source while a camera at `rate` asks for each frame once the audio of
// its time (plus one chunk: the input's latency) has been fed. Camera frames start with the
// audio, offset by `cameraPhaseNs`.
std::vector<FrameTimecode> runTake(TimecodeSource& source, const std::vector<float>& audio,
                                   TimecodeRate rate, int64_t cameraPhaseNs = 0) {
    std::vector<FrameTimecode> result;
    size_t fed = 0;
    const auto fedUntilNs = [&] { return kAudioStartNs + int64_t(fed) * 1'000'000'000 / 48000; };
    for (int64_t frame = 0;; ++frame) {
        const int64_t t =
            kAudioStartNs + cameraPhaseNs + int64_t(double(frame) * 1e9 * rate.den() / rate.num());
        while (fed < audio.size() && fedUntilNs() < t + 10'000'000) {
            const size_t n = std::min(kChunk, audio.size() - fed);
            source.feedAudio(std::span<const float>(audio.data() + fed, n), fedUntilNs());
            fed += n;
        }
        if (fedUntilNs() < t) break;
        result.push_back(source.frameTimecode(t, kRealtimeNs + uint64_t(t)));
    }
    return result;
}

TEST(TimecodeSource, ClockWhenConfiguredSo) {
    setenv("TZ", "UTC", 1);
    tzset();
    auto source = makeSource(TimecodeSourceKind::Clock, TimecodeRate::fps25());
    const FrameTimecode tc = source->frameTimecode(123, kRealtimeNs + 500'000'000);
    EXPECT_EQ(tc.state, TimecodeState::Clock);
    EXPECT_EQ(tc.timecode.toString(), "13:45:07:12");
    const TimecodeStatus status = source->status();
    EXPECT_EQ(status.source, TimecodeSourceKind::Clock);
    EXPECT_STREQ(toString(status.state), "clock");
}

TEST(TimecodeSource, LocksToLtcAndStampsEachFrame) {
    const TimecodeRate rate = TimecodeRate::fps25();
    const LtcSignal signal = encodeLtc(*Timecode::parse("01:00:00:00", rate), 100);
    auto source = makeSource(TimecodeSourceKind::Ltc, rate);
    // A camera 3 ms behind the LTC frame edges (well within half a frame).
    const std::vector<FrameTimecode> frames = runTake(*source, signal.samples, rate, 3'000'000);
    ASSERT_GE(frames.size(), 95u);
    // Until libltc has decoded a frame (the first one ends 40 ms in) the clock stands in.
    EXPECT_EQ(frames[0].state, TimecodeState::Clock);
    size_t locked = 0;
    for (size_t i = 0; i < frames.size(); ++i) {
        if (frames[i].state != TimecodeState::Ltc) continue;
        ++locked;
        EXPECT_EQ(frames[i].timecode.toString(), signal.first.plus(int64_t(i)).toString())
            << "camera frame " << i;
    }
    EXPECT_GE(locked, frames.size() - 4);
    const TimecodeStatus status = source->status();
    EXPECT_EQ(status.state, TimecodeState::Ltc);
    EXPECT_EQ(status.jams, 1u);
    EXPECT_EQ(status.dropouts, 0u);
    EXPECT_GE(status.ltc.decoded, 98u);
    ASSERT_TRUE(status.lastLtc);
    EXPECT_EQ(status.lastLtc->toString(), "01:00:03:23")
        << "the last frame needs the edge after it";
}

TEST(TimecodeSource, FramesAskedLateGetTheLtcOfTheirTime) {
    const TimecodeRate rate = TimecodeRate::fps24();
    const LtcSignal signal = encodeLtc(*Timecode::parse("02:00:00:00", rate), 48);
    auto source = makeSource(TimecodeSourceKind::Ltc, rate, rate);
    source->feedAudio(signal.samples, kAudioStartNs);
    // All the audio is in; a frame from half a second ago still gets its own timecode.
    const int64_t frameNs = rate.frameNs();
    const FrameTimecode tc = source->frameTimecode(kAudioStartNs + 12 * frameNs, kRealtimeNs);
    EXPECT_EQ(tc.state, TimecodeState::Ltc);
    EXPECT_EQ(tc.timecode.toString(), "02:00:00:12");
}

TEST(TimecodeSource, DropoutFreewheelsThenReJams) {
    const TimecodeRate rate = TimecodeRate::fps29_97Df();
    // 2 s of LTC, 1.5 s of silence (the generator unplugged), then LTC again, re-jammed to a new
    // value as after a generator reset.
    LtcSignal before = encodeLtc(*Timecode::parse("00:00:58;00", rate), 60);
    const size_t gapSamples = 72000;
    std::vector<float> audio = before.samples;
    const size_t resumeAt = audio.size() + gapSamples;
    audio.resize(resumeAt, 0.0f);
    const Timecode jam = *Timecode::parse("10:00:00;00", rate);
    const LtcSignal after = encodeLtc(jam, 60);
    audio.insert(audio.end(), after.samples.begin(), after.samples.end());

    auto source = makeSource(TimecodeSourceKind::Ltc, rate);
    const std::vector<FrameTimecode> frames = runTake(*source, audio, rate);
    const double cameraFramesPerSample = rate.fps() / 48000.0;
    const int64_t lastGood = 59;  // camera frame i sits on LTC frame i before the gap
    const int64_t resumeFrame = std::llround(double(resumeAt) * cameraFramesPerSample);

    bool sawFreewheel = false;
    for (size_t i = 0; i < frames.size(); ++i) {
        const FrameTimecode& f = frames[i];
        SCOPED_TRACE(i);
        if (int64_t(i) <= lastGood && f.state == TimecodeState::Ltc) {
            EXPECT_EQ(f.timecode, before.first.plus(int64_t(i)));
        }
        if (f.state == TimecodeState::Freewheel) {
            sawFreewheel = true;
            // Free-running on from the last good frame at its rate, across a dropping minute.
            EXPECT_EQ(f.timecode, before.first.plus(int64_t(i)));
            ASSERT_TRUE(f.freewheelSinceNs);
            // The end of the last frame decoded: frame 58, as the last frame before the silence
            // has no edge after it to end it.
            EXPECT_NEAR(double(*f.freewheelSinceNs), double(kAudioStartNs) + 59 * 1e9 / rate.fps(),
                        1e6);
            EXPECT_LT(int64_t(i), resumeFrame + 4);
        }
        if (int64_t(i) > resumeFrame + 3) {
            EXPECT_EQ(f.state, TimecodeState::Ltc);
            EXPECT_EQ(f.timecode, jam.plus(int64_t(i) - resumeFrame));
        }
    }
    EXPECT_TRUE(sawFreewheel);
    // In the middle of the gap the source is free-running.
    EXPECT_EQ(frames[size_t(lastGood + 20)].state, TimecodeState::Freewheel);
    EXPECT_EQ(frames[size_t(lastGood + 20)].timecode.toString(), "00:01:00;21");
    const TimecodeStatus status = source->status();
    EXPECT_EQ(status.dropouts, 1u);
    EXPECT_EQ(status.jams, 2u) << "the first lock and the re-jam";
    EXPECT_EQ(status.state, TimecodeState::Ltc);
    EXPECT_FALSE(status.freewheelSinceNs);
}

TEST(TimecodeSource, DropoutWithoutAskingIsStillCounted) {
    const TimecodeRate rate = TimecodeRate::fps25();
    LtcSignal signal = encodeLtc(*Timecode::parse("03:00:00:00", rate), 150);
    // Silence over frames 50..99; the generator ran on, so LTC resumes where it would be.
    std::fill(signal.samples.begin() + 50 * 1920, signal.samples.begin() + 100 * 1920, 0.0f);
    auto source = makeSource(TimecodeSourceKind::Ltc, rate);
    source->feedAudio(signal.samples, kAudioStartNs);
    const TimecodeStatus status = source->status();
    EXPECT_EQ(status.dropouts, 1u);
    EXPECT_EQ(status.jams, 2u);
    const FrameTimecode tc =
        source->frameTimecode(kAudioStartNs + 120 * int64_t(40'000'000), kRealtimeNs);
    EXPECT_EQ(tc.state, TimecodeState::Ltc);
    EXPECT_EQ(tc.timecode.toString(), "03:00:04:20");
}

TEST(TimecodeSource, BitErrorsShowInTheStatusNotInTheTimecode) {
    const TimecodeRate rate = TimecodeRate::fps25();
    LtcSignal signal = encodeLtc(*Timecode::parse("04:00:00:00", rate), 100);
    // Half a bit cell inverted in the timecode bits of frames 20, 40, 60 and 80.
    for (int frame : {20, 40, 60, 80})
        for (size_t i = 0; i < 12; ++i) {
            float& s = signal.samples[size_t(frame) * 1920 + 30 * 24 + i];
            s = -s;
        }
    auto source = makeSource(TimecodeSourceKind::Ltc, rate);
    const std::vector<FrameTimecode> frames = runTake(*source, signal.samples, rate, 1'000'000);
    for (size_t i = 0; i < frames.size(); ++i)
        if (frames[i].state != TimecodeState::Clock) {
            EXPECT_EQ(frames[i].timecode, signal.first.plus(int64_t(i))) << i;
        }
    const TimecodeStatus status = source->status();
    EXPECT_GE(status.ltc.rejected + status.ltc.lostFrames, 4u);
    EXPECT_EQ(status.dropouts, 0u) << "a lost frame is not a dropout";
    EXPECT_EQ(status.jams, 1u);
}

TEST(TimecodeSource, GarbageNeverLocks) {
    std::vector<float> tone(48000 * 2);
    for (size_t i = 0; i < tone.size(); ++i)
        tone[i] = 0.5f * float(std::sin(2 * M_PI * 1200.0 * double(i) / 48000.0));
    auto source = makeSource(TimecodeSourceKind::Ltc, TimecodeRate::fps25());
    for (const FrameTimecode& f : runTake(*source, tone, TimecodeRate::fps25()))
        EXPECT_EQ(f.state, TimecodeState::Clock);
    EXPECT_EQ(source->status().jams, 0u);
    EXPECT_FALSE(source->status().lastLtc);
}

TEST(TimecodeSource, WrongRateLtcNeverLocks) {
    // 30 fps LTC on a set whose timecode is 25: the clock stands in and the status says why.
    const LtcSignal thirty = encodeLtc(*Timecode::parse("01:00:00:00", TimecodeRate::fps30()), 60);
    auto source = makeSource(TimecodeSourceKind::Ltc, TimecodeRate::fps25(), TimecodeRate::fps25());
    for (const FrameTimecode& f : runTake(*source, thirty.samples, TimecodeRate::fps25()))
        EXPECT_EQ(f.state, TimecodeState::Clock);
    const TimecodeStatus status = source->status();
    EXPECT_EQ(status.ltc.decoded, 0u);
    EXPECT_GT(status.ltc.rejected, 0u);
    EXPECT_EQ(status.jams, 0u);
}

TEST(TimecodeSource, FeedAndAskFromTwoThreads) {
    const TimecodeRate rate = TimecodeRate::fps30();
    const LtcSignal signal = encodeLtc(*Timecode::parse("06:00:00:00", rate), 300);
    auto source = makeSource(TimecodeSourceKind::Ltc, rate);
    std::atomic<bool> done = false;
    std::thread audio([&] {
        playAudioClip({signal.samples, 48000}, kAudioStartNs, 480, source->audioSink());
        done = true;
    });
    // The asking thread sees only whole states: clock before the lock, then the LTC's values,
    // locked or (for times the audio has not reached yet) free-running on from the last frame,
    // which here is the same value as the signal runs on unbroken.
    int asked = 0;
    while (!done || asked < 100) {
        const int64_t frame = asked % 290;
        const FrameTimecode f =
            source->frameTimecode(kAudioStartNs + frame * rate.frameNs(), kRealtimeNs);
        if (f.state != TimecodeState::Clock) {
            EXPECT_EQ(f.timecode, signal.first.plus(frame));
        }
        ++asked;
    }
    audio.join();
    EXPECT_GE(source->status().ltc.decoded, 299u);
}

TEST(TimecodeSource, ConfigWords) {
    EXPECT_EQ(*parseTimecodeSourceKind("ltc"), TimecodeSourceKind::Ltc);
    EXPECT_EQ(*parseTimecodeSourceKind("clock"), TimecodeSourceKind::Clock);
    EXPECT_FALSE(parseTimecodeSourceKind("genlock"));
    EXPECT_STREQ(toString(TimecodeState::Freewheel), "freewheel");
}

}  // namespace
}  // namespace previs
