#include "render/film.h"

#include <algorithm>
#include <utility>

#include "base/log.h"
#include "gpu/shaders/shared/denoise.h"
#include "gpu/shaders/shared/scene_types.h"
#include "render/plate.h"

namespace previs {

namespace {

// The accumulation slot an AOV's colour is the mean of (the composite's plate-free part where a
// plate is composited, else the mixed scene). Also its luminance moment's component in
// PV_GUIDE_MOMENTS.
uint32_t colourSlot(Aov aov, bool withPlate) {
    if (aov == Aov::Real) return PV_ACCUM_REAL;
    if (aov == Aov::Mixed || !withPlate) return PV_ACCUM_MIXED;
    return PV_ACCUM_COMPOSITE;
}

ImageF blankImage(uint32_t width, uint32_t height, int channels) {
    ImageF img;
    img.width = width;
    img.height = height;
    img.channels = channels;
    img.pixels.resize(size_t(width) * height * channels);
    return img;
}

}  // namespace

double Film::Accumulation::value(size_t pixel, uint32_t slot, int channel) const {
    const size_t at = pixel * PV_ACCUM_COUNT + slot;
    return double(sum[at][channel]) - double(compensation[at][channel]);
}

double Film::Accumulation::count(size_t pixel) const { return value(pixel, PV_ACCUM_MIXED, 3); }

double Film::Accumulation::mean(size_t pixel, uint32_t slot, int channel) const {
    const double n = count(pixel);
    return n > 0.0 ? value(pixel, slot, channel) / n : 0.0;
}

Result<Film> Film::create(GpuContext& ctx, const RenderSettings& settings, uint32_t traceWidth,
                          uint32_t traceHeight) {
    Film film;
    film.ctx_ = &ctx;
    film.width_ = settings.width;
    film.height_ = settings.height;
    film.differential_ = settings.differential;
    film.heldOutlineTest_ = settings.previewOutlineTest;
    film.maxStorageRange_ = ctx.physicalDevice().getProperties().limits.maxStorageBufferRange;
    if (settings.denoise) {
        auto denoiser = Denoiser::create(ctx, traceWidth, traceHeight, settings.denoiseSettings);
        if (!denoiser) return denoiser.error();
        film.denoiser_.emplace(std::move(denoiser.value()));
    }
    return film;
}

Status Film::setPlate(ImageF plate, std::string_view source) {
    if (plate.width != width_ || plate.height != height_ || plate.channels < 3)
        return makeError(
            "the plate is {}x{} with {} channel(s); the render is {}x{} and needs "
            "RGB (render at the plate's resolution)",
            plate.width, plate.height, plate.channels, width_, height_);
    const PlateRepair repair = repairPlate(plate);
    if (repair.total() > 0 && plateValuesRepaired_ == 0)
        logWarning(
            "{}: {} NaN/infinite value(s) replaced by their finite neighbours' mean (0 "
            "where there is none) and {} negative value(s) by 0; they are never "
            "composited (docs/plates.md)",
            source, repair.nonFinite, repair.negative);
    plateValuesRepaired_ += repair.total();
    plate_ = std::move(plate);
    ++plateVersion_;
    return {};
}

Result<Film::Accumulation> Film::readAccumulation(const TracedBuffers& traced) {
    const size_t values = size_t(traced.width) * traced.height * PV_ACCUM_COUNT;
    Accumulation a;
    a.sum.resize(values);
    a.compensation.resize(values);
    const size_t bytes = values * sizeof(glm::vec4);
    if (Status s = traced.sum->download(a.sum.data(), bytes); !s) return s.error();
    if (Status s = traced.compensation->download(a.compensation.data(), bytes); !s)
        return s.error();
    return a;
}

Result<std::vector<glm::vec4>> Film::readGuides(const TracedBuffers& traced) {
    if (!traced.guides)
        return makeError(
            "the denoiser's guides (albedo, normal, depth) exist only in a renderer created with "
            "denoising on");
    std::vector<glm::vec4> g(size_t(traced.width) * traced.height * PV_GUIDE_COUNT);
    if (Status s = traced.guides->download(g.data(), g.size() * sizeof(glm::vec4)); !s)
        return s.error();
    return g;
}

size_t Film::platePixelOf(const TracedBuffers& traced, size_t i) const {
    const size_t x =
        (i % traced.width) * width_ / traced.width + width_ / (2 * size_t(traced.width));
    const size_t y =
        (i / traced.width) * height_ / traced.height + height_ / (2 * size_t(traced.height));
    return std::min(y, size_t(height_) - 1) * width_ + std::min(x, size_t(width_) - 1);
}

ImageF Film::upsample(const ImageF& traced) const {
    if (traced.width == width_ && traced.height == height_) return traced;
    return jointBilateralUpsample(traced, width_, height_, plate(), upsample_);
}

ImageF Film::compositeOverPlate(const ImageF& plateFree) const {
    // At a fraction of the output the plate-free terms are upsampled first; the plate term is
    // added at full resolution, so the plate is never resampled.
    const ImageF up = upsample(plateFree);
    ImageF out = blankImage(width_, height_, 3);
    for (size_t i = 0; i < size_t(width_) * height_; ++i) {
        const double mask = up.pixels[i * 4 + 3];
        for (int c = 0; c < 3; ++c) {
            const double mean = compositeSum(up.pixels[i * 4 + c], mask, 1.0,
                                             plate_->pixels[i * plate_->channels + c]);
            // Light is never negative, but Eq. 1's mean is where a virtual shadow (L_om − L_or
            // < 0) takes more than the plate holds there (noise, or a plate darker than the real
            // scene renders). Clamped here, on the mean: per sample it would bias the estimate.
            // The display pass clamps the same (film_display.comp); the differential layer
            // (Mixed − Real) stays signed.
            out.pixels[i * 3 + c] = float(std::max(mean, 0.0));
        }
    }
    return out;
}

Result<ImageF> Film::guideImage(const TracedBuffers& traced, Aov aov) const {
    auto g = readGuides(traced);
    if (!g) return g.error();
    const bool depth = aov == Aov::Depth;
    ImageF img = blankImage(traced.width, traced.height, depth ? 1 : 3);
    const uint32_t slot = aov == Aov::Normal ? PV_GUIDE_NORMAL : PV_GUIDE_ALBEDO_DEPTH;
    for (size_t i = 0; i < size_t(traced.width) * traced.height; ++i) {
        const glm::vec4& v = (*g)[i * PV_GUIDE_COUNT + slot];
        if (depth)
            img.pixels[i] = v.w;
        else
            for (int c = 0; c < 3; ++c) img.pixels[i * 3 + c] = v[c];
    }
    return upsample(img);
}

Result<ImageF> Film::image(const TracedBuffers& traced, Aov aov) const {
    if (aov == Aov::Albedo || aov == Aov::Normal || aov == Aov::Depth)
        return guideImage(traced, aov);
    Result<Accumulation> read = readAccumulation(traced);
    if (!read) return read.error();
    const Accumulation& a = *read;
    const size_t pixels = size_t(traced.width) * traced.height;
    if (compositesPlate(aov)) return compositeOverPlate(plateFreeMeans(a, traced));
    const bool single = aov == Aov::Mask || aov == Aov::SampleCount;
    ImageF img = blankImage(traced.width, traced.height, single ? 1 : 3);
    const uint32_t k = colourSlot(aov, false);
    for (size_t i = 0; i < pixels; ++i) {
        if (aov == Aov::Mask)
            img.pixels[i] = float(a.mean(i, PV_ACCUM_COMPOSITE, 3));
        else if (aov == Aov::SampleCount)
            img.pixels[i] = float(a.count(i));
        else
            for (int c = 0; c < 3; ++c) img.pixels[i * 3 + c] = float(a.mean(i, k, c));
    }
    return upsample(img);
}

Result<ImageF> Film::realSurfaceMeans(const TracedBuffers& traced) const {
    if (!differential_)
        return makeError("the real-only render L_or exists only in a differential render");
    Result<Accumulation> read = readAccumulation(traced);
    if (!read) return read.error();
    ImageF img = blankImage(traced.width, traced.height, 5);
    for (size_t i = 0; i < size_t(traced.width) * traced.height; ++i) {
        for (int c = 0; c < 4; ++c) img.pixels[i * 5 + c] = float(read->mean(i, PV_ACCUM_REAL, c));
        img.pixels[i * 5 + 4] = float(read->mean(i, PV_ACCUM_COMPOSITE, 3));
    }
    return img;
}

ImageF Film::plateFreeMeans(const Accumulation& a, const TracedBuffers& traced) {
    ImageF plateFree = blankImage(traced.width, traced.height, 4);
    for (size_t i = 0; i < size_t(traced.width) * traced.height; ++i)
        for (int c = 0; c < 4; ++c)
            plateFree.pixels[i * 4 + c] = float(a.mean(i, PV_ACCUM_COMPOSITE, c));
    return plateFree;
}

bool Film::holdView(bool on, uint32_t traceWidth, uint32_t traceHeight) {
    if (on && held_ && !held_->traces(traceWidth, traceHeight)) held_.reset();
    if (on && !held_) held_ = HeldView::create(width_, height_, traceWidth, traceHeight);
    if (!on && held_) held_->reset();
    if (on && held_) held_->hold();
    return on && held_;
}

bool Film::followView(uint32_t traceWidth, uint32_t traceHeight) {
    if (!holdView(true, traceWidth, traceHeight)) return false;
    held_->follow();
    return true;
}

Status Film::reprojectHeld(GpuBuffer& held, const DenoiseCamera& to) {
    const std::optional<DenoiseCamera> from = heldCamera();
    if (!from) return {};
    if (!reprojection_) {
        auto r = HeldReprojection::create(*ctx_, width_, height_);
        if (!r) return r.error();
        reprojection_.emplace(std::move(r.value()));
    }
    return reprojection_->run(held,
                              reprojectParams(*from, to, width_, height_, HeldView::kFollowKeep));
}

Result<std::vector<glm::vec4>> Film::heldSamplesOf(const TracedBuffers& traced) const {
    if (traced.width != width_ || traced.height != height_)
        return makeError(
            "the held view's samples come from a trace at the output's size ({}x{}), "
            "not {}x{}",
            width_, height_, traced.width, traced.height);
    Result<Accumulation> read = readAccumulation(traced);
    if (!read) return read.error();
    // The first hits' distances, which place the samples when the camera moves on: the
    // guides' mean depth (without guides, all at the distance of a miss: they turn with the
    // camera but do not shift).
    std::vector<glm::vec4> guides;
    if (traced.guides) {
        Result<std::vector<glm::vec4>> g = readGuides(traced);
        if (!g) return g.error();
        guides = std::move(*g);
    }
    const size_t pixels = size_t(width_) * height_;
    std::vector<glm::vec4> samples(2 * pixels);
    for (size_t i = 0; i < pixels; ++i) {
        for (int c = 0; c < 4; ++c)
            samples[2 * i][c] = float(read->value(i, PV_ACCUM_COMPOSITE, c));
        const float count = float(read->count(i));
        const float distance = guides.empty()
                                   ? PV_GUIDE_MISS_DEPTH_M
                                   : guides[i * PV_GUIDE_COUNT + PV_GUIDE_ALBEDO_DEPTH].w;
        samples[2 * i + 1] = glm::vec4(count, count * distance, 0.0f, 0.0f);
    }
    return samples;
}

Result<ImageF> Film::heldComposite(const TracedBuffers& traced, const ImageF& estimate) {
    std::vector<glm::vec4> samples(size_t(width_) * height_ * 2);
    if (Status s = traced.held->download(samples.data(), samples.size() * sizeof(glm::vec4)); !s)
        return s.error();
    return compositeOverPlate(HeldView::blend(
        samples, upsample(estimate), HeldView::estimateSamples(frameSamples_), testsHeldOutline()));
}

Result<Denoiser*> Film::denoiserFor(const TracedBuffers& traced) {
    if (!denoiser_ || !traced.guides)
        return makeError(
            "a denoised image needs a renderer created with denoising on (--denoise on|auto)");
    // At a resolution scale below 1 the filter runs on the traced pixels, before upsampling
    // (the guides are traced there too), so it costs scale² of a full-size filter.
    if (denoiser_->width() != traced.width || denoiser_->height() != traced.height) {
        auto resized = Denoiser::create(*ctx_, traced.width, traced.height, denoiser_->settings());
        if (!resized) return resized.error();
        denoiser_.emplace(std::move(resized.value()));
    }
    return &*denoiser_;
}

Result<ImageF> Film::denoisedMeans(const TracedBuffers& traced, const Accumulation& m,
                                   uint32_t slot, const DenoiseCamera& camera) {
    if (Result<Denoiser*> d = denoiserFor(traced); !d) return d.error();
    auto g = readGuides(traced);
    if (!g) return g.error();
    const size_t pixels = size_t(traced.width) * traced.height;
    ImageF signal = blankImage(traced.width, traced.height, 3);
    std::vector<float> variance(pixels);
    for (size_t i = 0; i < pixels; ++i) {
        glm::dvec3 mean(0.0);
        for (int c = 0; c < 3; ++c) {
            mean[c] = m.mean(i, slot, c);
            signal.pixels[i * 3 + c] = float(mean[c]);
        }
        const double n = m.count(i);
        const double y = glm::dot(mean, glm::dvec3(0.2126, 0.7152, 0.0722));  // luminance()
        const double y2 = (*g)[i * PV_GUIDE_COUNT + PV_GUIDE_MOMENTS][slot];
        variance[i] = float(PV_MEAN_LUMINANCE_VARIANCE(y, y2, n));
    }
    return temporalDenoise_ ? denoiser_->applyTemporal(signal, *g, variance, camera)
                            : denoiser_->apply(signal, *g, variance);
}

Result<ImageF> Film::compositeEstimate(const TracedBuffers& traced, bool denoised,
                                       const DenoiseCamera& camera) {
    Result<Accumulation> m = readAccumulation(traced);
    if (!m) return m.error();
    if (!denoised) return plateFreeMeans(*m, traced);
    // The filter sees the composite without its plate term; the mask is the one its output
    // carries, the mean that goes with the filtered signal (with the temporal stage, the
    // history's).
    auto filtered = denoisedMeans(traced, *m, PV_ACCUM_COMPOSITE, camera);
    if (!filtered) return filtered.error();
    const std::span<const float> mask = denoiser_->lastMask();
    ImageF plateFree = blankImage(traced.width, traced.height, 4);
    for (size_t i = 0; i < size_t(traced.width) * traced.height; ++i) {
        for (int c = 0; c < 3; ++c) plateFree.pixels[i * 4 + c] = filtered->pixels[i * 3 + c];
        plateFree.pixels[i * 4 + 3] = mask[i];
    }
    return plateFree;
}

Result<ImageF> Film::image(const TracedBuffers& traced, Aov aov, bool denoised,
                           const DenoiseCamera& camera) {
    const bool held = held_ && traced.held;
    if (compositesPlate(aov) && (denoised || held)) {
        Result<ImageF> estimate = compositeEstimate(traced, denoised, camera);
        if (!estimate) return estimate.error();
        return held ? heldComposite(traced, *estimate) : compositeOverPlate(*estimate);
    }
    if (!denoised || !(aov == Aov::Composite || aov == Aov::Mixed || aov == Aov::Real))
        return image(traced, aov);
    Result<Accumulation> m = readAccumulation(traced);
    if (!m) return m.error();
    auto filtered = denoisedMeans(traced, *m, colourSlot(aov, false), camera);
    if (!filtered) return filtered.error();
    return upsample(*filtered);
}

bool Film::displayPassFits(const TracedBuffers& traced) const {
    const uint64_t perTraced = uint64_t(traced.width) * traced.height * sizeof(glm::vec4);
    const uint64_t perOutput = uint64_t(width_) * height_ * sizeof(glm::vec4);
    return perTraced * std::max(PV_ACCUM_COUNT, PV_GUIDE_COUNT) <= maxStorageRange_ &&
           perOutput * 2 <= maxStorageRange_;
}

Result<DisplayImage> Film::display(const TracedBuffers& traced, bool denoised,
                                   const DenoiseCamera& camera, const DisplaySettings& settings) {
    // Without a plate to composite, or with buffers too large for the device to bind whole (an
    // output far beyond 4K on a device with a small maxStorageBufferRange), the host finishes it.
    if (!compositesPlate(Aov::Composite) || !displayPassFits(traced)) {
        Result<ImageF> image = this->image(traced, Aov::Composite, denoised, camera);
        if (!image) return image.error();
        return toDisplayImage(std::move(*image), settings);
    }
    if (!displayPass_) {
        auto pass = DisplayPass::create(*ctx_, width_, height_);
        if (!pass) return pass.error();
        displayPass_.emplace(std::move(pass.value()));
    }
    DisplayPass::Inputs in{&*plate_,     plateVersion_, traced.sum, traced.compensation,
                           traced.width, traced.height};
    in.held = held_ && traced.held ? traced.held : nullptr;
    in.heldEstimateSamples = HeldView::estimateSamples(frameSamples_);
    in.heldOutlineTest = testsHeldOutline();
    // Denoised, the filter's input is written and filtered on the device too: nothing is read
    // back but the frame.
    if (denoised) {
        Result<Denoiser*> d = denoiserFor(traced);
        if (!d) return d.error();
        in.guides = traced.guides;
        in.signal = &(*d)->colourInput();
        if (Status s = displayPass_->writeSignal(in); !s) return s.error();
        if (Status s = (*d)->filter(*traced.guides, temporalDenoise_ ? &camera : nullptr); !s)
            return s.error();
        in.denoised = &(*d)->output();
    }
    return displayPass_->run(in, upsample_, settings);
}

Result<Convergence> Film::convergence(const TracedBuffers& traced, uint64_t samplesPerPixel) const {
    Result<Accumulation> read = readAccumulation(traced);
    if (!read) return read.error();
    const Accumulation& a = *read;
    // At a resolution scale below 1 the meter measures the traced pixels, each with the plate
    // pixel at its centre (the upsampled image is smoother: this errs high).
    const size_t pixels = size_t(traced.width) * traced.height;
    const bool withPlate = compositesPlate(Aov::Composite);
    std::vector<MeterPixel> composite(pixels), differential(pixels);
    for (size_t i = 0; i < pixels; ++i) {
        // Slot `k` of all samples and of replicate 1's.
        auto total = [&](uint32_t k, int c) { return a.value(i, k, c); };
        auto half = [&](uint32_t k, int c) { return a.value(i, PV_ACCUM_REPLICATE_1 + k, c); };
        MeterPixel& mp = composite[i];
        MeterPixel& d = differential[i];
        mp.count = d.count = total(PV_ACCUM_MIXED, 3);
        mp.halfCount = d.halfCount = half(PV_ACCUM_MIXED, 3);
        for (int c = 0; c < 3; ++c) {
            if (withPlate) {
                const double plate = plate_->pixels[platePixelOf(traced, i) * plate_->channels + c];
                mp.sum[c] = compositeSum(total(PV_ACCUM_COMPOSITE, c), total(PV_ACCUM_COMPOSITE, 3),
                                         mp.count, plate);
                mp.halfSum[c] = compositeSum(half(PV_ACCUM_COMPOSITE, c),
                                             half(PV_ACCUM_COMPOSITE, 3), mp.halfCount, plate);
            } else {
                // What image(Aov::Composite) shows without a plate: the mixed scene.
                mp.sum[c] = total(PV_ACCUM_MIXED, c);
                mp.halfSum[c] = half(PV_ACCUM_MIXED, c);
            }
            d.sum[c] = total(PV_ACCUM_MIXED, c) - total(PV_ACCUM_REAL, c);
            d.halfSum[c] = half(PV_ACCUM_MIXED, c) - half(PV_ACCUM_REAL, c);
        }
    }
    Convergence out;
    out.composite = estimateNoise(composite);
    out.differential = estimateNoise(differential);
    out.samplesPerPixel = samplesPerPixel;
    return out;
}

}  // namespace previs
