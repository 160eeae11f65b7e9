#include "timecode/ltc_bench.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <vector>

#include "timecode/ltc_decoder.h"
#include "timecode/ltc_encoder.h"

namespace previs {

namespace {

// The thread's CPU time: what decoding costs, not what the other processes on a shared machine
// take from the wall clock meanwhile.
double threadCpuSeconds() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

}  // namespace

Result<LtcDecodeCost> measureLtcDecodeCost(TimecodeRate rate, int sampleRate, double seconds,
                                           int repeats) {
    Result<LtcEncoder> encoder = LtcEncoder::create(rate, sampleRate);
    if (!encoder) return encoder.error();
    std::vector<float> audio;
    encoder->setTimecode(*Timecode::fromFields(10, 0, 0, 0, rate));
    encoder->encode(int(std::ceil(seconds * rate.fps())), audio);
    const double audioSeconds = double(audio.size()) / sampleRate;

    LtcDecodeCost cost;
    double best = 1e30;
    // 10 ms chunks, as the ALSA input delivers them.
    const size_t chunk = size_t(sampleRate / 100);
    std::vector<LtcFrame> frames;
    for (int r = 0; r < std::max(repeats, 1); ++r) {
        Result<LtcDecoder> decoder = LtcDecoder::create({sampleRate, rate});
        if (!decoder) return decoder.error();
        const double start = threadCpuSeconds();
        for (size_t at = 0; at < audio.size(); at += chunk) {
            frames.clear();
            decoder->write(
                std::span<const float>(audio.data() + at, std::min(chunk, audio.size() - at)),
                frames);
        }
        best = std::min(best, threadCpuSeconds() - start);
        cost.framesDecoded = decoder->counters().decoded;
        cost.rejected = decoder->counters().rejected;
    }
    cost.usPerAudioSecond = best / audioSeconds * 1e6;
    cost.realTimeFactor = best > 0 ? audioSeconds / best : 0.0;
    return cost;
}

}  // namespace previs
