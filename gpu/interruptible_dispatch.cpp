#include "gpu/interruptible_dispatch.h"

#include <algorithm>
#include <chrono>

namespace previs {

Result<double> InterruptibleDispatch::run(ComputePipeline& pipeline, uint32_t groupsX,
                                          uint32_t groupsY, const std::atomic<bool>& stop) {
    const bool alongY = groupsY > 1;
    const uint32_t lines = alongY ? groupsY : groupsX;  // the axis the parts split
    const uint32_t groupsPerLine = alongY ? groupsX : 1;
    double gpuMs = 0.0;
    for (uint32_t first = 0; first < lines;) {
        if (stop.load()) return makeError("{}", kDispatchInterrupted);
        // Until a part was timed, the first is one line: on a slow device a guess of more could
        // be the whole stop's wait.
        uint32_t count = 1;
        if (msPerGroup_ > 0.0)
            count = uint32_t(
                std::clamp(partMs_ / (msPerGroup_ * groupsPerLine), 1.0, double(lines - first)));
        const auto start = std::chrono::steady_clock::now();
        auto ms = alongY ? pipeline.dispatchPart(0, first, groupsX, count)
                         : pipeline.dispatchPart(first, 0, count, 1);
        if (!ms) return ms.error();
        gpuMs += ms.value();
        const double wallMs =
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                .count();
        msPerGroup_ = wallMs / double(count * groupsPerLine);
        first += count;
    }
    return gpuMs;
}

}  // namespace previs
