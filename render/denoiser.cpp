#include "render/denoiser.h"

#include <array>
#include <iterator>

#include "denoise.spv.h"
#include "gpu/shaders/shared/denoise.h"

namespace previs {

namespace {

Status validate(const DenoiseSettings& settings) {
    if (settings.iterations > 10 || settings.kernelRadius < 1 || settings.kernelRadius > 2 ||
        !(settings.sigmaLuminance > 0.0f) || !(settings.sigmaNormal >= 0.0f) ||
        !(settings.sigmaDepth > 0.0f) || !(settings.sigmaMask >= 0.0f) ||
        !(settings.temporalAlpha > 0.0f && settings.temporalAlpha <= 1.0f) ||
        !(settings.maxHistoryFrames >= 1.0f))
        return makeError(
            "denoiser settings out of range ({} iterations, kernel radius {}, sigma luminance "
            "{}, normal {}, depth {}, mask {}, temporal alpha {}, history {}): iterations 0..10, "
            "radius 1 or 2, sigmas > 0 (normal and mask >= 0), alpha in (0, 1], history >= 1",
            settings.iterations, settings.kernelRadius, settings.sigmaLuminance,
            settings.sigmaNormal, settings.sigmaDepth, settings.sigmaMask, settings.temporalAlpha,
            settings.maxHistoryFrames);
    return {};
}

}  // namespace

Result<Denoiser> Denoiser::create(GpuContext& ctx, uint32_t width, uint32_t height,
                                  const DenoiseSettings& settings) {
    if (width == 0 || height == 0)
        return makeError("denoiser image size {}x{} is empty", width, height);
    if (Status s = validate(settings); !s) return s.error();
    Denoiser d;
    d.width_ = width;
    d.height_ = height;
    d.settings_ = settings;
    const size_t pixels = size_t(width) * height;
    // Every binding owns its buffer except the *_TEXELS ones, which view the buffer before them.
    struct Owned {
        int binding;
        size_t bytes;
        const char* label;
    };
    const Owned owned[] = {
        {PV_DENOISE_BINDING_PARAMS, sizeof(shader::DenoiseParams), "denoiseParams"},
        {PV_DENOISE_BINDING_COLOR, pixels * sizeof(glm::vec4), "denoiseColor"},
        // Guides of its own only for apply()/applyTemporal() (the service filters with the path
        // tracer's), the temporal image and the history only for the temporal stage (refinement
        // filters at full resolution without it): placeholders until first needed (ensureSize).
        {PV_DENOISE_BINDING_GUIDES, PV_GUIDE_COUNT * sizeof(glm::vec4), "denoiseGuides"},
        {PV_DENOISE_BINDING_WORK, (PV_DENOISE_WORK_IMAGES - 1) * pixels * sizeof(glm::vec4),
         "denoiseWork"},
        {PV_DENOISE_BINDING_OUTPUT, pixels * sizeof(glm::vec4), "denoiseOutput"},
        {PV_DENOISE_BINDING_PACKED, 2 * pixels * sizeof(glm::uvec4), "denoisePacked"},
        {PV_DENOISE_BINDING_HISTORY, PV_HISTORY_TEXELS * sizeof(glm::vec4), "denoiseHistory"},
    };
    d.buffers_.reserve(std::size(owned));
    for (const Owned& o : owned) {
        auto buffer = GpuBuffer::create(ctx, o.bytes, o.label);
        if (!buffer) return buffer.error();
        d.buffers_.push_back(std::move(buffer.value()));
    }
    // (The vector's elements keep their addresses when the denoiser moves.)
    for (size_t i = 0; i < std::size(owned); ++i) d.bound_[owned[i].binding] = &d.buffers_[i];
    d.ctx_ = &ctx;
    d.bound_[PV_DENOISE_BINDING_WORK_TEXELS] = d.bound_[PV_DENOISE_BINDING_WORK];
    d.bound_[PV_DENOISE_BINDING_PACKED_TEXELS] = d.bound_[PV_DENOISE_BINDING_PACKED];
    d.bound_[PV_DENOISE_BINDING_HISTORY_TEXELS] = d.bound_[PV_DENOISE_BINDING_HISTORY];
    std::array<BindingKind, PV_DENOISE_BINDING_COUNT> kinds{};
    kinds.fill(BindingKind::StorageBuffer);
    for (int b :
         {PV_DENOISE_BINDING_COLOR, PV_DENOISE_BINDING_GUIDES, PV_DENOISE_BINDING_WORK_TEXELS,
          PV_DENOISE_BINDING_PACKED_TEXELS, PV_DENOISE_BINDING_HISTORY_TEXELS})
        kinds[b] = BindingKind::TexelBufferUint4;
    auto make = [&](uint32_t stage, std::optional<ComputePipeline>& out) -> Status {
        const std::array<uint32_t, 1> constants{stage};
        auto p = ComputePipeline::create(
            ctx, std::span<const uint32_t>(denoise_spv, sizeof(denoise_spv) / 4), kinds, constants,
            "denoise");
        if (!p) return p.error();
        out.emplace(std::move(p.value()));
        return Status{};
    };
    if (Status s = make(PV_DENOISE_STAGE_PREPARE, d.prepare_); !s) return s.error();
    if (Status s = make(PV_DENOISE_STAGE_TEMPORAL, d.temporal_); !s) return s.error();
    if (Status s = make(PV_DENOISE_STAGE_ATROUS, d.atrous_); !s) return s.error();
    if (Status s = make(PV_DENOISE_STAGE_FINISH, d.finish_); !s) return s.error();
    if (Status s = d.bindGuides(*d.bound_[PV_DENOISE_BINDING_GUIDES]); !s) return s.error();
    return d;
}

Status Denoiser::ensureSize(int binding, size_t perPixel, const char* label) {
    const size_t bytes = perPixel * size_t(width_) * height_;
    // bound_ points at the vector's element, which takes the new buffer.
    GpuBuffer& buffer = buffers_[size_t(bound_[binding] - buffers_.data())];
    if (buffer.size() >= bytes) return {};
    auto made = GpuBuffer::create(*ctx_, bytes, label);
    if (!made) return made.error();
    // The old buffer goes at once: dispatches wait for completion (ComputePipeline::dispatch), so
    // no command still uses it.
    buffer = std::move(made.value());
    boundGuides_ = 0;  // the next bindGuides binds it to every pipeline
    return {};
}

Status Denoiser::bindGuides(const GpuBuffer& guides) {
    if (boundGuides_ == guides.id()) return {};
    std::array<const GpuBuffer*, PV_DENOISE_BINDING_COUNT> bound = bound_;
    bound[PV_DENOISE_BINDING_GUIDES] = &guides;
    for (ComputePipeline* p : {&*prepare_, &*temporal_, &*atrous_, &*finish_})
        if (Status s = p->bind(bound); !s) return s;
    boundGuides_ = guides.id();
    return {};
}

Status Denoiser::setSettings(const DenoiseSettings& settings) {
    if (Status s = validate(settings); !s) return s;
    settings_ = settings;
    return {};
}

Status Denoiser::dispatch(ComputePipeline& pipeline) {
    auto ms = pipeline.dispatch((width_ + PV_DENOISE_GROUP_X - 1) / PV_DENOISE_GROUP_X,
                                (height_ + PV_DENOISE_GROUP_Y - 1) / PV_DENOISE_GROUP_Y);
    if (!ms) return ms.error();
    lastGpuMs_ += ms.value();
    return {};
}

Result<ImageF> Denoiser::apply(const ImageF& signal, std::span<const glm::vec4> guides,
                               std::span<const float> variance) {
    return run(signal, guides, variance, nullptr);
}

Result<ImageF> Denoiser::applyTemporal(const ImageF& signal, std::span<const glm::vec4> guides,
                                       std::span<const float> variance, const DenoiseCamera& now) {
    return run(signal, guides, variance, &now);
}

Result<ImageF> Denoiser::run(const ImageF& signal, std::span<const glm::vec4> guides,
                             std::span<const float> variance, const DenoiseCamera* now) {
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
    // Strength 0 without temporal accumulation: nothing to do.
    lastGpuMs_ = 0.0;
    if (settings_.iterations == 0 && !now) return signal;
    std::vector<glm::vec4> color(pixels);
    for (size_t i = 0; i < pixels; ++i)
        color[i] = glm::vec4(signal.pixels[3 * i], signal.pixels[3 * i + 1],
                             signal.pixels[3 * i + 2], variance.empty() ? -1.0f : variance[i]);
    if (Status s =
            buffers_[PV_DENOISE_BINDING_COLOR].upload(color.data(), pixels * sizeof(glm::vec4));
        !s)
        return s.error();
    if (Status s = ensureSize(PV_DENOISE_BINDING_GUIDES, PV_GUIDE_COUNT * sizeof(glm::vec4),
                              "denoiseGuides");
        !s)
        return s.error();
    GpuBuffer& ownGuides = buffers_[PV_DENOISE_BINDING_GUIDES];
    if (Status s = ownGuides.upload(guides.data(), guides.size_bytes()); !s) return s.error();
    if (Status s = filter(ownGuides, now); !s) return s.error();
    if (Status s =
            buffers_[PV_DENOISE_BINDING_OUTPUT].download(color.data(), pixels * sizeof(glm::vec4));
        !s)
        return s.error();
    ImageF out;
    out.width = width_;
    out.height = height_;
    out.channels = 3;
    out.pixels.resize(pixels * 3);
    lastMask_.resize(pixels);
    for (size_t i = 0; i < pixels; ++i) {
        for (int c = 0; c < 3; ++c) out.pixels[3 * i + c] = color[i][c];
        lastMask_[i] = color[i].w;
    }
    return out;
}

Status Denoiser::filter(const GpuBuffer& guides, const DenoiseCamera* now) {
    lastGpuMs_ = 0.0;
    if (now) {
        if (Status s = ensureSize(PV_DENOISE_BINDING_WORK,
                                  PV_DENOISE_WORK_IMAGES * sizeof(glm::vec4), "denoiseWork");
            !s)
            return s;
        if (Status s = ensureSize(PV_DENOISE_BINDING_HISTORY,
                                  2 * PV_HISTORY_TEXELS * sizeof(glm::vec4), "denoiseHistory");
            !s)
            return s;
    }
    if (Status s = bindGuides(guides); !s) return s;
    shader::DenoiseParams params{};
    params.width = width_;
    params.height = height_;
    params.kernelRadius = settings_.kernelRadius;
    // This frame's guides go into the image not holding the previous frame's.
    params.packedImage = 1u - prevPacked_;
    params.historyIn = historyIn_;
    params.temporalAlpha = settings_.temporalAlpha;
    params.maxHistory = settings_.maxHistoryFrames;
    params.sigmaLuminance = settings_.sigmaLuminance;
    params.sigmaNormal = settings_.sigmaNormal;
    params.sigmaDepth = settings_.sigmaDepth;
    params.sigmaMask = settings_.sigmaMask;
    if (now) {
        params.prevCameraFromCamera =
            glm::mat4(glm::inverse(prevCamera_.worldFromCamera) * now->worldFromCamera);
        params.tanHalfFov = now->tanHalfFov;
        params.historyValid = historyValid_ ? 1u : 0u;
        params.temporal = 1u;
        params.prevTanHalfFov = prevCamera_.tanHalfFov;
    }
    GpuBuffer& paramsBuffer = buffers_[PV_DENOISE_BINDING_PARAMS];
    // Dispatches wait for completion (ComputePipeline::dispatch), so each iteration's parameters
    // can be uploaded into the one buffer between them.
    if (Status s = paramsBuffer.upload(&params, sizeof(params)); !s) return s;
    if (Status s = dispatch(*prepare_); !s) return s;
    uint32_t image = PV_DENOISE_WORK_PREPARED;
    if (now) {
        if (Status s = dispatch(*temporal_); !s) return s;
        image = PV_DENOISE_WORK_TEMPORAL;
        prevPacked_ = params.packedImage;
        historyIn_ = 1u - historyIn_;
        historyFrames_ = historyValid_ ? historyFrames_ + 1 : 1;
        historyValid_ = true;
        prevCamera_ = *now;
    }
    // The iterations ping-pong between the two images after the prepared one and, with the
    // temporal stage, its image.
    const uint32_t firstPingPong = (now ? PV_DENOISE_WORK_TEMPORAL : PV_DENOISE_WORK_PREPARED) + 1u;
    for (uint32_t i = 0; i < settings_.iterations; ++i) {
        params.stepPx = 1u << i;
        params.inImage = image;
        params.outImage = firstPingPong + i % 2;
        image = params.outImage;
        if (Status s = paramsBuffer.upload(&params, sizeof(params)); !s) return s;
        if (Status s = dispatch(*atrous_); !s) return s;
    }
    params.inImage = image;
    if (Status s = paramsBuffer.upload(&params, sizeof(params)); !s) return s;
    if (Status s = dispatch(*finish_); !s) return s;
    return {};
}

}  // namespace previs
