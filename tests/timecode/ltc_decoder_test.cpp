// LTC decoding (timecode/ltc_decoder.h) of audio libltc's own encoder wrote: every frame comes
// back with its value and the sample it started at, at 24, 25, 29.97 drop-frame and 30 fps and
// other sample rates; bit errors, noise and clipping never deliver a wrong timecode and are
// counted; a wrong rate or garbage never locks.
#include "timecode/ltc_decoder.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <random>

#include "tests/timecode/ltc_test_signal.h"

namespace previs {
namespace {

using testing::decodeAll;
using testing::encodeLtc;
using testing::LtcSignal;

LtcDecoder makeDecoder(int sampleRate, std::optional<TimecodeRate> rate) {
    Result<LtcDecoder> decoder = LtcDecoder::create({sampleRate, rate});
    EXPECT_TRUE(decoder) << (decoder ? "" : decoder.message());
    return std::move(decoder).value();
}

// Every delivered frame carries the value written at its position; returns how many came back.
size_t checkDelivered(const LtcSignal& signal, const std::vector<LtcFrame>& frames) {
    for (const LtcFrame& frame : frames) {
        const Timecode expected = signal.expectedAt(frame.startSample);
        EXPECT_EQ(frame.timecode.toString(), expected.toString())
            << "at sample " << frame.startSample;
        EXPECT_EQ(frame.timecode.rate(), signal.first.rate());
        // libltc places the start within a few samples of where the encoder began the frame (more
        // for the first frame, before it has measured the bit rate, or when the first bit is
        // damaged): 0.5 ms, a sixtieth of a frame, is what matching camera frames needs.
        const double exactStart =
            double(signal.indexAt(frame.startSample)) * signal.samplesPerFrame();
        EXPECT_NEAR(double(frame.startSample), exactStart, signal.sampleRate / 2000.0)
            << expected.toString();
    }
    return frames.size();
}

struct RateCase {
    TimecodeRate rate;
    const char* first;
    bool configured;  // 23.976 and 29.97 non-drop are not told apart from the signal
};

class LtcRoundTrip : public ::testing::TestWithParam<RateCase> {};

TEST_P(LtcRoundTrip, DecodesEveryFrameExactly) {
    const RateCase c = GetParam();
    for (int sampleRate : {48000, 44100, 96000}) {
        SCOPED_TRACE(sampleRate);
        const Timecode first = *Timecode::parse(c.first, c.rate);
        const int frames = 3 * c.rate.nominal();
        const LtcSignal signal = encodeLtc(first, frames, sampleRate);
        LtcDecoder decoder =
            makeDecoder(sampleRate, c.configured ? std::optional(c.rate) : std::nullopt);
        const std::vector<LtcFrame> decoded = decodeAll(decoder, signal.samples);
        checkDelivered(signal, decoded);
        // libltc needs the first frame to find the bit rate, and the last one's end needs the
        // edge after it: every frame between comes back.
        ASSERT_GE(decoded.size(), size_t(frames - 2));
        EXPECT_EQ(decoded.back().timecode, first.plus(frames - 2));
        for (size_t i = 1; i < decoded.size(); ++i)
            EXPECT_EQ(decoded[i].timecode, decoded[i - 1].timecode.next());
        EXPECT_EQ(decoder.counters().rejected, 0u);
        EXPECT_EQ(decoder.counters().lostFrames, 0u);
    }
}

INSTANTIATE_TEST_SUITE_P(
    Rates, LtcRoundTrip,
    ::testing::Values(RateCase{TimecodeRate::fps25(), "10:00:00:00", false},
                      RateCase{TimecodeRate::fps24(), "01:59:59:00", false},
                      // Across a dropping minute and a tenth minute that keeps its labels.
                      RateCase{TimecodeRate::fps29_97Df(), "00:00:58;00", false},
                      RateCase{TimecodeRate::fps29_97Df(), "00:09:58;00", true},
                      RateCase{TimecodeRate::fps30(), "23:59:58:00", false},
                      RateCase{TimecodeRate::fps29_97(), "12:00:00:00", true},
                      RateCase{TimecodeRate::fps23_976(), "12:00:00:00", true}),
    [](const ::testing::TestParamInfo<RateCase>& param) {
        std::string name = param.param.rate.toString() + (param.param.configured ? "Set" : "Auto");
        for (char& ch : name)
            if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
        return name + std::to_string(param.index);
    });

TEST(LtcDecoder, SixteenBitInputAndDropFrameBit) {
    const TimecodeRate df = TimecodeRate::fps29_97Df();
    const LtcSignal signal = encodeLtc(*Timecode::parse("01:00:59;20", df), 40);
    std::vector<int16_t> s16;
    for (float s : signal.samples) s16.push_back(int16_t(std::lround(s * 32000.0f)));
    LtcDecoder decoder = makeDecoder(48000, std::nullopt);
    std::vector<LtcFrame> frames;
    decoder.write(std::span<const int16_t>(s16), frames);
    ASSERT_GE(frames.size(), 39u);
    checkDelivered(signal, frames);
    EXPECT_TRUE(frames.back().timecode.dropFrame()) << "from the LTC frame's drop-frame bit";
    EXPECT_EQ(frames.back().timecode.toString(), "01:01:01;00");
}

// Inverts the signal for `length` samples from `at`: a bit cell read the wrong way.
void invert(std::vector<float>& samples, size_t at, size_t length) {
    for (size_t i = at; i < std::min(at + length, samples.size()); ++i) samples[i] = -samples[i];
}

TEST(LtcDecoder, BitErrorsAreCountedAndNeverDelivered) {
    const TimecodeRate rate = TimecodeRate::fps25();
    LtcSignal signal = encodeLtc(*Timecode::parse("10:00:00:00", rate), 250);
    const double spf = signal.samplesPerFrame();
    const size_t bit = size_t(spf / 80);
    // Every seventh frame gets one half-bit flipped somewhere in its timecode bits.
    std::mt19937 random(39);
    int damaged = 0;
    for (int frame = 5; frame < 245; frame += 7, ++damaged) {
        const size_t bitIndex = random() % 60;
        invert(signal.samples, size_t(frame * spf) + bitIndex * bit + bit / 4, bit / 2);
    }
    LtcDecoder decoder = makeDecoder(48000, rate);
    const size_t delivered = checkDelivered(signal, decodeAll(decoder, signal.samples));
    const LtcCounters& c = decoder.counters();
    EXPECT_GE(c.rejected + c.lostFrames, uint64_t(damaged)) << "each damaged frame is dropped";
    EXPECT_LE(delivered, size_t(250 - damaged));
    EXPECT_GE(delivered, size_t(250 - 3 * damaged)) << "a damaged frame costs few good ones";
    EXPECT_EQ(c.decoded, delivered);
}

TEST(LtcDecoder, RandomCorruptionNeverDeliversAWrongTimecode) {
    const TimecodeRate rate = TimecodeRate::fps29_97Df();
    LtcSignal signal = encodeLtc(*Timecode::parse("00:59:00;02", rate), 2000);
    const double spf = signal.samplesPerFrame();
    std::mt19937 random(1239);
    // Inversions of random lengths (a sample to two bits) anywhere, several per frame in places.
    for (int i = 0; i < 1500; ++i) {
        const size_t at = random() % signal.samples.size();
        invert(signal.samples, at, 1 + random() % size_t(spf / 40));
    }
    LtcDecoder decoder = makeDecoder(48000, std::nullopt);
    const size_t delivered = checkDelivered(signal, decodeAll(decoder, signal.samples));
    EXPECT_GT(decoder.counters().rejected + decoder.counters().lostFrames, 300u);
    EXPECT_GT(delivered, 500u) << "the undamaged frames still come through";
}

TEST(LtcDecoder, NoiseAndClippingDoNotDeliverWrongValues) {
    const TimecodeRate rate = TimecodeRate::fps24();
    // Clipped hard (a square wave): LTC survives it whole.
    LtcSignal clipped = encodeLtc(*Timecode::parse("05:00:00:00", rate), 96, 48000, -20.0);
    for (float& s : clipped.samples) s = std::clamp(s * 40.0f, -0.5f, 0.5f);
    LtcDecoder a = makeDecoder(48000, rate);
    EXPECT_GE(checkDelivered(clipped, decodeAll(a, clipped.samples)), 95u);

    // Noise from mild to heavy: whatever comes out is right at every level, and where frames
    // are damaged the damage is counted. -3 dBFS LTC is ±0.7; noise σ 0.2 .. 0.6.
    uint64_t damageCounted = 0;
    for (float sigma : {0.05f, 0.1f, 0.15f, 0.2f, 0.3f, 0.4f}) {
        LtcSignal noisy = encodeLtc(*Timecode::parse("05:00:00:00", rate), 480);
        std::mt19937 random(7);
        std::normal_distribution<float> noise(0.0f, sigma);
        for (float& s : noisy.samples) s += noise(random);
        LtcDecoder b = makeDecoder(48000, rate);
        const size_t delivered = checkDelivered(noisy, decodeAll(b, noisy.samples));
        const LtcCounters& c = b.counters();
        std::printf(
            "noise σ %.2f: %zu of 480 frames delivered, %llu rejected (%llu parity), "
            "%llu lost\n",
            double(sigma), delivered, (unsigned long long)c.rejected,
            (unsigned long long)c.parityErrors, (unsigned long long)c.lostFrames);
        damageCounted += c.rejected + c.lostFrames;
    }
    EXPECT_GT(damageCounted, 0u);
}

TEST(LtcDecoder, WrongRateNeverLocks) {
    // 30 fps LTC into a decoder told 25: the bit rate is 20 % off.
    const LtcSignal thirty = encodeLtc(*Timecode::parse("01:00:00:00", TimecodeRate::fps30()), 90);
    LtcDecoder pal = makeDecoder(48000, TimecodeRate::fps25());
    EXPECT_TRUE(decodeAll(pal, thirty.samples).empty());
    EXPECT_GT(pal.counters().rejected, 0u);

    // 24 fps into 25: 4 %, still told apart.
    const LtcSignal film = encodeLtc(*Timecode::parse("01:00:00:00", TimecodeRate::fps24()), 72);
    LtcDecoder pal2 = makeDecoder(48000, TimecodeRate::fps25());
    EXPECT_TRUE(decodeAll(pal2, film.samples).empty());
    EXPECT_GT(pal2.counters().wrongRate, 0u);

    // Drop-frame LTC into a decoder told 29.97 non-drop: the drop-frame bit disagrees.
    const LtcSignal df = encodeLtc(*Timecode::parse("01:00:00;00", TimecodeRate::fps29_97Df()), 90);
    LtcDecoder ndf = makeDecoder(48000, TimecodeRate::fps29_97());
    EXPECT_TRUE(decodeAll(ndf, df.samples).empty());
    EXPECT_GT(ndf.counters().wrongRate, 0u);
}

TEST(LtcDecoder, GarbageNeverLocks) {
    std::mt19937 random(5);
    std::uniform_real_distribution<float> uniform(-1.0f, 1.0f);
    std::vector<float> noise(48000 * 3);
    for (float& s : noise) s = uniform(random);
    std::vector<float> tone(48000 * 3);
    for (size_t i = 0; i < tone.size(); ++i)
        tone[i] = 0.7f * float(std::sin(2 * M_PI * 1000.0 * double(i) / 48000.0));
    std::vector<float> silence(48000 * 3, 0.0f);
    for (const std::vector<float>* input : {&noise, &tone, &silence}) {
        LtcDecoder decoder = makeDecoder(48000, std::nullopt);
        EXPECT_TRUE(decodeAll(decoder, *input).empty());
        EXPECT_EQ(decoder.counters().decoded, 0u);
    }
}

TEST(LtcDecoder, RejectsImpossibleSettings) {
    EXPECT_FALSE(LtcDecoder::create({48000, TimecodeRate::fps50()}));
    EXPECT_FALSE(LtcDecoder::create({100, std::nullopt}));
}

}  // namespace
}  // namespace previs
