#include "render/denoiser.h"

#include <array>

#include "denoise.spv.h"
#include "shared/denoise.h"

namespace previs {

Result<Denoiser> Denoiser::create(GpuContext& ctx, uint32_t width, uint32_t height,
                                  const DenoiseSettings& settings) {
    if (width == 0 || height == 0)
        return makeError("denoiser image size {}x{} is empty", width, height);
    if (settings.iterations == 0 || settings.iterations > 10 || !(settings.sigmaLuminance > 0.0f) ||
        !(settings.sigmaNormal >= 0.0f) || !(settings.sigmaDepth > 0.0f) ||
        !(settings.sigmaMask >= 0.0f))
        return makeError(
            "denoiser settings out of range ({} iterations, sigma luminance {}, normal {}, "
            "depth {}, mask {}): iterations 1..10, sigmas > 0 (normal and mask >= 0)",
            settings.iterations, settings.sigmaLuminance, settings.sigmaNormal, settings.sigmaDepth,
            settings.sigmaMask);
    Denoiser d;
    d.width_ = width;
    d.height_ = height;
    d.settings_ = settings;
    const size_t pixels = size_t(width) * height;
    // Bindings 0..4; the work buffer is bound again as PV_DENOISE_BINDING_WORK_TEXELS.
    const size_t sizes[PV_DENOISE_BINDING_WORK_TEXELS] = {
        sizeof(shader::DenoiseParams), pixels * sizeof(glm::vec4),
        pixels * PV_GUIDE_COUNT * sizeof(glm::vec4), 3 * pixels * sizeof(glm::vec4),
        pixels * sizeof(glm::vec4)};
    const char* labels[PV_DENOISE_BINDING_WORK_TEXELS] = {
        "denoiseParams", "denoiseColor", "denoiseGuides", "denoiseWork", "denoiseOutput"};
    for (int b = 0; b < PV_DENOISE_BINDING_WORK_TEXELS; ++b) {
        auto buffer = GpuBuffer::create(ctx, sizes[b], labels[b]);
        if (!buffer) return buffer.error();
        d.buffers_.push_back(std::move(buffer.value()));
    }
    std::vector<const GpuBuffer*> bound;
    for (const GpuBuffer& b : d.buffers_) bound.push_back(&b);
    bound.push_back(&d.buffers_[PV_DENOISE_BINDING_WORK]);
    std::array<BindingKind, PV_DENOISE_BINDING_COUNT> kinds{};
    kinds.fill(BindingKind::StorageBuffer);
    for (int b :
         {PV_DENOISE_BINDING_COLOR, PV_DENOISE_BINDING_GUIDES, PV_DENOISE_BINDING_WORK_TEXELS})
        kinds[b] = BindingKind::TexelBufferUint4;
    auto make = [&](uint32_t stage, std::optional<ComputePipeline>& out) -> Status {
        const std::array<uint32_t, 1> constants{stage};
        auto p = ComputePipeline::create(
            ctx, std::span<const uint32_t>(denoise_spv, sizeof(denoise_spv) / 4), kinds, constants,
            "denoise");
        if (!p) return p.error();
        out.emplace(std::move(p.value()));
        return out->bind(bound);
    };
    if (Status s = make(PV_DENOISE_STAGE_PREPARE, d.prepare_); !s) return s.error();
    if (Status s = make(PV_DENOISE_STAGE_ATROUS, d.atrous_); !s) return s.error();
    if (Status s = make(PV_DENOISE_STAGE_FINISH, d.finish_); !s) return s.error();
    return d;
}

Status Denoiser::dispatch(ComputePipeline& pipeline) {
    auto ms = pipeline.dispatch((width_ + PV_DENOISE_GROUP_SIZE - 1) / PV_DENOISE_GROUP_SIZE,
                                (height_ + PV_DENOISE_GROUP_SIZE - 1) / PV_DENOISE_GROUP_SIZE);
    if (!ms) return ms.error();
    lastGpuMs_ += ms.value();
    return {};
}

Result<ImageF> Denoiser::apply(const ImageF& signal, std::span<const glm::vec4> guides,
                               std::span<const float> variance) {
    const size_t pixels = size_t(width_) * height_;
    if (signal.width != width_ || signal.height != height_ || signal.channels != 3 ||
        signal.pixels.size() != pixels * 3 || guides.size() != pixels * PV_GUIDE_COUNT ||
        (!variance.empty() && variance.size() != pixels))
        return makeError(
            "denoiser input is {}x{} with {} channel(s), {} guide texels and {} variances; the "
            "denoiser is {}x{} and needs RGB, {} guide texels per pixel and 0 or 1 variance "
            "per pixel",
            signal.width, signal.height, signal.channels, guides.size(), variance.size(), width_,
            height_, PV_GUIDE_COUNT);
    lastGpuMs_ = 0.0;
    std::vector<glm::vec4> color(pixels);
    for (size_t i = 0; i < pixels; ++i)
        color[i] = glm::vec4(signal.pixels[3 * i], signal.pixels[3 * i + 1],
                             signal.pixels[3 * i + 2], variance.empty() ? -1.0f : variance[i]);
    if (Status s =
            buffers_[PV_DENOISE_BINDING_COLOR].upload(color.data(), pixels * sizeof(glm::vec4));
        !s)
        return s.error();
    if (Status s = buffers_[PV_DENOISE_BINDING_GUIDES].upload(guides.data(), guides.size_bytes());
        !s)
        return s.error();
    shader::DenoiseParams params{};
    params.width = width_;
    params.height = height_;
    params.sigmaLuminance = settings_.sigmaLuminance;
    params.sigmaNormal = settings_.sigmaNormal;
    params.sigmaDepth = settings_.sigmaDepth;
    params.sigmaMask = settings_.sigmaMask;
    GpuBuffer& paramsBuffer = buffers_[PV_DENOISE_BINDING_PARAMS];
    // Dispatches wait for completion (ComputePipeline::dispatch), so each iteration's parameters
    // can be uploaded into the one buffer between them.
    if (Status s = paramsBuffer.upload(&params, sizeof(params)); !s) return s.error();
    if (Status s = dispatch(*prepare_); !s) return s.error();
    for (uint32_t i = 0; i < settings_.iterations; ++i) {
        params.stepPx = 1u << i;
        params.inImage = i == 0 ? 0u : 1u + (i + 1) % 2;
        params.outImage = 1u + i % 2;
        if (Status s = paramsBuffer.upload(&params, sizeof(params)); !s) return s.error();
        if (Status s = dispatch(*atrous_); !s) return s.error();
    }
    params.inImage = params.outImage;
    if (Status s = paramsBuffer.upload(&params, sizeof(params)); !s) return s.error();
    if (Status s = dispatch(*finish_); !s) return s.error();
    if (Status s =
            buffers_[PV_DENOISE_BINDING_OUTPUT].download(color.data(), pixels * sizeof(glm::vec4));
        !s)
        return s.error();
    ImageF out;
    out.width = width_;
    out.height = height_;
    out.channels = 3;
    out.pixels.resize(pixels * 3);
    for (size_t i = 0; i < pixels; ++i)
        for (int c = 0; c < 3; ++c) out.pixels[3 * i + c] = color[i][c];
    return out;
}

}  // namespace previs
