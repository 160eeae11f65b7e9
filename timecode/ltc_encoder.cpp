#include "timecode/ltc_encoder.h"

#include <ltc.h>

namespace previs {

namespace {

// Where the binary group flags and the polarity-correction bit sit depends on the TV standard
// (libltc's LTC_TV_STANDARD): 25 fps is the 625/50 layout.
LTC_TV_STANDARD standardFor(TimecodeRate rate) {
    switch (rate.nominal()) {
        case 25:
            return LTC_TV_625_50;
        case 24:
            return LTC_TV_FILM_24;
        default:
            return LTC_TV_525_60;
    }
}

}  // namespace

void LtcEncoder::Deleter::operator()(LTCEncoder* encoder) const { ltc_encoder_free(encoder); }

Result<LtcEncoder> LtcEncoder::create(TimecodeRate rate, int sampleRate, double volumeDbfs) {
    if (rate.nominal() > 30)
        return makeError("LTC encoder: LTC carries at most 30 frames a second, not {}",
                         rate.toString());
    LTCEncoder* encoder = ltc_encoder_create(sampleRate, rate.fps(), standardFor(rate), 0);
    if (!encoder)
        return makeError("LTC encoder: cannot encode {} at {} Hz", rate.toString(), sampleRate);
    LtcEncoder result(rate, encoder);
    if (ltc_encoder_set_volume(encoder, volumeDbfs) != 0)
        return makeError("LTC encoder: volume {} dBFS is out of range", volumeDbfs);
    // libltc sets the drop-frame bit for every 29.97 rate; 29.97 non-drop clears it.
    LTCFrame frame;
    ltc_encoder_get_frame(encoder, &frame);
    frame.dfbit = rate.dropFrame() ? 1 : 0;
    ltc_encoder_set_frame(encoder, &frame);
    result.setTimecode(Timecode(rate));
    return result;
}

void LtcEncoder::setTimecode(const Timecode& tc) {
    SMPTETimecode smpte{};
    smpte.hours = static_cast<unsigned char>(tc.hours());
    smpte.mins = static_cast<unsigned char>(tc.minutes());
    smpte.secs = static_cast<unsigned char>(tc.seconds());
    smpte.frame = static_cast<unsigned char>(tc.frames());
    // Also recomputes the polarity-correction bit.
    ltc_encoder_set_timecode(encoder_.get(), &smpte);
    next_ = tc;
}

void LtcEncoder::encode(int frames, std::vector<float>& out) {
    for (int i = 0; i < frames; ++i) {
        ltc_encoder_encode_frame(encoder_.get());
        ltcsnd_sample_t* buffer = nullptr;
        const int size = ltc_encoder_get_bufferptr(encoder_.get(), &buffer, 1);
        // libltc writes unsigned 8-bit samples centred on 128.
        for (int s = 0; s < size; ++s) out.push_back((float(buffer[s]) - 128.0f) / 127.0f);
        // Our own count, not libltc's increment: the timecode the next frame must carry.
        setTimecode(next_.next());
    }
}

}  // namespace previs
