#include "timecode/ltc_decoder.h"

#include <ltc.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

namespace previs {

namespace {

// libltc's queue between its sync search and our reads; write() drains it after every call, so
// it only needs to hold the frames one call's samples can contain (a second of 30 fps audio).
constexpr int kQueueFrames = 64;
// How far a frame's measured length may be from the rate's: 24 and 25 fps are 4 % apart, while
// a real generator and sound card agree to well under 0.1 %.
constexpr double kRateTolerance = 0.015;
// A frame follows another when it starts this close (in frames) to a whole number of frames
// after it: libltc places a frame's start to a sample or two.
constexpr double kPositionTolerance = 0.25;
// The most frames a delivered frame may jump over and still confirm itself by its position.
constexpr int64_t kMaxFramesSkipped = 8;

// The 80 bits of an LTC frame as libltc lays them out (the first 10 bytes of LTCFrame).
std::array<uint8_t, 10> frameBytes(const LTCFrame& frame) {
    std::array<uint8_t, 10> bytes{};
    static_assert(sizeof(LTCFrame) >= 10);
    std::memcpy(bytes.data(), &frame, bytes.size());
    return bytes;
}

// ST 12-1: the biphase mark polarity-correction bit makes the number of zeros in the 80 bits
// even (so every sync word starts with the same phase). A single flipped bit breaks it.
bool parityOk(const LTCFrame& frame) {
    int ones = 0;
    for (uint8_t byte : frameBytes(frame)) ones += std::popcount(byte);
    return ones % 2 == 0;
}

uint16_t syncWord() {
    LTCFrame reference;
    ltc_frame_reset(&reference);
    return uint16_t(reference.sync_word);
}

bool bcdInRange(const LTCFrame& f) {
    return f.frame_units <= 9 && f.secs_units <= 9 && f.secs_tens <= 5 && f.mins_units <= 9 &&
           f.mins_tens <= 5 && f.hours_units <= 9 && f.hours_tens <= 2;
}

// The nominal rates LTC carries (frame tens are 2 bits: at most 39 frames).
std::optional<TimecodeRate> rateFromLength(double framesPerSecond, bool dropFrameBit) {
    for (int nominal : {24, 25, 30}) {
        if (std::abs(framesPerSecond / nominal - 1.0) > kRateTolerance) continue;
        if (dropFrameBit)
            return nominal == 30 ? std::optional(TimecodeRate::fps29_97Df()) : std::nullopt;
        return TimecodeRate::fromFps(nominal);
    }
    return std::nullopt;
}

}  // namespace

void LtcDecoder::Deleter::operator()(LTCDecoder* decoder) const { ltc_decoder_free(decoder); }

Result<LtcDecoder> LtcDecoder::create(const LtcDecoderConfig& config) {
    if (config.sampleRate < 8000 || config.sampleRate > 384000)
        return makeError("LTC decoder: sample rate {} Hz is outside 8000..384000",
                         config.sampleRate);
    if (config.rate && config.rate->nominal() > 30)
        return makeError("LTC decoder: LTC carries at most 30 frames a second, not {}",
                         config.rate->toString());
    // The samples per frame libltc starts its bit-rate tracking from; it adapts after a frame.
    const double fps = config.rate ? config.rate->fps() : 25.0;
    LTCDecoder* decoder =
        ltc_decoder_create(int(std::lround(config.sampleRate / fps)), kQueueFrames);
    if (!decoder) return makeError("LTC decoder: out of memory");
    LtcDecoder result(config, decoder);
    // One-pole low-pass at 10 kHz: above LTC's fastest half-bit (2.4 kHz at 30 fps) and its 40 µs
    // rise time, it removes the broadband noise that makes libltc's zero-crossing detector see
    // extra edges. It delays the signal by 1/(2π·10 kHz) = 16 µs, under a sample at 48 kHz.
    result.lowPassGain_ = float(1.0 - std::exp(-2.0 * M_PI * 10'000.0 / config.sampleRate));
    return result;
}

void LtcDecoder::write(std::span<const float> samples, std::vector<LtcFrame>& out) {
    // libltc's queue is a ring that overwrites when full: feed it a tenth of a second (three
    // frames at most) at a time and drain it after each, whatever size the caller hands in.
    const size_t piece = size_t(config_.sampleRate / 10);
    for (size_t at = 0; at < samples.size(); at += piece) {
        const size_t n = std::min(piece, samples.size() - at);
        filtered_.resize(n);
        for (size_t i = 0; i < n; ++i) {
            lowPass_ += lowPassGain_ * (samples[at + i] - lowPass_);
            filtered_[i] = lowPass_;
        }
        ltc_decoder_write_float(decoder_.get(), filtered_.data(), n, position_);
        position_ += int64_t(n);
        drain(out);
    }
}

void LtcDecoder::write(std::span<const int16_t> samples, std::vector<LtcFrame>& out) {
    std::vector<float>& scaled = scaled_;
    scaled.resize(samples.size());
    for (size_t i = 0; i < samples.size(); ++i) scaled[i] = float(samples[i]) / 32768.0f;
    write(std::span<const float>(scaled), out);
}

void LtcDecoder::drain(std::vector<LtcFrame>& out) {
    LTCFrameExt ext;
    while (ltc_decoder_read(decoder_.get(), &ext)) {
        const std::optional<LtcFrame> frame = check(ext);
        if (!frame) {
            ++counters_.rejected;
            continue;
        }
        accept(*frame, out);
    }
}

std::optional<LtcFrame> LtcDecoder::check(const LTCFrameExt& ext) {
    const LTCFrame& f = ext.ltc;
    if (ext.reverse) {
        ++counters_.reversed;
        return std::nullopt;
    }
    if (!parityOk(f) || f.sync_word != syncWord()) {
        ++counters_.parityErrors;
        return std::nullopt;
    }
    if (!bcdInRange(f)) {
        ++counters_.invalidFields;
        return std::nullopt;
    }
    const double length = double(ext.off_end - ext.off_start + 1);
    const double framesPerSecond = config_.sampleRate / std::max(length, 1.0);
    std::optional<TimecodeRate> rate = config_.rate;
    if (rate) {
        if (std::abs(framesPerSecond / rate->fps() - 1.0) > kRateTolerance ||
            bool(f.dfbit) != rate->dropFrame())
            rate.reset();
    } else {
        rate = rateFromLength(framesPerSecond, f.dfbit);
    }
    if (!rate) {
        ++counters_.wrongRate;
        return std::nullopt;
    }
    const std::optional<Timecode> tc = Timecode::fromFields(
        f.hours_tens * 10 + f.hours_units, f.mins_tens * 10 + f.mins_units,
        f.secs_tens * 10 + f.secs_units, f.frame_tens * 10 + f.frame_units, *rate);
    if (!tc) {
        ++counters_.invalidFields;
        return std::nullopt;
    }
    return LtcFrame{*tc, ext.off_start, ext.off_end, ext.volume};
}

void LtcDecoder::dropCandidate() {
    ++counters_.unconfirmed;
    ++counters_.rejected;
    candidate_.reset();
}

std::optional<int64_t> LtcDecoder::framesBetween(const LtcFrame& from, const LtcFrame& to) const {
    const TimecodeRate rate = to.timecode.rate();
    const double samplesPerFrame = double(config_.sampleRate) * rate.den() / rate.num();
    const double frames = double(to.startSample - from.startSample) / samplesPerFrame;
    const double whole = std::round(frames);
    if (whole < 1 || whole > double(kMaxFramesSkipped) ||
        std::abs(frames - whole) > kPositionTolerance)
        return std::nullopt;
    return int64_t(whole);
}

void LtcDecoder::accept(const LtcFrame& frame, std::vector<LtcFrame>& out) {
    const auto follows = [&](const LtcFrame& before) {
        const std::optional<int64_t> n = framesBetween(before, frame);
        return n && before.timecode.rate() == frame.timecode.rate() &&
                       before.timecode.plus(*n) == frame.timecode
                   ? n
                   : std::nullopt;
    };
    if (last_) {
        if (const std::optional<int64_t> n = follows(*last_)) {
            counters_.lostFrames += uint64_t(*n - 1);
            // A valid frame between two that follow each other: corrupted where parity missed.
            if (candidate_) dropCandidate();
            ++counters_.decoded;
            out.push_back(frame);
            last_ = frame;
            return;
        }
    }
    if (candidate_) {
        if (const std::optional<int64_t> n = follows(*candidate_)) {
            // A new run of timecode, confirmed by its second frame: a jump when it came straight
            // after the last delivered frame in the audio, a re-lock after a gap otherwise.
            if (last_ && framesBetween(*last_, *candidate_)) ++counters_.discontinuities;
            counters_.lostFrames += uint64_t(*n - 1);
            counters_.decoded += 2;
            out.push_back(*candidate_);
            out.push_back(frame);
            last_ = frame;
            candidate_.reset();
            return;
        }
        dropCandidate();
    }
    candidate_ = frame;
}

}  // namespace previs
