#include "capture/exposure_bracket.h"

#include <algorithm>
#include <cmath>

namespace previs {

Result<std::vector<int64_t>> planExposureSteps(const std::vector<float>& stops, int64_t base,
                                               const ControlRange& range, std::string_view device,
                                               std::string_view control) {
    if (base <= 0)
        return makeError(
            "camera {}: the bracket's base {} = {} is not positive; set the camera's exposure in "
            "its controls",
            device, control, base);
    const int64_t step = std::max<int64_t>(range.step, 1);
    std::vector<int64_t> values;
    for (float stop : stops) {
        const double ideal = double(base) * std::exp2(double(stop));
        // Rounded onto the control's grid (minimum + k·step), then kept inside the range.
        const double k = std::round((ideal - double(range.minimum)) / double(step));
        const int64_t value =
            std::clamp(range.minimum + int64_t(k) * step, range.minimum, range.maximum);
        const double reached = value > 0 ? std::log2(double(value) / double(base)) : -INFINITY;
        if (!(std::abs(reached - stop) <= kMaxStepErrorStops))
            return makeError(
                "camera {}: bracket stop {} needs {} = {:.4g} ({} × 2^{}), but the control takes "
                "{} to {} in steps of {} (the nearest, {}, is {:.2f} stops); move the base "
                "exposure in the camera's controls or narrow the bracket",
                device, stop, control, ideal, base, stop, range.minimum, range.maximum, step, value,
                reached);
        values.push_back(value);
    }
    return values;
}

ExposureCycle::ExposureCycle(size_t steps, int framesPerStep)
    : steps_(std::max<size_t>(steps, 1)),
      framesPerStep_(uint32_t(std::clamp(framesPerStep, 1, kMaxFramesPerStep))) {}

size_t ExposureCycle::start(uint64_t nowNs) {
    step_ = 0;
    anchored_ = false;
    setNs_ = nowNs;
    return step_;
}

ExposureCycle::Decision ExposureCycle::onFrame(uint32_t deviceSequence, uint64_t timestampNs,
                                               uint64_t nowNs) {
    if (!anchored_) {
        // The first frame after start(): step 0's control was set before streaming.
        anchored_ = true;
        anchorSeq_ = deviceSequence - 1;
        lastSeq_ = deviceSequence - 1;
    }
    if (deviceSequence != lastSeq_ + 1) {
        // A frame the driver dropped (or a sequence that jumped): the count no longer says which
        // exposure a frame has, so the cycle starts over from this frame.
        ++restarts_;
        ++settleFrames_;
        lastSeq_ = deviceSequence;
        anchorSeq_ = deviceSequence;
        step_ = 0;
        setNs_ = nowNs;
        return {std::nullopt, step_};
    }
    lastSeq_ = deviceSequence;
    if (deviceSequence - anchorSeq_ < framesPerStep_) {
        ++settleFrames_;
        return {};
    }
    if (timestampNs != 0 && timestampNs <= setNs_) {
        // Exposed before its control was even set: the capture thread is frames behind the
        // sensor, so the frames still queued are as suspect. Hold the step for another round.
        ++extended_;
        ++settleFrames_;
        anchorSeq_ = deviceSequence;
        return {};
    }
    Decision decision;
    decision.label = step_;
    step_ = (step_ + 1) % steps_;
    decision.set = step_;
    anchorSeq_ = deviceSequence;
    setNs_ = nowNs;
    return decision;
}

std::optional<float> exposureStopsFromMetadata(const std::vector<float>& stops,
                                               std::optional<double> exposureUs,
                                               std::optional<double> analogueGain,
                                               double baseExposureUs, double baseAnalogueGain) {
    if (!exposureUs || !analogueGain || !(*exposureUs > 0.0) || !(*analogueGain > 0.0) ||
        !(baseExposureUs > 0.0) || !(baseAnalogueGain > 0.0))
        return std::nullopt;
    const double measured =
        std::log2((*exposureUs * *analogueGain) / (baseExposureUs * baseAnalogueGain));
    if (!std::isfinite(measured)) return std::nullopt;
    for (float stop : stops)
        if (std::abs(measured - stop) <= kMaxStepErrorStops) return stop;
    return float(measured);
}

}  // namespace previs
