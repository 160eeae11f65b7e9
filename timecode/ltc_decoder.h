#pragma once

// LTC (SMPTE ST 12-1 linear timecode) from audio samples, decoded by libltc. libltc finds frames
// by their sync word and reports the sample where each began; it checks nothing else, so every
// frame it reports is checked here before it is delivered: polarity-correction (parity) bit, BCD
// digits in range, the drop-frame bit and bit rate agreeing with the timecode rate, and the
// value following the frame before it. A frame that fails is counted and dropped; a frame that
// is valid but does not follow its predecessor is held until the next frame confirms it, so a
// corrupted frame whose parity happens to pass is not delivered either.

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "base/result.h"
#include "timecode/timecode.h"

struct LTCDecoder;
struct LTCFrameExt;

namespace previs {

struct LtcFrame {
    Timecode timecode;
    // Sample positions (from the first sample written, 0) of the frame's first bit transition
    // and of its end: what maps the frame to the camera's clock.
    int64_t startSample = 0;
    int64_t endSample = 0;
    // Signal level of the frame, dBFS.
    double volumeDbfs = 0.0;
};

struct LtcCounters {
    uint64_t decoded = 0;          // frames delivered
    uint64_t rejected = 0;         // frames dropped, all reasons below together
    uint64_t parityErrors = 0;     // the polarity-correction bit did not make the zeros even
    uint64_t invalidFields = 0;    // a BCD digit or field out of range, a skipped drop label
    uint64_t wrongRate = 0;        // bit rate or drop-frame bit not the timecode rate's
    uint64_t reversed = 0;         // played backwards
    uint64_t unconfirmed = 0;      // valid alone, but neither followed nor was followed
    uint64_t lostFrames = 0;       // frames missing between two delivered ones (bit errors the
                                   // sync search itself lost)
    uint64_t discontinuities = 0;  // the value jumped between two frames adjacent in the audio
};

struct LtcDecoderConfig {
    int sampleRate = 48000;
    // The timecode rate the LTC must have. Without it the rate is taken from each frame's bit
    // rate (24, 25 or 30) and drop-frame bit (29.97 DF); 23.976 and 29.97 non-drop cannot be told
    // from 24 and 30 that way (0.1 %), so they must be configured.
    std::optional<TimecodeRate> rate;
};

class LtcDecoder {
public:
    static Result<LtcDecoder> create(const LtcDecoderConfig& config);

    // Decodes the next samples (mono, full scale ±1.0 or ±32768) and appends the frames that
    // passed every check, in order, to `out`.
    void write(std::span<const float> samples, std::vector<LtcFrame>& out);
    void write(std::span<const int16_t> samples, std::vector<LtcFrame>& out);

    const LtcCounters& counters() const { return counters_; }
    int64_t samplesWritten() const { return position_; }
    int sampleRate() const { return config_.sampleRate; }

private:
    struct Deleter {
        void operator()(LTCDecoder* decoder) const;
    };

    explicit LtcDecoder(const LtcDecoderConfig& config, LTCDecoder* decoder)
        : config_(config), decoder_(decoder) {}

    void drain(std::vector<LtcFrame>& out);
    std::optional<LtcFrame> check(const LTCFrameExt& ext);
    void accept(const LtcFrame& frame, std::vector<LtcFrame>& out);
    void dropCandidate();
    // Frames between `from`'s start and `to`'s start, when a whole number within a few frames.
    std::optional<int64_t> framesBetween(const LtcFrame& from, const LtcFrame& to) const;

    LtcDecoderConfig config_;
    std::unique_ptr<LTCDecoder, Deleter> decoder_;
    int64_t position_ = 0;
    float lowPassGain_ = 1.0f;
    float lowPass_ = 0.0f;
    std::vector<float> filtered_;
    std::vector<float> scaled_;
    LtcCounters counters_;
    std::optional<LtcFrame> last_;       // last delivered
    std::optional<LtcFrame> candidate_;  // valid, waiting for its successor to confirm it
};

}  // namespace previs
