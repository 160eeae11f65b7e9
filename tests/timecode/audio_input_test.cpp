// Audio inputs (timecode/audio_input.h): LTC written to a WAV or raw file reads back and decodes
// frame-exactly; a missing ALSA device or file is a one-line error naming it. Inside the test VM
// with snd-aloop (ALSA loopback), LTC played into the loopback is captured and decoded live.
#include "timecode/audio_input.h"

#include <alsa/asoundlib.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <random>
#include <thread>

#include "tests/support/temp_dir.h"
#include "tests/timecode/ltc_test_signal.h"

namespace previs {
namespace {

using testing::decodeAll;
using testing::encodeLtc;
using testing::LtcSignal;

// A sound card 80 ppm fast against CLOCK_MONOTONIC, read every 10 ms by a thread that runs up to
// 3 ms late (exponential, mean 0.5 ms): the stamps stay within 0.5 ms (libltc's own precision for
// a frame's start, a sixtieth of a frame) of when each chunk's first sample was really captured;
// the raw measurements are up to 3 ms off.
TEST(ChunkClock, FollowsTheCardThroughSchedulingJitter) {
    ChunkClock clock(48000);
    std::mt19937 random(11);
    std::exponential_distribution<double> lateMs(2.0);
    const double nsPerSample = 1e9 / 48000.0 / (1.0 + 80e-6);
    double worstUs = 0.0;
    for (int chunk = 0; chunk < 6000; ++chunk) {
        const double truthNs = 1e9 + chunk * 480 * nsPerSample;
        const double late = std::min(lateMs(random), 3.0) * 1e6;
        const int64_t stamp = clock.stamp(int64_t(truthNs + late), 480);
        if (chunk > 500) worstUs = std::max(worstUs, std::abs(double(stamp) - truthNs) / 1e3);
    }
    EXPECT_LT(worstUs, 500.0);
    std::printf("chunk clock: worst error %.0f us after settling\n", worstUs);
}

// A chunk measured far early (the card's delay misread: CI's VM once stamped a chunk 10.5 ms
// before its predicted time, before the one before it) follows on from the last chunk; a chunk
// measured far late (a stall) starts the time line over there. The stamps always increase.
TEST(ChunkClock, AChunkMeasuredFarEarlyNeverGoesBeforeTheLastOne) {
    ChunkClock clock(48000);
    const int64_t chunkNs = 10'000'000;
    const int64_t first = clock.stamp(1'000'000'000, 480);
    const int64_t second = clock.stamp(first + chunkNs - 10'500'000, 480);
    EXPECT_EQ(second, first + chunkNs);
    const int64_t third = clock.stamp(second + chunkNs + 50'000'000, 480);
    EXPECT_EQ(third, second + chunkNs + 50'000'000);
    EXPECT_GT(clock.stamp(third - 40'000'000, 480), third);
}

TEST(AudioFile, WavRoundTripDecodes) {
    const TimecodeRate rate = TimecodeRate::fps25();
    const LtcSignal signal = encodeLtc(*Timecode::parse("07:00:00:00", rate), 50);
    const std::string path = (testing::scratchDir("previs_tc") / "ltc.wav").string();
    ASSERT_TRUE(writeWavFile(path, {signal.samples, 48000}));
    const Result<AudioClip> clip = readAudioFile(path);
    ASSERT_TRUE(clip) << clip.message();
    EXPECT_EQ(clip->sampleRate, 48000);
    ASSERT_EQ(clip->samples.size(), signal.samples.size());
    Result<LtcDecoder> decoder = LtcDecoder::create({48000, rate});
    const std::vector<LtcFrame> frames = decodeAll(*decoder, clip->samples);
    // The last frame's end needs an edge after it, which the file does not have.
    ASSERT_GE(frames.size(), 48u);
    EXPECT_EQ(frames.back().timecode.toString(), "07:00:01:23");
}

TEST(AudioFile, StereoWavPicksTheChannelAndRawIsS16) {
    const std::string dir = testing::scratchDir("previs_tc").string();
    // A stereo 16-bit WAV: left 1000, right -2000.
    std::vector<uint8_t> wav = {'R', 'I', 'F',  'F',  44,  0,   0,   0,    'W', 'A', 'V',
                                'E', 'f', 'm',  't',  ' ', 16,  0,   0,    0,   1,   0,
                                2,   0,   0x80, 0xbb, 0,   0,   0,   0xee, 2,   0,   4,
                                0,   16,  0,    'd',  'a', 't', 'a', 8,    0,   0,   0};
    for (int i = 0; i < 2; ++i)
        for (int16_t v : {int16_t(1000), int16_t(-2000)}) {
            wav.push_back(uint8_t(v & 0xff));
            wav.push_back(uint8_t((v >> 8) & 0xff));
        }
    std::ofstream(dir + "/stereo.wav", std::ios::binary)
        .write(reinterpret_cast<const char*>(wav.data()), std::streamsize(wav.size()));
    const Result<AudioClip> right = readAudioFile(dir + "/stereo.wav", 1);
    ASSERT_TRUE(right) << right.message();
    ASSERT_EQ(right->samples.size(), 2u);
    EXPECT_FLOAT_EQ(right->samples[0], -2000.0f / 32768.0f);
    EXPECT_FALSE(readAudioFile(dir + "/stereo.wav", 2)) << "no third channel";

    const int16_t raw[3] = {0, 16384, -32768};
    std::ofstream(dir + "/ltc.raw", std::ios::binary)
        .write(reinterpret_cast<const char*>(raw), sizeof raw);
    const Result<AudioClip> clip = readAudioFile(dir + "/ltc.raw", 0, 44100);
    ASSERT_TRUE(clip);
    EXPECT_EQ(clip->sampleRate, 44100);
    ASSERT_EQ(clip->samples.size(), 3u);
    EXPECT_FLOAT_EQ(clip->samples[1], 0.5f);
    EXPECT_FLOAT_EQ(clip->samples[2], -1.0f);
}

TEST(AudioFile, MissingFileNamesIt) {
    const Result<AudioClip> clip = readAudioFile("/nonexistent/ltc.wav");
    ASSERT_FALSE(clip);
    EXPECT_NE(clip.message().find("/nonexistent/ltc.wav"), std::string::npos);
}

TEST(AlsaCapture, MissingDeviceIsAOneLineErrorNamingIt) {
    const Result<std::unique_ptr<AlsaCapture>> capture =
        AlsaCapture::create({"hw:97,0", 0, 48000, 480}, [](std::span<const float>, int64_t) {});
    ASSERT_FALSE(capture);
    EXPECT_NE(capture.message().find("\"hw:97,0\""), std::string::npos) << capture.message();
    EXPECT_EQ(capture.message().find('\n'), std::string::npos);
}

struct PcmClose {
    void operator()(snd_pcm_t* pcm) const { snd_pcm_close(pcm); }
};

// Plays `samples` (mono, 48 kHz) into an ALSA playback device, blocking until written.
void play(snd_pcm_t* pcm, const std::vector<float>& samples) {
    std::vector<int16_t> s16;
    for (float s : samples) s16.push_back(int16_t(std::lround(std::clamp(s, -1.0f, 1.0f) * 32767)));
    for (size_t at = 0; at < s16.size();) {
        const snd_pcm_sframes_t n = snd_pcm_writei(pcm, s16.data() + at, s16.size() - at);
        if (n < 0) {
            ASSERT_GE(snd_pcm_recover(pcm, int(n), 1), 0) << snd_strerror(int(n));
            continue;
        }
        at += size_t(n);
    }
    snd_pcm_drain(pcm);
}

// Inside the test VM (snd-aloop): LTC played into one end of the ALSA loopback card is captured
// from the other by AlsaCapture on its thread and decoded frame by frame, in order.
TEST(AlsaLoopback, CapturesAndDecodesLtcLive) {
    if (!std::getenv("VMTEST")) GTEST_SKIP() << "needs the test VM's snd-aloop (label vm)";
    snd_pcm_t* raw = nullptr;
    if (snd_pcm_open(&raw, "hw:Loopback,0,0", SND_PCM_STREAM_PLAYBACK, 0) < 0)
        GTEST_SKIP() << "no ALSA loopback card (modprobe snd-aloop)";
    std::unique_ptr<snd_pcm_t, PcmClose> playback(raw);
    ASSERT_EQ(snd_pcm_set_params(raw, SND_PCM_FORMAT_S16_LE, SND_PCM_ACCESS_RW_INTERLEAVED, 1,
                                 48000, 1, 200'000),
              0);

    const TimecodeRate rate = TimecodeRate::fps25();
    Result<LtcDecoder> decoder = LtcDecoder::create({48000, rate});
    ASSERT_TRUE(decoder);
    std::mutex mutex;
    std::vector<LtcFrame> frames;
    std::vector<int64_t> chunkTimes;
    Result<std::unique_ptr<AlsaCapture>> capture = AlsaCapture::create(
        {"hw:Loopback,1,0", 0, 48000, 480}, [&](std::span<const float> samples, int64_t t) {
            std::lock_guard lock(mutex);
            decoder->write(samples, frames);
            chunkTimes.push_back(t);
        });
    ASSERT_TRUE(capture) << capture.message();
    const LtcSignal signal = encodeLtc(*Timecode::parse("01:00:00:00", rate), 100);
    play(playback.get(), signal.samples);
    // The capture side lags by its buffer; give it time to deliver the last periods.
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    const uint64_t overruns = (*capture)->overruns();
    capture->reset();  // stops and joins the capture thread

    std::lock_guard lock(mutex);
    // An emulated VM can miss a period on either end (an underrun or overrun skips a few LTC
    // frames); what comes through is in order and is what was played.
    EXPECT_GE(frames.size(), 80u) << "rejected " << decoder->counters().rejected << ", overruns "
                                  << overruns;
    for (size_t i = 1; i < frames.size(); ++i)
        EXPECT_GT(frames[i].timecode.frameCount(), frames[i - 1].timecode.frameCount());
    if (!frames.empty()) {
        EXPECT_GE(frames.front().timecode.frameCount(), signal.first.frameCount());
        EXPECT_LE(frames.back().timecode.frameCount(), signal.first.frameCount() + 99);
    }
    for (size_t i = 1; i < chunkTimes.size(); ++i) EXPECT_GT(chunkTimes[i], chunkTimes[i - 1]);
}

}  // namespace
}  // namespace previs
