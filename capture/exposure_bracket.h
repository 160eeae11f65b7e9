#pragma once

// Live exposure bracketing (DESIGN.md §4, "Light capture is HDR"): a camera cycled through a set
// of exposures, each delivered frame labelled with the exposure it was taken at
// (Frame::exposureStops), so vision/hdr_bracket.h can check and merge complete brackets.
//
// How a frame's exposure is identified depends on the camera:
// - V4L2: a control (exposure_time_absolute by default) is set to base·2^stop and lands a few
//   frames late, at a delay no API reports. Each exposure is held for framesPerStep frames; the
//   first framesPerStep − 1 are the control landing and are withheld (never delivered, so they
//   are neither lit from nor recorded), the last is delivered labelled. The label is what the
//   control was set to, an assumption the assembler then checks against the pictures.
// - libcamera: every request carries its step's ExposureTime, and each completed request's
//   metadata says what the sensor actually used, so each frame is labelled with that.
// The logic here needs no device, so the tests run it on the host.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "base/result.h"

namespace previs {

struct ExposureBracketConfig {
    // The exposures in stops from the camera's configured (calibrated) one, in cycle order.
    std::vector<float> stops;
    // V4L2 only: frames each exposure is held for (1 = the control lands on the very next
    // frame); libcamera labels from metadata and needs no settling.
    int framesPerStep = 3;
    // V4L2 only: the control cycled (any name V4L2Device::setControl takes). Its value in the
    // camera's `controls` is the base exposure; it must scale the light linearly (an exposure
    // time in any unit, a linear gain).
    std::string control = "exposure_time_absolute";
};

// Most frames a V4L2 step may be held: at 5 fps, 8 frames keep the delivered frames closer
// together than CaptureOptions::stallTimeoutMs.
constexpr int kMaxFramesPerStep = 8;

// An integer control (or a sensor's exposure quantum) reaches base·2^stop only approximately.
// Within this many stops the frame is labelled with the configured stop: 0.1 stops is a 7 %
// error in that frame's radiance, below what the assembler's picture check resolves (its
// default tolerance is 0.5 stops). A stop the control cannot reach this closely is refused.
constexpr float kMaxStepErrorStops = 0.1f;

// A V4L2 integer control's range, as VIDIOC_QUERY_EXT_CTRL reports it.
struct ControlRange {
    int64_t minimum = 0;
    int64_t maximum = 0;
    int64_t step = 1;
};

// The control value for each stop: base·2^stop rounded to the control's step. Fails, naming
// `device`, the control, the base and the range, when a stop is outside the range or not
// reachable within kMaxStepErrorStops (a short stop from a small base: raise the base).
Result<std::vector<int64_t>> planExposureSteps(const std::vector<float>& stops, int64_t base,
                                               const ControlRange& range, std::string_view device,
                                               std::string_view control);

// Which V4L2 frames carry which exposure, and when to set the next. The control of step k is set
// right after the frame that ended step k − 1 was dequeued; the frames counted from there by
// the driver's sequence number are the step's, and the framesPerStep-th is labelled.
//
// Two things shift frames against the count, and both restart or extend the step rather than
// risk a wrong label: a gap in the driver's sequence (a frame the driver dropped) restarts the
// cycle at step 0, and a frame at the label's place whose timestamp is not later than the
// moment the control was set (the capture thread had fallen behind, the frame was exposed
// before the change) extends the step by another framesPerStep frames.
class ExposureCycle {
public:
    ExposureCycle(size_t steps, int framesPerStep);

    struct Decision {
        // The frame shows this step's exposure: deliver it labelled. Unset: withhold it.
        std::optional<size_t> label;
        // Set this step's control now (before handling the next frame).
        std::optional<size_t> set;
    };

    // The step whose control must be set before streaming starts (always 0); `nowNs`
    // (CLOCK_MONOTONIC) is when it was set. Also restarts the cycle after a reopen.
    size_t start(uint64_t nowNs);
    // One dequeued frame, good or not (a corrupt frame still took its place in the sequence):
    // the driver's sequence, its CLOCK_MONOTONIC timestamp (0 = not on that clock: not
    // compared) and the time now. After a `set`, the caller sets that step's control at once.
    Decision onFrame(uint32_t deviceSequence, uint64_t timestampNs, uint64_t nowNs);

    size_t step() const { return step_; }
    // Frames withheld while a control landed, cycle restarts (sequence gaps) and steps extended
    // because a frame predated its control: for the log and the status.
    uint64_t settleFrames() const { return settleFrames_; }
    uint64_t restarts() const { return restarts_; }
    uint64_t extended() const { return extended_; }

private:
    size_t steps_;
    uint32_t framesPerStep_;
    size_t step_ = 0;
    bool anchored_ = false;   // the first frame after start() has been seen
    uint32_t anchorSeq_ = 0;  // the last frame before the current step's control was set
    uint32_t lastSeq_ = 0;
    uint64_t setNs_ = 0;  // when the current step's control was set
    uint64_t settleFrames_ = 0;
    uint64_t restarts_ = 0;
    uint64_t extended_ = 0;
};

// libcamera: a frame's exposure in stops from its request's metadata, exposure·gain against the
// base exposure·gain. Within kMaxStepErrorStops of a configured stop it is that stop (the sensor
// quantises exposure to its line time); otherwise the measured value, which the assembler
// rejects as not the bracket's next exposure. Unset when either metadata value is missing or
// not positive: a frame whose exposure is not reported is never labelled.
std::optional<float> exposureStopsFromMetadata(const std::vector<float>& stops,
                                               std::optional<double> exposureUs,
                                               std::optional<double> analogueGain,
                                               double baseExposureUs, double baseAnalogueGain);

}  // namespace previs
