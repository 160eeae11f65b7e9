#pragma once

// The preview's last step on the device (gpu/shaders/film_display.comp): the traced estimate
// upsampled to the output guided by the plate, the held view's samples blended in, Eq. 1 with
// the plate, the tone curve and the 8-bit sRGB encode, so one 8-bit frame comes back instead of
// float accumulations composited and tone mapped on the host. The film (render/film.h) owns one,
// made when the first display frame is asked for.

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/compute_pipeline.h"
#include "gpu/context.h"
#include "gpu/shaders/shared/composite.h"
#include "image/image.h"
#include "render/tonemap.h"
#include "render/upsample.h"

namespace previs {

// How the composite becomes display values: the white balance the plate's inverse applied
// (undone before the curve, per channel) and the curve with its exposure.
struct DisplaySettings {
    ToneMapSettings tone;
    std::array<float, 3> whiteBalance{1.0f, 1.0f, 1.0f};
    // [output.colour]'s display and view baked to viewLutSize³ RGB nodes (colour/
    // ocio_colour.h's DisplayColourTransform::lut, which says how it is applied), in place of
    // the curve and the sRGB encode; the exposure and the white balance still apply first. Null:
    // the curve. The device only: toDisplayImage knows the curve alone.
    std::shared_ptr<const std::vector<float>> viewLut{};
    uint32_t viewLutSize = 0;
};

// An 8-bit sRGB frame, RGB interleaved.
struct DisplayImage {
    uint32_t width = 0;
    uint32_t height = 0;
    std::vector<uint8_t> rgb;
};

// The host's version of the same frame from a float composite (render/film.h's image()).
DisplayImage toDisplayImage(ImageF composite, const DisplaySettings& settings);

class DisplayPass {
public:
    static Result<DisplayPass> create(GpuContext& ctx, uint32_t width, uint32_t height);

    DisplayPass(DisplayPass&&) = default;
    DisplayPass& operator=(DisplayPass&&) = default;

    // What a frame is made of, all on the device but the plate. `plate`: RGB (≥ 3 channels) at
    // the output size, uploaded only when `plateVersion` differs from the last call's. The path
    // tracer's accumulation at the traced size (`sum`, `compensation`: PV_BINDING_ACCUM_*) and,
    // for a denoised frame, its guides. `held`: the held view's samples at the output size
    // (PV_BINDING_HELD_SAMPLES), or null. `signal`: the denoiser's input buffer writeSignal
    // fills; `denoised`: its output, which run() then takes for the estimate (RGB the filtered
    // signal, A the mask's mean that goes with it; null: the means).
    struct Inputs {
        const ImageF* plate = nullptr;
        uint64_t plateVersion = 0;
        const GpuBuffer* sum = nullptr;
        const GpuBuffer* compensation = nullptr;
        uint32_t traceWidth = 0;
        uint32_t traceHeight = 0;
        const GpuBuffer* held = nullptr;
        float heldEstimateSamples = 0.0f;  // what the estimate counts as beside them
        bool heldOutlineTest = false;      // ... after the test of its outline (heldBlend)
        const GpuBuffer* guides = nullptr;
        GpuBuffer* signal = nullptr;
        const GpuBuffer* denoised = nullptr;
    };
    // Writes the denoiser's input (Denoiser::colourInput: the mean of Eq. 1's plate-free part
    // and the variance of its luminance) from the accumulation and the guides' moments.
    Status writeSignal(const Inputs& in);
    // The frame, 8-bit, read back.
    Result<DisplayImage> run(const Inputs& in, const UpsampleSettings& upsample,
                             const DisplaySettings& settings);

    uint64_t deviceBytes() const;

private:
    DisplayPass() = default;
    Status sizeTrace(uint32_t traceWidth, uint32_t traceHeight);
    Status uploadPlate(const ImageF& plate, uint64_t plateVersion);
    // The view's table, uploaded when it is not the one the device holds.
    Status uploadView(const DisplaySettings& settings);
    // Binds what changed since the last frame (buffers are compared by GpuBuffer::id).
    Status bind(const Inputs& in);
    shader::FilmParams params(const Inputs& in, const UpsampleSettings& upsample,
                              const DisplaySettings& settings) const;

    GpuContext* ctx_ = nullptr;
    uint32_t width_ = 0;
    uint32_t height_ = 0;
    uint32_t traceWidth_ = 0;
    uint32_t traceHeight_ = 0;
    std::optional<uint64_t> plateVersion_;
    std::shared_ptr<const std::vector<float>> viewUploaded_;
    float plateMean_ = 0.0f;
    // GpuBuffer::id of the inputs bound last: held, sum, compensation, guides, signal, denoised.
    std::array<uint64_t, 6> bound_{};
    std::optional<GpuBuffer> params_, plate_, estimate_, lowGuide_, thresholds_, output_, none_,
        viewLut_;
    std::optional<ComputePipeline> signalStage_, estimateStage_, guide_, resolve_;
};

}  // namespace previs
