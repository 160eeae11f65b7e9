#pragma once

// LTC test audio from libltc's own encoder (timecode/ltc_encoder.h), and what a decoded frame
// must say given where it sits in that audio.

#include <gtest/gtest.h>

#include <cmath>
#include <ostream>
#include <vector>

#include "timecode/ltc_decoder.h"
#include "timecode/ltc_encoder.h"

namespace previs {

// gtest prints a Timecode as its label and rate.
inline void PrintTo(const Timecode& tc, std::ostream* os) {
    *os << tc.toString() << " at " << tc.rate().toString();
}

}  // namespace previs

namespace previs::testing {

struct LtcSignal {
    std::vector<float> samples;
    Timecode first;
    int sampleRate = 48000;

    double samplesPerFrame() const {
        return double(sampleRate) * first.rate().den() / first.rate().num();
    }
    // Index of the frame the encoder began nearest `startSample`.
    int64_t indexAt(int64_t startSample) const {
        return std::llround(double(startSample) / samplesPerFrame());
    }
    // The timecode the encoder wrote at the frame starting near `startSample`.
    Timecode expectedAt(int64_t startSample) const { return first.plus(indexAt(startSample)); }
};

inline LtcSignal encodeLtc(const Timecode& first, int frames, int sampleRate = 48000,
                           double volumeDbfs = -3.0) {
    Result<LtcEncoder> encoder = LtcEncoder::create(first.rate(), sampleRate, volumeDbfs);
    EXPECT_TRUE(encoder) << (encoder ? "" : encoder.message());
    LtcSignal signal{{}, first, sampleRate};
    encoder->setTimecode(first);
    encoder->encode(frames, signal.samples);
    return signal;
}

// Decodes `samples` in chunks of `chunk` (as an audio input delivers them).
inline std::vector<LtcFrame> decodeAll(LtcDecoder& decoder, const std::vector<float>& samples,
                                       size_t chunk = 480) {
    std::vector<LtcFrame> frames;
    for (size_t at = 0; at < samples.size(); at += chunk)
        decoder.write(
            std::span<const float>(samples.data() + at, std::min(chunk, samples.size() - at)),
            frames);
    return frames;
}

}  // namespace previs::testing
