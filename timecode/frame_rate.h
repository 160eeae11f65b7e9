#pragma once

// The rate a camera's frames come at, measured from their capture timestamps when no config
// says it (issue 54): the median per-frame interval over a window of recent frames (a frame the
// consumer skipped counts by its sequence number, so a slow tracker or refinement's pacing does
// not halve the rate), snapped to a standard rate within kSnapTolerance. One owner a meter; not
// thread-safe.

#include <cstdint>
#include <deque>
#include <optional>

namespace previs {

// An exact frame rate num/den: 15/1, 30000/1001.
struct FrameRate {
    uint32_t num = 0;
    uint32_t den = 1;
    double fps() const { return double(num) / den; }
    bool operator==(const FrameRate&) const = default;
};

// Relative distance within which a measured rate is taken for a standard one.
constexpr double kSnapTolerance = 0.005;

// The standard rate (10, 12, 12.5, 15, 20, 23.976, 24, 25, 29.97, 30, 48, 50, 59.94, 60, 72, 90,
// 100, 119.88, 120) within kSnapTolerance of `fps`, else `fps` in thousandths.
FrameRate snapFrameRate(double fps);

class FrameRateMeter {
public:
    static constexpr size_t kWindow = 31;  // intervals: two seconds at 15 fps

    // A frame captured at `timestampNs`, the `sequence`-th its camera delivered. A timestamp or
    // sequence that does not increase (a replay looping, a second caller asking for the same
    // frame) adds no interval; a gap of more than 8 frames neither.
    void add(int64_t timestampNs, uint64_t sequence);
    // The snapped rate of the window; nothing before the first interval.
    std::optional<FrameRate> rate() const;

private:
    std::deque<int64_t> intervalsNs_;  // per frame, newest last
    std::optional<int64_t> lastNs_;
    uint64_t lastSequence_ = 0;
};

}  // namespace previs
