#pragma once

// `previs bench --only denoise`: what the denoiser (render/denoiser.h) costs and buys on the
// bunny on a real floor (differential, environment light): its time at 640×480, and the RMSE and
// relMSE of the composite against a long reference with and without it at 1, 4, 16 and 64 spp.

#include <cstdint>
#include <string>

#include "gpu/context.h"

namespace previs::bench {

struct DenoiseBenchOptions {
    std::string dataDir;
    bool quick = false;
    int repetitions = 3;  // seeds of the error curves; timings are medians over this many runs
};

int runDenoiseBench(GpuContext& ctx, const DenoiseBenchOptions& options);

}  // namespace previs::bench
