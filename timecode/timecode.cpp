#include "timecode/timecode.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <ctime>

namespace previs {

namespace {

struct NamedRate {
    std::string_view name;
    TimecodeRate rate;
};

constexpr std::array<NamedRate, 10> kNamedRates{{
    {"23.976", TimecodeRate::fps23_976()},
    {"24", TimecodeRate::fps24()},
    {"25", TimecodeRate::fps25()},
    {"29.97", TimecodeRate::fps29_97()},
    {"29.97df", TimecodeRate::fps29_97Df()},
    {"30", TimecodeRate::fps30()},
    {"50", TimecodeRate::fps50()},
    {"59.94", TimecodeRate::fps59_94()},
    {"59.94df", TimecodeRate::fps59_94Df()},
    {"60", TimecodeRate::fps60()},
}};

int64_t floorMod(int64_t a, int64_t b) { return ((a % b) + b) % b; }

std::optional<int> twoDigits(std::string_view text, size_t at) {
    if (!std::isdigit(static_cast<unsigned char>(text[at])) ||
        !std::isdigit(static_cast<unsigned char>(text[at + 1])))
        return std::nullopt;
    return (text[at] - '0') * 10 + (text[at + 1] - '0');
}

}  // namespace

Result<TimecodeRate> TimecodeRate::parse(std::string_view text) {
    std::string lower;
    for (char c : text)
        if (c != ' ') lower += char(std::tolower(static_cast<unsigned char>(c)));
    if (lower.ends_with("ndf")) lower.resize(lower.size() - 3);
    for (const NamedRate& named : kNamedRates)
        if (lower == named.name) return named.rate;
    return makeError(
        "timecode rate \"{}\" is not one of 23.976, 24, 25, 29.97, 29.97df, 30, 50, 59.94, "
        "59.94df, 60",
        text);
}

TimecodeRate TimecodeRate::fromFps(double fps, bool dropFrame) {
    const NamedRate* best = &kNamedRates[0];
    for (const NamedRate& named : kNamedRates) {
        if (named.rate.dropFrame()) continue;
        if (std::abs(named.rate.fps() - fps) < std::abs(best->rate.fps() - fps)) best = &named;
    }
    // A slow camera (15 fps) is labelled at the rate it divides, not the nearest (23.976).
    constexpr double kTolerance = 0.005;
    constexpr int kMostLabelsAFrame = 8;
    for (int k = 1; k <= kMostLabelsAFrame && fps > 0.0; ++k) {
        const NamedRate* match = nullptr;
        for (const NamedRate& named : kNamedRates) {
            const double off = std::abs(named.rate.fps() - k * fps);
            if (!named.rate.dropFrame() && off <= kTolerance * named.rate.fps() &&
                (!match || off < std::abs(match->rate.fps() - k * fps)))
                match = &named;
        }
        if (match) {
            best = match;
            break;
        }
    }
    TimecodeRate rate = best->rate;
    // Only the 1000/1001 rates have a drop-frame form.
    if (dropFrame && rate.den_ == 1001 && rate.nominal() % 30 == 0) rate.dropFrame_ = true;
    return rate;
}

int64_t TimecodeRate::framesPerDay() const {
    return int64_t(nominal()) * 86400 - int64_t(dropsPerMinute()) * (1440 - 144);
}

std::string TimecodeRate::toString() const {
    std::string text = den_ == 1 ? fmt::format("{}", num_) : fmt::format("{:.3f}", fps());
    // 29.970 → 29.97, 23.976 stays.
    if (den_ != 1 && text.back() == '0') text.pop_back();
    return dropFrame_ ? text + " DF" : text;
}

std::optional<TimecodeRate> LabelRateRule::fromConfig() const {
    if (configured) return configured;
    if (cameraFps > 0.0) return TimecodeRate::fromFps(cameraFps);
    return std::nullopt;
}

TimecodeRate LabelRateRule::rate(std::optional<double> measuredFps) const {
    if (std::optional<TimecodeRate> known = fromConfig()) return *known;
    if (measuredFps && *measuredFps > 0.0) return TimecodeRate::fromFps(*measuredFps);
    return TimecodeRate::fps30();
}

TimecodeRate labelRate(std::string_view label, std::string_view recorded,
                       const LabelRateRule& rule) {
    if (!recorded.empty())
        if (Result<TimecodeRate> rate = TimecodeRate::parse(recorded)) return *rate;
    const bool dropFrame = label.find_first_of(";.") != std::string_view::npos;
    const TimecodeRate boxRate = rule.rate();
    return boxRate.dropFrame() == dropFrame ? boxRate
                                            : TimecodeRate::fromFps(boxRate.fps(), dropFrame);
}

std::string TimecodeRate::name() const {
    for (const NamedRate& named : kNamedRates)
        if (named.rate == *this) return std::string(named.name);
    return toString();  // every rate is a named one; kept total
}

std::optional<Timecode> Timecode::fromFields(int hours, int minutes, int seconds, int frames,
                                             TimecodeRate rate) {
    if (hours < 0 || hours > 23 || minutes < 0 || minutes > 59 || seconds < 0 || seconds > 59 ||
        frames < 0 || frames >= rate.nominal())
        return std::nullopt;
    // Drop-frame skips the first labels of each minute not divisible by ten.
    if (seconds == 0 && frames < rate.dropsPerMinute() && minutes % 10 != 0) return std::nullopt;
    return Timecode(hours, minutes, seconds, frames, rate);
}

Timecode Timecode::fromFrameCount(int64_t count, TimecodeRate rate) {
    count = floorMod(count, rate.framesPerDay());
    const int64_t nominal = rate.nominal();
    const int64_t drops = rate.dropsPerMinute();
    if (drops > 0) {
        // Each ten minutes hold 9 dropping minutes; the first minute of the ten keeps all labels.
        const int64_t perTenMinutes = nominal * 600 - 9 * drops;
        const int64_t perMinute = nominal * 60 - drops;
        const int64_t tens = count / perTenMinutes;
        const int64_t rest = count % perTenMinutes;
        count += 9 * drops * tens;
        if (rest >= drops) count += drops * ((rest - drops) / perMinute);
    }
    const int64_t totalSeconds = count / nominal;
    return Timecode(int(totalSeconds / 3600), int(totalSeconds / 60 % 60), int(totalSeconds % 60),
                    int(count % nominal), rate);
}

Result<Timecode> Timecode::parse(std::string_view text, TimecodeRate rate) {
    const auto fail = [&](std::string_view why) {
        return makeError("timecode \"{}\" at {}: {} (expected HH:MM:SS:FF{})", text,
                         rate.toString(), why, rate.dropFrame() ? " or HH:MM:SS;FF" : "");
    };
    if (text.size() != 11) return fail("wrong length");
    bool dropSeparator = false;
    for (size_t at : {2, 5, 8}) {
        const char c = text[at];
        if (c == ';' || c == '.' || c == ',')
            dropSeparator = true;
        else if (c != ':')
            return fail("a separator is not ':' or ';'");
    }
    if (dropSeparator && !rate.dropFrame()) return fail("drop-frame separator at a non-drop rate");
    std::array<int, 4> fields{};
    for (int i = 0; i < 4; ++i) {
        const std::optional<int> value = twoDigits(text, size_t(i) * 3);
        if (!value) return fail("a field is not two digits");
        fields[size_t(i)] = *value;
    }
    const std::optional<Timecode> tc = fromFields(fields[0], fields[1], fields[2], fields[3], rate);
    if (!tc) return fail("a field is out of range or the label is one drop-frame skips");
    return *tc;
}

int64_t Timecode::frameCount() const {
    const int64_t totalMinutes = int64_t(hours_) * 60 + minutes_;
    const int64_t labels = (totalMinutes * 60 + seconds_) * rate_.nominal() + frames_;
    return labels - int64_t(rate_.dropsPerMinute()) * (totalMinutes - totalMinutes / 10);
}

std::string Timecode::toString() const {
    return fmt::format("{:02}:{:02}:{:02}{}{:02}", hours_, minutes_, seconds_,
                       rate_.dropFrame() ? ';' : ':', frames_);
}

Timecode clockTimecode(uint64_t wallClockNs, TimecodeRate rate) {
    const std::time_t seconds = std::time_t(wallClockNs / 1'000'000'000ull);
    const int64_t fractionNs = int64_t(wallClockNs % 1'000'000'000ull);
    std::tm local{};
    localtime_r(&seconds, &local);
    // A leap second (tm_sec 60) is held at :59.
    const int64_t secondOfDay =
        local.tm_hour * 3600 + local.tm_min * 60 + std::min(local.tm_sec, 59);
    if (!rate.dropFrame()) {
        const int frame = int(fractionNs * rate.nominal() / 1'000'000'000);
        return Timecode::fromFields(local.tm_hour, local.tm_min, std::min(local.tm_sec, 59), frame,
                                    rate)
            .value_or(Timecode(rate));
    }
    // ns of the day × num fits in int64 (8.64e13 × 60000 < 9.2e18).
    const int64_t nsOfDay = secondOfDay * 1'000'000'000 + fractionNs;
    return Timecode::fromFrameCount(nsOfDay * rate.num() / (int64_t(rate.den()) * 1'000'000'000),
                                    rate);
}

}  // namespace previs
