#include "render/display_pass.h"

#include <array>
#include <cmath>
#include <span>

#include "base/log.h"
#include "film_display.spv.h"
#include "gpu/shaders/shared/composite.h"

namespace previs {

namespace {

constexpr uint32_t groups(uint32_t n, uint32_t group) { return (n + group - 1) / group; }

uint32_t toneOp(ToneMapOperator op) {
    switch (op) {
        case ToneMapOperator::Clamp:
            return PV_TONE_CLAMP;
        case ToneMapOperator::Reinhard:
            return PV_TONE_REINHARD;
        case ToneMapOperator::ReinhardExtended:
            return PV_TONE_REINHARD_EXTENDED;
    }
    return PV_TONE_CLAMP;
}

}  // namespace

DisplayImage toDisplayImage(ImageF composite, const DisplaySettings& settings) {
    // Undo the white balance the plate's inverse applied (in place: no copy per frame), then the
    // camera's curve forward.
    if (settings.whiteBalance != std::array<float, 3>{1.0f, 1.0f, 1.0f})
        for (size_t i = 0; i < composite.pixels.size(); ++i)
            composite.pixels[i] /= settings.whiteBalance[i % composite.channels];
    return {composite.width, composite.height, toneMapToSrgb8(composite, settings.tone)};
}

Result<DisplayPass> DisplayPass::create(GpuContext& ctx, uint32_t width, uint32_t height) {
    DisplayPass d;
    d.ctx_ = &ctx;
    d.width_ = width;
    d.height_ = height;
    const size_t pixels = size_t(width) * height;
    auto make = [&](std::optional<GpuBuffer>& out, size_t bytes, const char* label) -> Status {
        auto b = GpuBuffer::create(ctx, bytes, label);
        if (!b) return b.error();
        out.emplace(std::move(b.value()));
        return {};
    };
    for (Status s : {make(d.params_, sizeof(shader::FilmParams), "filmParams"),
                     make(d.plate_, pixels * 3 * sizeof(float), "filmPlate"),
                     make(d.thresholds_, 256 * sizeof(float), "filmSrgbThresholds"),
                     make(d.output_, pixels * sizeof(uint32_t), "filmDisplay"),
                     make(d.none_, 2 * sizeof(glm::vec4), "filmUnused")})
        if (!s) return s.error();
    if (Status s = d.thresholds_->upload(srgb8Thresholds().data(), 256 * sizeof(float)); !s)
        return s.error();
    std::array<BindingKind, PV_FILM_BINDING_COUNT> kinds{};
    kinds.fill(BindingKind::StorageBuffer);
    kinds[PV_FILM_BINDING_PLATE] = BindingKind::TexelBufferUint;
    kinds[PV_FILM_BINDING_SRGB_THRESHOLDS] = BindingKind::TexelBufferUint;
    kinds[PV_FILM_BINDING_ESTIMATE] = BindingKind::TexelBufferUint4;
    kinds[PV_FILM_BINDING_LOW_GUIDE_TEXELS] = BindingKind::TexelBufferUint4;
    for (auto [stage, out] : {std::pair{PV_FILM_STAGE_SIGNAL, &d.signalStage_},
                              std::pair{PV_FILM_STAGE_ESTIMATE, &d.estimateStage_},
                              std::pair{PV_FILM_STAGE_GUIDE, &d.guide_},
                              std::pair{PV_FILM_STAGE_RESOLVE, &d.resolve_}}) {
        const std::array<uint32_t, 1> constants{stage};
        auto p = ComputePipeline::create(
            ctx, std::span<const uint32_t>(film_display_spv, sizeof(film_display_spv) / 4), kinds,
            constants, "film_display");
        if (!p) return p.error();
        out->emplace(std::move(p.value()));
    }
    return d;
}

uint64_t DisplayPass::deviceBytes() const {
    uint64_t total = 0;
    for (const std::optional<GpuBuffer>* b :
         {&params_, &plate_, &estimate_, &lowGuide_, &thresholds_, &output_, &none_, &viewLut_})
        if (*b) total += (*b)->size();
    return total;
}

Status DisplayPass::sizeTrace(uint32_t traceWidth, uint32_t traceHeight) {
    if (traceWidth == traceWidth_ && traceHeight == traceHeight_) return {};
    const size_t bytes = size_t(traceWidth) * traceHeight * sizeof(glm::vec4);
    auto estimate = GpuBuffer::create(*ctx_, bytes, "filmEstimate");
    if (!estimate) return estimate.error();
    auto lowGuide = GpuBuffer::create(*ctx_, bytes, "filmLowGuide");
    if (!lowGuide) return lowGuide.error();
    estimate_.emplace(std::move(estimate.value()));
    lowGuide_.emplace(std::move(lowGuide.value()));
    traceWidth_ = traceWidth;
    traceHeight_ = traceHeight;
    bound_ = {};  // the new buffers are not bound yet
    return {};
}

Status DisplayPass::uploadPlate(const ImageF& plate, uint64_t plateVersion) {
    if (plateVersion_ == plateVersion) return {};
    PV_ASSERT(plate.width == width_ && plate.height == height_ && plate.channels >= 3);
    const size_t pixels = size_t(width_) * height_;
    std::vector<float> rgb;
    if (plate.channels != 3) {
        rgb.resize(pixels * 3);
        for (size_t i = 0; i < pixels; ++i)
            for (int c = 0; c < 3; ++c) rgb[i * 3 + c] = plate.pixels[i * plate.channels + c];
    }
    const std::span<const float> values = plate.channels == 3 ? plate.pixels : rgb;
    if (Status s = plate_->upload(values.data(), values.size_bytes()); !s) return s;
    // The range kernel's ε is relative to the plate's mean (render/upsample.h).
    double sum = 0.0;
    for (float v : values) sum += std::max(v, 0.0f);
    plateMean_ = float(sum / double(std::max<size_t>(values.size(), 1)));
    plateVersion_ = plateVersion;
    return {};
}

Status DisplayPass::uploadView(const DisplaySettings& settings) {
    if (!settings.viewLut || settings.viewLut == viewUploaded_) return {};
    const std::vector<float>& table = *settings.viewLut;
    PV_ASSERT(table.size() ==
              size_t(settings.viewLutSize) * settings.viewLutSize * settings.viewLutSize * 3);
    auto lut = GpuBuffer::create(*ctx_, table.size() * sizeof(float), "filmViewLut");
    if (!lut) return lut.error();
    if (Status s = lut->upload(table.data(), table.size() * sizeof(float)); !s) return s;
    viewLut_.emplace(std::move(lut.value()));
    viewUploaded_ = settings.viewLut;
    bound_ = {};  // the new table is not bound yet
    return {};
}

Status DisplayPass::bind(const Inputs& in) {
    auto orNone = [&](const GpuBuffer* b) -> const GpuBuffer& { return b ? *b : *none_; };
    const std::array<const GpuBuffer*, 6> inputs{&orNone(in.held),         &orNone(in.sum),
                                                 &orNone(in.compensation), &orNone(in.guides),
                                                 &orNone(in.signal),       &orNone(in.denoised)};
    std::array<uint64_t, 6> ids{};
    for (size_t k = 0; k < ids.size(); ++k) ids[k] = inputs[k]->id();
    if (bound_ == ids) return {};
    std::array<const GpuBuffer*, PV_FILM_BINDING_COUNT> bound{};
    bound[PV_FILM_BINDING_PARAMS] = &*params_;
    bound[PV_FILM_BINDING_PLATE] = &*plate_;
    bound[PV_FILM_BINDING_ESTIMATE] = &*estimate_;
    bound[PV_FILM_BINDING_ESTIMATE_OUT] = &*estimate_;
    bound[PV_FILM_BINDING_LOW_GUIDE] = &*lowGuide_;
    bound[PV_FILM_BINDING_LOW_GUIDE_TEXELS] = &*lowGuide_;
    bound[PV_FILM_BINDING_SRGB_THRESHOLDS] = &*thresholds_;
    bound[PV_FILM_BINDING_OUTPUT] = &*output_;
    bound[PV_FILM_BINDING_HELD] = inputs[0];
    bound[PV_FILM_BINDING_ACCUM_SUM] = inputs[1];
    bound[PV_FILM_BINDING_ACCUM_COMPENSATION] = inputs[2];
    bound[PV_FILM_BINDING_GUIDES] = inputs[3];
    bound[PV_FILM_BINDING_SIGNAL_OUT] = inputs[4];
    bound[PV_FILM_BINDING_DENOISED] = inputs[5];
    bound[PV_FILM_BINDING_VIEW_LUT] = viewLut_ ? &*viewLut_ : &*none_;
    for (ComputePipeline* p : {&*signalStage_, &*estimateStage_, &*guide_, &*resolve_})
        if (Status s = p->bind(bound); !s) return s;
    bound_ = ids;
    return {};
}

Status DisplayPass::writeSignal(const Inputs& in) {
    PV_ASSERT(in.sum && in.compensation && in.guides && in.signal);
    if (Status s = sizeTrace(in.traceWidth, in.traceHeight); !s) return s;
    if (Status s = bind(in); !s) return s;
    const shader::FilmParams p = params(in, {}, {});
    if (Status s = params_->upload(&p, sizeof(p)); !s) return s;
    auto ms = signalStage_->dispatch(groups(in.traceWidth, PV_FILM_GROUP_X),
                                     groups(in.traceHeight, PV_FILM_GROUP_Y));
    return ms ? Status{} : Status(ms.error());
}

Result<DisplayImage> DisplayPass::run(const Inputs& in, const UpsampleSettings& upsample,
                                      const DisplaySettings& settings) {
    PV_ASSERT(in.plate && in.sum && in.compensation);
    if (Status s = sizeTrace(in.traceWidth, in.traceHeight); !s) return s.error();
    if (Status s = uploadPlate(*in.plate, in.plateVersion); !s) return s.error();
    if (Status s = uploadView(settings); !s) return s.error();
    if (Status s = bind(in); !s) return s.error();
    const shader::FilmParams p = params(in, upsample, settings);
    if (Status s = params_->upload(&p, sizeof(p)); !s) return s.error();
    const uint32_t tx = groups(in.traceWidth, PV_FILM_GROUP_X);
    const uint32_t ty = groups(in.traceHeight, PV_FILM_GROUP_Y);
    if (auto ms = estimateStage_->dispatch(tx, ty); !ms) return ms.error();
    if (in.traceWidth != width_ || in.traceHeight != height_)
        if (auto ms = guide_->dispatch(tx, ty); !ms) return ms.error();
    auto ms = resolve_->dispatch(groups(width_, PV_FILM_GROUP_X), groups(height_, PV_FILM_GROUP_Y));
    if (!ms) return ms.error();
    const size_t pixels = size_t(width_) * height_;
    std::vector<uint32_t> packed(pixels);
    if (Status s = output_->download(packed.data(), pixels * sizeof(uint32_t)); !s)
        return s.error();
    DisplayImage out{width_, height_, std::vector<uint8_t>(pixels * 3)};
    for (size_t i = 0; i < pixels; ++i)
        for (int c = 0; c < 3; ++c) out.rgb[i * 3 + c] = uint8_t(packed[i] >> (8 * c));
    return out;
}

shader::FilmParams DisplayPass::params(const Inputs& in, const UpsampleSettings& upsample,
                                       const DisplaySettings& settings) const {
    shader::FilmParams p{};
    p.width = width_;
    p.height = height_;
    p.traceWidth = in.traceWidth;
    p.traceHeight = in.traceHeight;
    // exp(−d_ln²/(2σ²)) with d_ln = ln 2 · d_log2.
    const float ln2 = 0.69314718f, sigma = upsample.rangeSigma;
    p.rangeScale = sigma > 0.0f ? ln2 * ln2 / (2.0f * sigma * sigma) : 0.0f;
    p.logEpsilon = std::max(upsample.logEpsilonFraction * plateMean_, 1e-12f);
    const OutlineKernel outline =
        outlineKernel(upsample, width_, height_, in.traceWidth, in.traceHeight);
    p.maskSharpness = outline.sharpness;
    p.maskRangeScale = outline.rangeScale;
    p.held = in.held ? 1u : 0u;
    p.heldEstimateSamples = in.heldEstimateSamples;
    p.heldOutlineTest = in.heldOutlineTest ? 1u : 0u;
    p.denoised = in.denoised ? 1u : 0u;
    p.toneOp = toneOp(settings.tone.op);
    const float exposure = std::exp2(settings.tone.exposureStops);
    for (int c = 0; c < 3; ++c) p.exposure[c] = exposure / settings.whiteBalance[c];
    p.maxRadiance = settings.tone.maxRadiance;
    p.whiteLuminance = settings.tone.whiteLuminance;
    p.viewLutSize = settings.viewLut ? settings.viewLutSize : 0u;
    return p;
}

}  // namespace previs
