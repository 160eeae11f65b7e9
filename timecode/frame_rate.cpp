#include "timecode/frame_rate.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

namespace previs {

namespace {

constexpr std::array<FrameRate, 19> kStandardRates{{
    {10, 1}, {12, 1},       {25, 2},  {15, 1},        {20, 1},  {24000, 1001}, {24, 1},
    {25, 1}, {30000, 1001}, {30, 1},  {48, 1},        {50, 1},  {60000, 1001}, {60, 1},
    {72, 1}, {90, 1},       {100, 1}, {120000, 1001}, {120, 1},
}};

constexpr uint64_t kLongestGapFrames = 8;

}  // namespace

FrameRate snapFrameRate(double fps) {
    if (!(fps > 0.0)) return {};
    const FrameRate* best = nullptr;
    for (const FrameRate& r : kStandardRates) {
        const double off = std::abs(r.fps() - fps) / r.fps();
        if (off <= kSnapTolerance && (!best || off < std::abs(best->fps() - fps) / best->fps()))
            best = &r;
    }
    if (best) return *best;
    return {uint32_t(std::lround(std::min(fps, 1e6) * 1000.0)), 1000};
}

void FrameRateMeter::add(int64_t timestampNs, uint64_t sequence) {
    const bool after = lastNs_ && timestampNs > *lastNs_ && sequence > lastSequence_;
    if (lastNs_ && !after && sequence <= lastSequence_ && timestampNs <= *lastNs_) return;
    if (after && sequence - lastSequence_ <= kLongestGapFrames) {
        intervalsNs_.push_back((timestampNs - *lastNs_) / int64_t(sequence - lastSequence_));
        if (intervalsNs_.size() > kWindow) intervalsNs_.pop_front();
    }
    lastNs_ = timestampNs;
    lastSequence_ = sequence;
}

std::optional<FrameRate> FrameRateMeter::rate() const {
    if (intervalsNs_.empty()) return std::nullopt;
    std::vector<int64_t> sorted(intervalsNs_.begin(), intervalsNs_.end());
    const auto middle = sorted.begin() + ptrdiff_t(sorted.size() / 2);
    std::nth_element(sorted.begin(), middle, sorted.end());
    if (*middle <= 0) return std::nullopt;
    return snapFrameRate(1e9 / double(*middle));
}

}  // namespace previs
