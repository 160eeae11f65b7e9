#pragma once

// `previs bench --only denoise`: what the denoiser (render/denoiser.h) costs and buys on the
// bunny on a real floor (differential, environment light): its GPU time per kernel at 213×160,
// 320×240 and 640×480; RMSE and time per strength (iterations 0..5) at the dial's preview point;
// the RMSE and relMSE of the composite against a long reference with and without it at 1, 4, 16
// and 64 spp; and a camera pan's per-frame RMSE without, with spatial and with temporal +
// spatial denoising.

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
