#pragma once

// The timecode of every captured frame: from LTC on an audio input when one is configured, else
// the time of day from the system clock at the camera's rate. The audio thread feeds samples; the
// capture thread asks, per frame, with the frame's timestamps. Thread-safe.
//
// States: Ltc (locked: the LTC frame whose start is nearest the camera timestamp), Freewheel (no
// valid LTC for longer than the dropout time: counting on from the last good LTC frame at its
// rate; says since when), Clock (no LTC configured, or none locked yet). When LTC comes back the
// source re-locks (a jam) to the new values, confirmed by two consecutive frames.

#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "base/result.h"
#include "timecode/audio_input.h"
#include "timecode/frame_rate.h"
#include "timecode/ltc_decoder.h"
#include "timecode/timecode.h"

namespace previs {

enum class TimecodeSourceKind { Clock, Ltc };
enum class TimecodeState { Ltc, Freewheel, Clock };

// "clock", "ltc" (the config's `[timecode] source` and the status's words).
const char* toString(TimecodeSourceKind kind);
// "ltc", "freewheel", "clock".
const char* toString(TimecodeState state);
Result<TimecodeSourceKind> parseTimecodeSourceKind(std::string_view text);

struct TimecodeSourceConfig {
    TimecodeSourceKind kind = TimecodeSourceKind::Clock;
    // The clock's timecode rate, also used before LTC first locks: the rule's (timecode/
    // timecode.h), with the camera's rate measured from the frames asked (FrameRateMeter) where
    // the config names none, 30 until the second frame.
    LabelRateRule rate{TimecodeRate::fps25(), 0.0};
    // The rate the LTC must have; nothing: taken from the signal (24, 25, 30, 29.97 DF).
    std::optional<TimecodeRate> ltcRate;
    int sampleRate = 48000;
    // LTC silent or invalid for longer than this after its last good frame ended: freewheel.
    // Longer than the audio input's chunk and a frame, or every frame asked would freewheel.
    int64_t dropoutNs = 200'000'000;
    // Added to a camera timestamp before it is matched to LTC: the camera's timestamp latency
    // relative to the LTC frame's start (capture/exposure point vs. the timecode generator).
    int64_t cameraOffsetNs = 0;
};

struct FrameTimecode {
    Timecode timecode;
    TimecodeState state = TimecodeState::Clock;
    // CLOCK_MONOTONIC ns when the last good LTC frame ended (Freewheel only).
    std::optional<int64_t> freewheelSinceNs;
};

struct TimecodeStatus {
    TimecodeSourceKind source = TimecodeSourceKind::Clock;
    TimecodeState state = TimecodeState::Clock;  // of the last frame asked
    TimecodeRate rate = TimecodeRate::fps25();   // of the last frame asked
    std::optional<Timecode> lastLtc;             // last good LTC frame decoded
    int64_t lastLtcMonoNs = 0;                   // its start, CLOCK_MONOTONIC
    std::optional<int64_t> freewheelSinceNs;
    LtcCounters ltc;        // frames decoded, bit errors and rejected frames
    uint64_t dropouts = 0;  // times the LTC went away for longer than the dropout time
    uint64_t jams = 0;      // times the source locked or re-locked to LTC
};

class TimecodeSource {
public:
    static Result<std::unique_ptr<TimecodeSource>> create(const TimecodeSourceConfig& config);

    // The audio thread: consecutive mono chunks and their first sample's CLOCK_MONOTONIC time.
    void feedAudio(std::span<const float> samples, int64_t firstSampleMonoNs);
    void feedAudio(std::span<const int16_t> samples, int64_t firstSampleMonoNs);
    // A sink for AlsaCapture or playAudioClip feeding this source (which must outlive it).
    AudioSink audioSink();

    // The timecode of the frame captured at `monoNs` (CLOCK_MONOTONIC) / `realtimeNs`
    // (CLOCK_REALTIME, for the clock state). `sequence`: the camera's count of the frame, from
    // which (with `monoNs`) the rate is measured when the config names none.
    FrameTimecode frameTimecode(int64_t monoNs, uint64_t realtimeNs,
                                std::optional<uint64_t> sequence = std::nullopt);
    TimecodeStatus status() const;

private:
    struct Anchor {
        Timecode timecode;
        int64_t startNs;
        int64_t endNs;
    };

    TimecodeSource(const TimecodeSourceConfig& config, std::optional<LtcDecoder> decoder)
        : config_(config), decoder_(std::move(decoder)) {
        status_.source = config.kind;
        status_.rate = clockRate();
    }

    void publish(const std::vector<LtcFrame>& frames, int64_t firstSampleMonoNs,
                 int64_t firstSample);
    const Anchor& anchorFor(int64_t t) const;
    // The configured rate, else the measured one (mutex_ held, or before any thread starts).
    TimecodeRate clockRate() const;

    const TimecodeSourceConfig config_;
    // Audio thread only.
    std::optional<LtcDecoder> decoder_;
    std::vector<LtcFrame> decoded_;

    mutable std::mutex mutex_;
    // Recent good LTC frames, oldest first: a frame asked late is matched to the LTC of its time,
    // not extrapolated across a jam.
    std::deque<Anchor> anchors_;
    bool dropoutCounted_ = false;
    FrameRateMeter cameraRate_;  // without a configured rate
    TimecodeStatus status_;
};

}  // namespace previs
