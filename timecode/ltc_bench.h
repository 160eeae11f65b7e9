#pragma once

// The cost of decoding LTC, for `previs bench`: libltc's encoder writes `seconds` of LTC at
// `rate`, and the decoder (with every check it makes) reads it back `repeats` times.

#include "base/result.h"
#include "timecode/timecode.h"

namespace previs {

struct LtcDecodeCost {
    double usPerAudioSecond = 0.0;  // CPU time to decode one second of audio (best of repeats)
    double realTimeFactor = 0.0;    // seconds of audio decoded per second of CPU
    uint64_t framesDecoded = 0;     // per repeat; seconds × rate when every frame came back
    uint64_t rejected = 0;
};

Result<LtcDecodeCost> measureLtcDecodeCost(TimecodeRate rate, int sampleRate = 48000,
                                           double seconds = 10.0, int repeats = 5);

}  // namespace previs
