#pragma once

// SMPTE ST 12-1 timecode: a frame label HH:MM:SS:FF at a frame rate, with drop-frame counting for
// the NTSC-derived rates (29.97 and 59.94). A label counts whole frames at the rate's nominal
// integer rate (30 for 29.97); drop-frame skips labels so the count stays close to the wall clock:
// frames 0 and 1 (0..3 at 59.94) are skipped at the start of every minute except every tenth.

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "base/result.h"

namespace previs {

// A timecode rate: the exact frame rate num/den and whether labels drop-frame count.
class TimecodeRate {
public:
    static constexpr TimecodeRate fps23_976() { return {24000, 1001, false}; }
    static constexpr TimecodeRate fps24() { return {24, 1, false}; }
    static constexpr TimecodeRate fps25() { return {25, 1, false}; }
    static constexpr TimecodeRate fps29_97() { return {30000, 1001, false}; }
    static constexpr TimecodeRate fps29_97Df() { return {30000, 1001, true}; }
    static constexpr TimecodeRate fps30() { return {30, 1, false}; }
    static constexpr TimecodeRate fps50() { return {50, 1, false}; }
    static constexpr TimecodeRate fps59_94() { return {60000, 1001, false}; }
    static constexpr TimecodeRate fps59_94Df() { return {60000, 1001, true}; }
    static constexpr TimecodeRate fps60() { return {60, 1, false}; }

    // "23.976", "24", "25", "29.97", "29.97df", "30", "50", "59.94", "59.94df", "60" (the
    // config's `[timecode] rate`); an error names the value and lists these.
    static Result<TimecodeRate> parse(std::string_view text);
    // The rate a camera running at `fps` is labelled at: the standard rate within 0.5 % of it,
    // else of the smallest whole multiple of it (15 fps counts at 30, 12.5 at 25, 12 at 24: every
    // frame a whole number of labels on), else the nearest; non-drop-frame unless `dropFrame`
    // and the rate is 29.97 or 59.94.
    static TimecodeRate fromFps(double fps, bool dropFrame = false);

    int num() const { return num_; }
    int den() const { return den_; }
    bool dropFrame() const { return dropFrame_; }
    double fps() const { return double(num_) / den_; }
    // Labels a second counts: 30 for 29.97, 24 for 23.976.
    int nominal() const { return (num_ + den_ - 1) / den_; }
    // Labels skipped at each dropping minute: 2 at 29.97 DF, 4 at 59.94 DF, 0 otherwise.
    int dropsPerMinute() const { return dropFrame_ ? nominal() / 15 : 0; }
    // Frames from 00:00:00:00 to 24:00:00:00.
    int64_t framesPerDay() const;
    // Duration of one frame in nanoseconds (exact rate, rounded).
    int64_t frameNs() const { return (int64_t(1'000'000'000) * den_ + num_ / 2) / num_; }
    // "29.97 DF", "25", "23.976".
    std::string toString() const;
    // The name parse() reads back: "29.97df", "25", "23.976" (a take's index, the config).
    std::string name() const;

    bool operator==(const TimecodeRate&) const = default;

private:
    constexpr TimecodeRate(int num, int den, bool dropFrame)
        : num_(num), den_(den), dropFrame_(dropFrame) {}

    int num_;
    int den_;
    bool dropFrame_;
};

class Timecode {
public:
    // Frame 0 of the day at `rate`.
    explicit Timecode(TimecodeRate rate) : rate_(rate) {}

    // The label, or nothing when a field is out of range or the label is one drop-frame skips.
    static std::optional<Timecode> fromFields(int hours, int minutes, int seconds, int frames,
                                              TimecodeRate rate);
    // The label of frame `count` of the day (taken modulo 24 h; negative counts wrap back).
    static Timecode fromFrameCount(int64_t count, TimecodeRate rate);
    // "HH:MM:SS:FF", or "HH:MM:SS;FF" / "HH:MM:SS.FF" / "HH;MM;SS;FF" for drop-frame. A ';' or '.'
    // at a non-drop-frame rate, or a label drop-frame skips, is an error naming the text.
    static Result<Timecode> parse(std::string_view text, TimecodeRate rate);

    int hours() const { return hours_; }
    int minutes() const { return minutes_; }
    int seconds() const { return seconds_; }
    int frames() const { return frames_; }
    TimecodeRate rate() const { return rate_; }
    bool dropFrame() const { return rate_.dropFrame(); }

    // Frames since 00:00:00:00 (drop-frame labels counted as the frames they stand for).
    int64_t frameCount() const;
    // `n` frames later (earlier when negative), wrapping at 24 h.
    Timecode plus(int64_t n) const { return fromFrameCount(frameCount() + n, rate_); }
    Timecode next() const { return plus(1); }
    // "HH:MM:SS:FF", with ';' before the frames at a drop-frame rate (the SMPTE convention).
    std::string toString() const;

    bool operator==(const Timecode&) const = default;

private:
    Timecode(int hours, int minutes, int seconds, int frames, TimecodeRate rate)
        : hours_(hours), minutes_(minutes), seconds_(seconds), frames_(frames), rate_(rate) {}

    int hours_ = 0;
    int minutes_ = 0;
    int seconds_ = 0;
    int frames_ = 0;
    TimecodeRate rate_;
};

// The rate a camera's timecode labels count at (docs/timecode.md "rate"), the one rule of the
// service's timecode source, the take recorder and every reader of a take: `[timecode] rate`
// when set; else the camera's configured fps; else the fps measured on its frames (each through
// TimecodeRate::fromFps, so a 15 fps camera counts at 30); else 30.
struct LabelRateRule {
    std::optional<TimecodeRate> configured{};  // [timecode] rate
    double cameraFps = 0.0;                    // the camera's configured fps; 0: none
    // What the config decides alone; nothing: the rate is measured on the camera's frames.
    std::optional<TimecodeRate> fromConfig() const;
    // fromConfig(), else fromFps(measuredFps), else 30 (nothing measured yet, or one frame).
    TimecodeRate rate(std::optional<double> measuredFps = std::nullopt) const;
};

// The rate a recorded label counts at (issue 54, docs/session-format.md), for every reader of a
// take: the rate the recorder wrote beside the label (`recorded`, a name parse() reads), else —
// a take from before that column, or a name this previs does not know — the rate the box
// labelled at, `rule.rate()`, drop-frame when the label says so (';' or '.' before the frames).
TimecodeRate labelRate(std::string_view label, std::string_view recorded,
                       const LabelRateRule& rule);

// The local time of day of `wallClockNs` (CLOCK_REALTIME) as a timecode at `rate`. Non-drop
// rates label HH:MM:SS with the clock's and count the frame within the second at the nominal
// rate (how takes were stamped before LTC); drop-frame rates count real frames since midnight,
// which drop-frame labels keep within a frame or two of the clock over the day.
Timecode clockTimecode(uint64_t wallClockNs, TimecodeRate rate);

}  // namespace previs
