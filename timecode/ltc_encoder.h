#pragma once

// LTC audio written by libltc's encoder: the test signal of the decoder's tests and of the decode
// cost measurement, and a signal a bench or a loopback test can play.

#include <memory>
#include <vector>

#include "base/result.h"
#include "timecode/timecode.h"

struct LTCEncoder;

namespace previs {

class LtcEncoder {
public:
    // `volumeDbfs`: libltc's default is -3 dBFS; line-level LTC is often -18 dBFS.
    static Result<LtcEncoder> create(TimecodeRate rate, int sampleRate, double volumeDbfs = -3.0);

    // The next frame encoded is `tc` (its rate must be the encoder's).
    void setTimecode(const Timecode& tc);
    // Appends `frames` frames of audio (mono, ±1.0 full scale), counting up from the current
    // timecode, and leaves the next one current.
    void encode(int frames, std::vector<float>& out);
    Timecode timecode() const { return next_; }

private:
    struct Deleter {
        void operator()(LTCEncoder* encoder) const;
    };

    LtcEncoder(TimecodeRate rate, LTCEncoder* encoder) : encoder_(encoder), next_(rate) {}

    std::unique_ptr<LTCEncoder, Deleter> encoder_;
    Timecode next_;
};

}  // namespace previs
