#pragma once

// The held view (render/held_view.h) following a moving camera: the samples kept per output pixel
// move to where their surface lies in the new camera's image, with the nearest surface hiding the
// others (gpu/shaders/held_reprojection.comp), and fade by a weight per move, so the output's
// resolution keeps a history while the camera pans as well as while it holds. Each pixel's
// samples carry their mean first-hit distance (PV_BINDING_HELD_SAMPLES), which places them; the
// cameras are pinholes (a calibrated lens grid approximated, as the denoiser's reprojection does:
// between two frames a point moves a few pixels, over which the lens's distortion barely
// changes).

#include <cstdint>
#include <optional>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/compute_pipeline.h"
#include "gpu/context.h"
#include "gpu/shaders/shared/held_reprojection_params.h"
#include "render/denoiser.h"

namespace previs {

// The reprojection's parameters from camera `from` to camera `to` at an output of width × height,
// the moved samples weighted by `keep`.
shader::ReprojectParams reprojectParams(const DenoiseCamera& from, const DenoiseCamera& to,
                                        uint32_t width, uint32_t height, float keep);

class HeldReprojection {
public:
    static Result<HeldReprojection> create(GpuContext& ctx, uint32_t width, uint32_t height);

    HeldReprojection(HeldReprojection&&) = default;
    HeldReprojection& operator=(HeldReprojection&&) = default;

    // Moves `held` (width × height pixels in PV_BINDING_HELD_SAMPLES' layout) as `params` say:
    // the moved samples are written to a second buffer, which is then swapped with `held` (no
    // copy; whoever binds `held` sees a new buffer id).
    Status run(GpuBuffer& held, const shader::ReprojectParams& params);
    // Bytes of device memory it holds: the second buffer and the landing distances.
    uint64_t deviceBytes() const;

private:
    HeldReprojection() = default;
    uint32_t width_ = 0;
    uint32_t height_ = 0;
    std::optional<GpuBuffer> params_;
    std::optional<GpuBuffer> spare_;
    std::optional<GpuBuffer> nearest_;
    std::optional<ComputePipeline> claim_;
    std::optional<ComputePipeline> move_;
};

}  // namespace previs
