#include "timecode/timecode_source.h"

#include <cmath>

#include "base/log.h"

namespace previs {

namespace {

// Good LTC frames kept for matching frames asked late: 64 frames is two seconds at 30 fps,
// more than any capture queue holds.
constexpr size_t kAnchors = 64;

int64_t samplesToNs(int64_t samples, int sampleRate) {
    return samples * 1'000'000'000 / sampleRate;
}

// Frames at `rate` from `fromNs` to `toNs`, to the nearest frame.
int64_t framesBetween(int64_t fromNs, int64_t toNs, TimecodeRate rate) {
    const double frameNs = 1e9 * rate.den() / rate.num();
    return std::llround(double(toNs - fromNs) / frameNs);
}

}  // namespace

const char* toString(TimecodeSourceKind kind) {
    return kind == TimecodeSourceKind::Ltc ? "ltc" : "clock";
}

const char* toString(TimecodeState state) {
    switch (state) {
        case TimecodeState::Ltc:
            return "ltc";
        case TimecodeState::Freewheel:
            return "freewheel";
        case TimecodeState::Clock:
            break;
    }
    return "clock";
}

Result<TimecodeSourceKind> parseTimecodeSourceKind(std::string_view text) {
    if (text == "ltc") return TimecodeSourceKind::Ltc;
    if (text == "clock") return TimecodeSourceKind::Clock;
    return makeError("[timecode] source = \"{}\": expected \"ltc\" or \"clock\"", text);
}

Result<std::unique_ptr<TimecodeSource>> TimecodeSource::create(const TimecodeSourceConfig& config) {
    std::optional<LtcDecoder> decoder;
    if (config.kind == TimecodeSourceKind::Ltc) {
        Result<LtcDecoder> made = LtcDecoder::create({config.sampleRate, config.ltcRate});
        if (!made) return made.error();
        decoder.emplace(std::move(made).value());
    }
    if (config.dropoutNs <= 0) return makeError("[timecode] dropout must be positive");
    return std::unique_ptr<TimecodeSource>(new TimecodeSource(config, std::move(decoder)));
}

void TimecodeSource::feedAudio(std::span<const float> samples, int64_t firstSampleMonoNs) {
    if (!decoder_) return;
    const int64_t firstSample = decoder_->samplesWritten();
    decoded_.clear();
    decoder_->write(samples, decoded_);
    publish(decoded_, firstSampleMonoNs, firstSample);
}

void TimecodeSource::feedAudio(std::span<const int16_t> samples, int64_t firstSampleMonoNs) {
    if (!decoder_) return;
    const int64_t firstSample = decoder_->samplesWritten();
    decoded_.clear();
    decoder_->write(samples, decoded_);
    publish(decoded_, firstSampleMonoNs, firstSample);
}

AudioSink TimecodeSource::audioSink() {
    return [this](std::span<const float> samples, int64_t firstSampleMonoNs) {
        feedAudio(samples, firstSampleMonoNs);
    };
}

void TimecodeSource::publish(const std::vector<LtcFrame>& frames, int64_t firstSampleMonoNs,
                             int64_t firstSample) {
    const int rate = decoder_->sampleRate();
    std::lock_guard lock(mutex_);
    for (const LtcFrame& frame : frames) {
        // The chunk's timestamp, carried back (or on) to the frame's samples at the audio rate.
        const Anchor anchor{
            frame.timecode, firstSampleMonoNs + samplesToNs(frame.startSample - firstSample, rate),
            firstSampleMonoNs + samplesToNs(frame.endSample + 1 - firstSample, rate)};
        if (anchors_.empty()) {
            ++status_.jams;
            logInfo("timecode: locked to LTC at {} ({})", frame.timecode.toString(),
                    frame.timecode.rate().toString());
        } else {
            const Anchor& previous = anchors_.back();
            const bool gap = anchor.startNs - previous.endNs > config_.dropoutNs;
            const Timecode expected = previous.timecode.plus(
                framesBetween(previous.startNs, anchor.startNs, previous.timecode.rate()));
            if (gap && !dropoutCounted_) ++status_.dropouts;
            if (gap || !(expected == frame.timecode)) {
                ++status_.jams;
                logInfo("timecode: LTC re-jammed at {} (free-running said {})",
                        frame.timecode.toString(), expected.toString());
            }
        }
        dropoutCounted_ = false;
        anchors_.push_back(anchor);
        if (anchors_.size() > kAnchors) anchors_.pop_front();
        status_.lastLtc = frame.timecode;
        status_.lastLtcMonoNs = anchor.startNs;
    }
    status_.ltc = decoder_->counters();
}

const TimecodeSource::Anchor& TimecodeSource::anchorFor(int64_t t) const {
    // The latest LTC frame that started by the time asked (half a frame's grace: a camera locked
    // to the same reference may stamp a frame a little before its LTC frame's first transition).
    for (auto it = anchors_.rbegin(); it != anchors_.rend(); ++it)
        if (it->startNs <= t + it->timecode.rate().frameNs() / 2) return *it;
    return anchors_.front();
}

TimecodeRate TimecodeSource::clockRate() const {
    const std::optional<FrameRate> measured = cameraRate_.rate();
    return config_.rate.rate(measured ? std::optional(measured->fps()) : std::nullopt);
}

FrameTimecode TimecodeSource::frameTimecode(int64_t monoNs, uint64_t realtimeNs,
                                            std::optional<uint64_t> sequence) {
    std::lock_guard lock(mutex_);
    if (sequence) cameraRate_.add(monoNs, *sequence);
    const TimecodeRate rate = clockRate();
    FrameTimecode result{Timecode(rate), TimecodeState::Clock, std::nullopt};
    const int64_t t = monoNs + config_.cameraOffsetNs;
    if (anchors_.empty()) {
        result.timecode = clockTimecode(realtimeNs, rate);
        result.state = TimecodeState::Clock;
    } else {
        const Anchor& anchor = anchorFor(t);
        result.timecode =
            anchor.timecode.plus(framesBetween(anchor.startNs, t, anchor.timecode.rate()));
        const Anchor& latest = anchors_.back();
        if (t - latest.endNs > config_.dropoutNs) {
            result.state = TimecodeState::Freewheel;
            result.freewheelSinceNs = latest.endNs;
            if (!dropoutCounted_) {
                ++status_.dropouts;
                dropoutCounted_ = true;
                logWarning("timecode: LTC lost after {}; free-running", latest.timecode.toString());
            }
        } else {
            result.state = TimecodeState::Ltc;
        }
    }
    status_.state = result.state;
    status_.rate = result.timecode.rate();
    status_.freewheelSinceNs = result.freewheelSinceNs;
    return result;
}

TimecodeStatus TimecodeSource::status() const {
    std::lock_guard lock(mutex_);
    return status_;
}

}  // namespace previs
