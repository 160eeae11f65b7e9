#pragma once

// The film (pbrt-v4's term): what the path tracer's accumulation becomes as images. It reads the
// traced sums back, takes their means per pixel, composites them with the camera image (Eq. 1 of
// Kán & Kaufmann, written once: compositeSum), upsamples a fraction-size trace to the output,
// runs the denoiser on the differential signal and the convergence meter. The renderer owns one;
// the path tracer writes the buffers it reads (TracedBuffers).

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/shaders/shared/composite.h"
#include "image/image.h"
#include "render/convergence.h"
#include "render/denoiser.h"
#include "render/display_pass.h"
#include "render/held_reprojection.h"
#include "render/held_view.h"
#include "render/render_settings.h"
#include "render/upsample.h"

namespace previs {

// Eq. 1 summed over n samples of a pixel: Σ[M·L_om + (1−M)(L_om − L_or)] (the plate-free sum the
// path tracer accumulates) plus (n − ΣM)·L_oc. With n = 1 and means it is the composite's mean;
// where no sample met a virtual object (both sums 0) it is n·L_oc, the plate bit for bit.
// (shared/composite.h's PV_COMPOSITE_SUM, which the display pass runs too.)
inline double compositeSum(double plateFreeSum, double maskSum, double samples, double plate) {
    return PV_COMPOSITE_SUM(plateFreeSum, maskSum, samples, plate);
}

// The accumulation the path tracer wrote (read-only views of the renderer's buffers): the
// compensated sums (PV_ACCUM_* slots per pixel), the denoiser's guides (null without them) and
// the traced size.
struct TracedBuffers {
    const GpuBuffer* sum = nullptr;
    const GpuBuffer* compensation = nullptr;
    const GpuBuffer* guides = nullptr;
    // The frame's samples at the output's resolution (PV_BINDING_HELD_SAMPLES); null unless the
    // held view is on.
    const GpuBuffer* held = nullptr;
    uint32_t width = 0;
    uint32_t height = 0;
};

class Film {
public:
    // Output size and what is composited from the settings; the denoiser (settings.denoise)
    // created at the traced size, so its settings are checked before the first frame.
    static Result<Film> create(GpuContext& ctx, const RenderSettings& settings, uint32_t traceWidth,
                               uint32_t traceHeight);

    // The camera image L_oc in linear radiance at the output size (no resampling: primary rays
    // follow the camera's lens model instead). Used by Aov::Composite. NaN, Inf and negative
    // values are never composited: repairPlate (render/plate.h) replaces them, with one warning
    // naming `source` (the first time only: the service sets a plate every frame). By value: a
    // caller done with its plate moves it in.
    Status setPlate(ImageF plate, std::string_view source = "plate");
    // The plate as repaired and kept; nullptr before the first setPlate.
    const ImageF* plate() const { return plate_ ? &*plate_ : nullptr; }
    // Plate values setPlate has replaced so far (NaN/Inf and negative).
    uint64_t plateValuesRepaired() const { return plateValuesRepaired_; }
    // How image() brings a traced buffer to the output size (resolution scale < 1).
    UpsampleSettings& upsampleSettings() { return upsample_; }

    // Renderer::image's two forms and Renderer::convergence (render/renderer.h says what each
    // returns).
    Result<ImageF> image(const TracedBuffers& traced, Aov aov) const;
    // `camera`: this frame's, for the temporal stage's reprojection.
    Result<ImageF> image(const TracedBuffers& traced, Aov aov, bool denoised,
                         const DenoiseCamera& camera);
    Result<Convergence> convergence(const TracedBuffers& traced, uint64_t samplesPerPixel) const;
    // Renderer::realSurfaceMeans (render/renderer.h says what it returns).
    Result<ImageF> realSurfaceMeans(const TracedBuffers& traced) const;
    // The composite as the monitor shows it: image(Composite, denoised, camera) tone mapped to
    // 8-bit sRGB, made on the device (render/display_pass.h: upsampling, the held view, Eq. 1,
    // the curve) with one 8-bit readback; without a plate to composite, on the host.
    Result<DisplayImage> display(const TracedBuffers& traced, bool denoised,
                                 const DenoiseCamera& camera, const DisplaySettings& settings);

    // A held camera's preview at the output's resolution (render/held_view.h): on, the
    // composite keeps each frame's samples per output pixel (TracedBuffers::held) and blends its
    // estimate with them; off, it forgets them. Stays off at full resolution. Returns whether it
    // is on.
    bool holdView(bool on, uint32_t traceWidth, uint32_t traceHeight);
    // The camera moved: the held view stays on (as holdView(true)) and its samples are to follow
    // the camera (reprojectHeld). Returns whether it is on.
    bool followView(uint32_t traceWidth, uint32_t traceHeight);
    // Frames the held view has kept since the camera last moved (0 while off or following).
    uint64_t heldFrames() const { return held_ ? held_->frames() : 0; }
    // Whether the held view's blend tests the estimate's outline (HeldView::blend): while the
    // camera holds, unless RenderSettings::previewOutlineTest is off.
    bool testsHeldOutline() const { return heldOutlineTest_ && held_ && held_->testsOutline(); }
    // The camera the held view's samples are aligned with; none while it keeps none (they are
    // then to be cleared).
    std::optional<DenoiseCamera> heldCamera() const {
        return held_ ? held_->camera() : std::nullopt;
    }
    // Moves the held view's samples (`held`, PV_BINDING_HELD_SAMPLES) from heldCamera() to `to`
    // (render/held_reprojection.h), fading them by HeldView::kFollowKeep.
    Status reprojectHeld(GpuBuffer& held, const DenoiseCamera& to);
    // The accumulation of a full-resolution trace (refinement's) as the held view's samples
    // (PV_BINDING_HELD_SAMPLES' layout: per output pixel the sums of Eq. 1's plate-free part and
    // of M, then the sample count): a preview that resumes on the refined view starts from them.
    Result<std::vector<glm::vec4>> heldSamplesOf(const TracedBuffers& traced) const;
    // Samples per traced pixel a preview frame traces (what the held view weighs its estimate by).
    void setFrameSamples(uint32_t spp) { frameSamples_ = spp; }
    // A preview frame's samples, traced from `camera`, joined the held view's (the renderer sums
    // them on the device).
    void heldFrameAdded(const DenoiseCamera& camera) {
        if (held_) held_->frameAdded(camera);
    }

    // Bytes of device memory in the denoiser's buffers (its history included) and the display
    // pass's.
    uint64_t deviceBytes() const {
        return (denoiser_ ? denoiser_->deviceBytes() : 0) +
               (displayPass_ ? displayPass_->deviceBytes() : 0) +
               (reprojection_ ? reprojection_->deviceBytes() : 0);
    }

    // The denoiser (null without RenderSettings::denoise): its settings and temporal history.
    Denoiser* denoiser() { return denoiser_ ? &*denoiser_ : nullptr; }
    const Denoiser* denoiser() const { return denoiser_ ? &*denoiser_ : nullptr; }
    // Denoised images accumulate the denoiser's temporal history (preview; Denoiser::
    // applyTemporal with Renderer::denoiseCamera()); off: spatial only (Denoiser::apply). The
    // history is one signal's: denoise one AOV a frame while it is on (the composite), and reset
    // it (denoiser()->resetHistory()) on a mode switch or a scene change.
    void setTemporalDenoise(bool on) { temporalDenoise_ = on; }

private:
    // The sums read back: value(pixel, PV_ACCUM_*, channel) is the compensated sum in double.
    struct Accumulation {
        std::vector<glm::vec4> sum, compensation;
        double value(size_t pixel, uint32_t slot, int channel) const;
        // The samples of pixel i that count: those not dropped (NaN/Inf,
        // RenderStats::nonFiniteSamples), so a dropped sample neither darkens the pixel nor lets
        // the plate through.
        double count(size_t pixel) const;
        // The mean of a slot; 0 (mask 0: the plate) for a pixel without samples.
        double mean(size_t pixel, uint32_t slot, int channel) const;
    };
    static Result<Accumulation> readAccumulation(const TracedBuffers& traced);
    static Result<std::vector<glm::vec4>> readGuides(const TracedBuffers& traced);
    // The means of Eq. 1's plate-free part (RGB) and of the mask M (A) per traced pixel.
    static ImageF plateFreeMeans(const Accumulation& a, const TracedBuffers& traced);
    Result<ImageF> guideImage(const TracedBuffers& traced, Aov aov) const;
    // The plate's pixel at the centre of traced pixel i (the meter at a fraction-size trace).
    size_t platePixelOf(const TracedBuffers& traced, size_t i) const;
    bool compositesPlate(Aov aov) const { return aov == Aov::Composite && plate_ && differential_; }
    // Brings a traced-size image to the output size (guided by the plate where there is one).
    ImageF upsample(const ImageF& traced) const;
    // Eq. 1 at the output size from `plateFree` (RGB the mean of M·L_om + (1−M)(L_om − L_or), A
    // the mask M), upsampled first when it is traced at a fraction of the output.
    ImageF compositeOverPlate(const ImageF& plateFree) const;
    // The frame's estimate of Eq. 1's plate-free part at the traced size: RGB its mean (denoised
    // where `denoised`), A the mask M.
    Result<ImageF> compositeEstimate(const TracedBuffers& traced, bool denoised,
                                     const DenoiseCamera& camera);
    // The denoiser at the traced size (made anew when the size changed); an error without one.
    Result<Denoiser*> denoiserFor(const TracedBuffers& traced);
    // The means of accumulation slot `slot` (RGB) through the denoiser (temporal where it is on).
    Result<ImageF> denoisedMeans(const TracedBuffers& traced, const Accumulation& m, uint32_t slot,
                                 const DenoiseCamera& camera);
    // Whether the display pass can bind the accumulation, the guides and the held samples whole.
    bool displayPassFits(const TracedBuffers& traced) const;
    // The held view's composite: the samples kept, blended with `estimate` (the traced-size
    // RGBA compositeOverPlate takes) upsampled.
    Result<ImageF> heldComposite(const TracedBuffers& traced, const ImageF& estimate);

    Film() = default;
    GpuContext* ctx_ = nullptr;
    uint32_t width_ = 0;  // the output's
    uint32_t height_ = 0;
    bool differential_ = false;
    uint64_t maxStorageRange_ = 0;  // the device's maxStorageBufferRange
    std::optional<ImageF> plate_;
    uint64_t plateVersion_ = 0;  // counts setPlate calls: the display pass uploads a new plate
    uint64_t plateValuesRepaired_ = 0;
    UpsampleSettings upsample_;
    std::optional<Denoiser> denoiser_;
    bool temporalDenoise_ = false;
    std::optional<HeldView> held_;
    uint32_t frameSamples_ = 1;                     // setFrameSamples
    bool heldOutlineTest_ = true;                   // RenderSettings::previewOutlineTest
    std::optional<HeldReprojection> reprojection_;  // made when the camera first moves
    std::optional<DisplayPass> displayPass_;        // made with the first display()
};

}  // namespace previs
