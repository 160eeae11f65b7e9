#pragma once

// A dispatch cut into parts so that a stop request waits for one part, not a whole pass. A
// Vulkan dispatch cannot be abandoned once submitted, and on a slow device one frame's dispatch
// is long: lavapipe under the test VM's emulated CPU takes about 50 s for one sample of a
// 320×180 preview, longer than a service may take to stop. The parts are sized from the time the
// last part took, so a fast device runs each pass in one part and pays one flag check.
// Splitting changes no result: each workgroup computes what it computes in a whole dispatch.

#include <atomic>
#include <cstdint>

#include "base/result.h"
#include "gpu/compute_pipeline.h"

namespace previs {

class InterruptibleDispatch {
public:
    // Each part aims at `partMs` of wall time.
    explicit InterruptibleDispatch(double partMs) : partMs_(partMs) {}

    // Dispatches groupsX × groupsY workgroups of `pipeline` in parts, along Y (along X when
    // groupsY is 1), and checks `stop` before each part. Returns the GPU time in milliseconds,
    // or an error saying the pass was interrupted once `stop` is set; the pass's output is then
    // incomplete.
    Result<double> run(ComputePipeline& pipeline, uint32_t groupsX, uint32_t groupsY,
                       const std::atomic<bool>& stop);

private:
    double partMs_;
    double msPerGroup_ = 0.0;  // measured on the last part; 0 until one ran
};

// The part size the renderer uses: a stop waits about this long for the pass it interrupts.
inline constexpr double kInterruptiblePartMs = 250.0;

// The message run() returns when it was interrupted.
inline constexpr const char* kDispatchInterrupted = "the GPU pass was interrupted by a stop";

}  // namespace previs
