#pragma once

// Edge-avoiding à-trous wavelet denoiser (gpu/shaders/denoise.comp; Dammertz et al. 2010 with
// SVGF's weights, Schied et al. 2017) for the renderer's accumulated signals. The renderer
// applies it to the composite *without* the plate term — M·L_om + (1−M)(L_om − L_or) — or to
// L_om or L_or, never to the camera image (Renderer::image(Aov, bool)).

#include <array>
#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <span>
#include <vector>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/compute_pipeline.h"
#include "gpu/context.h"
#include "gpu/shaders/shared/denoise.h"
#include "image/image.h"
#include "render/render_settings.h"

namespace previs {

// The pinhole camera of a frame, for temporal reprojection (Renderer::denoiseCamera): the
// camera's pose (looks along −Z, +Y up; double, as Renderer::setCameraPose takes it) and tan of
// the half field of view in x and y. A calibrated lens grid is approximated by this pinhole
// (bench/results/benchmarks_2026-11-28.md, "Issue 10: denoiser", says what that costs).
struct DenoiseCamera {
    glm::dmat4 worldFromCamera{1.0};
    glm::vec2 tanHalfFov{1.0f};
};

class Denoiser {
public:
    static Result<Denoiser> create(GpuContext& ctx, uint32_t width, uint32_t height,
                                   const DenoiseSettings& settings = {});
    // The pipelines create() compiles: denoise.comp's four stages.
    static constexpr size_t kPipelineCount = 4;

    Denoiser(Denoiser&&) = default;
    Denoiser& operator=(Denoiser&&) = default;

    // Filters `signal` (RGB, width × height) guided by `guides` (PV_GUIDE_COUNT vec4 per pixel,
    // shared/denoise.h: albedo and depth, normal; the moments are not read). `variance` is per
    // pixel the variance of the luminance of the pixel's mean, or negative where unknown (the
    // shader then estimates it from the neighbourhood); empty: unknown everywhere.
    Result<ImageF> apply(const ImageF& signal, std::span<const glm::vec4> guides,
                         std::span<const float> variance);

    // The same with SVGF's temporal accumulation first (preview): the previous call's history,
    // reprojected from its camera to `now` through the guides' depth, is kept where depth,
    // normal and mask agree (else the pixel starts afresh; a pixel's own history, when the
    // reprojection moves it under half a pixel, is kept whatever its guides: at an outline they
    // change with which surface a frame's samples hit), blended with this frame with weight
    // max(α, 1/(history + 1)), and the blend's variance (shader: "temporal") sets the spatial
    // filter's luminance tolerance. The depth must be the distance along the pixel centre's ray
    // of a pinhole camera `now`. apply() calls in between leave the history alone.
    Result<ImageF> applyTemporal(const ImageF& signal, std::span<const glm::vec4> guides,
                                 std::span<const float> variance, const DenoiseCamera& now);
    // The same for a signal already on the device, leaving the result there: the caller has
    // written colourInput() (per pixel the signal's RGB and the variance of its mean's luminance
    // in w, negative where unknown), `guides` is the path tracer's own buffer (layout as above),
    // and output() holds the filtered signal (vec4 per pixel, w the mask as lastMask() says).
    // `now`: through the temporal stage, as applyTemporal; null: as apply.
    Status filter(const GpuBuffer& guides, const DenoiseCamera* now);
    // The mask M that goes with the last apply()'s or applyTemporal()'s output, per pixel: after a
    // temporal stage the history's mean of it, which the composite's plate term needs beside the
    // history's mean of the signal (shared/denoise.h); else the guides' own, the mean over the
    // same samples as the accumulation's (the path tracer adds both from each kept sample).
    std::span<const float> lastMask() const { return lastMask_; }
    GpuBuffer& colourInput() { return buffers_[PV_DENOISE_BINDING_COLOR]; }
    const GpuBuffer& output() const { return buffers_[PV_DENOISE_BINDING_OUTPUT]; }

    // Forget the history: the next applyTemporal() starts afresh (mode switch, refinement start,
    // scene or resolution change).
    void resetHistory() {
        historyValid_ = false;
        historyFrames_ = 0;
    }
    // Frames in the history after the last applyTemporal() (0 after resetHistory()).
    uint32_t historyFrames() const { return historyFrames_; }

    // GPU time of the last apply()'s dispatches (ms; 0 without timestamps).
    double lastGpuMilliseconds() const { return lastGpuMs_; }
    const DenoiseSettings& settings() const { return settings_; }
    // New settings for the next calls (the dial's strength); out of range: an error, no change.
    Status setSettings(const DenoiseSettings& settings);
    uint32_t width() const { return width_; }
    uint64_t deviceBytes() const {
        uint64_t total = 0;
        for (const GpuBuffer& b : buffers_) total += b.size();
        return total;
    }
    uint32_t height() const { return height_; }

private:
    Denoiser() = default;
    Status dispatch(ComputePipeline& pipeline);
    // The buffer at `binding` at least `perPixel` bytes per pixel (made anew, and bound with the
    // next bindGuides, when smaller): what only some uses need is made on first use (create()).
    Status ensureSize(int binding, size_t perPixel, const char* label);
    // Binds `guides` (the denoiser's own buffer, or the path tracer's) unless it is bound.
    Status bindGuides(const GpuBuffer& guides);
    Result<ImageF> run(const ImageF& signal, std::span<const glm::vec4> guides,
                       std::span<const float> variance, const DenoiseCamera* now);

    uint32_t width_ = 0;
    uint32_t height_ = 0;
    DenoiseSettings settings_;
    double lastGpuMs_ = 0.0;
    std::vector<float> lastMask_;
    // Temporal state: the packed-guide image and history image holding the previous frame, and
    // its camera.
    uint32_t prevPacked_ = 1;
    uint32_t historyIn_ = 0;
    bool historyValid_ = false;
    uint32_t historyFrames_ = 0;
    DenoiseCamera prevCamera_;
    // Buffers in PV_DENOISE_BINDING_* order, then the pipelines that bind them.
    std::vector<GpuBuffer> buffers_;
    GpuContext* ctx_ = nullptr;
    std::array<const GpuBuffer*, PV_DENOISE_BINDING_COUNT> bound_{};  // own buffers per binding
    uint64_t boundGuides_ = 0;                                        // GpuBuffer::id
    std::optional<ComputePipeline> prepare_;
    std::optional<ComputePipeline> temporal_;
    std::optional<ComputePipeline> atrous_;
    std::optional<ComputePipeline> finish_;
};

}  // namespace previs
