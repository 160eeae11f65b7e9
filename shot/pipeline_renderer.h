#pragma once

// The render stage of the service (DESIGN.md §1): one tracked camera frame and the newest
// lighting in, one composited frame out — a preview frame of a few samples with the fixed random
// sequence, or the next step of a refinement. Owned by the render thread (it owns the Vulkan
// device); `previs replay` drives the same object frame by frame.

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <vector>

#include "base/result.h"
#include "config/service_config.h"
#include "gpu/context.h"
#include "image/image.h"
#include "render/cpu_tracer.h"
#include "render/display_pass.h"
#include "render/quality_dial.h"
#include "render/renderer.h"
#include "render/tonemap.h"
#include "scene/scene.h"
#include "shot/pipeline_stages.h"
#include "shot/preview_settings.h"
#include "shot/shot_controller.h"

namespace previs {

// What previsd's start shows while it makes a PipelineRenderer (daemon/service.h): each slow
// part as it begins, with how many steps it will count through `progress` (0: none), then
// those steps (the pipelines compiled, the dial's settings: done of total); and the flag that
// interrupts the dial's renders (a SIGTERM while starting).
struct PipelineStartHooks {
    static constexpr const char* kCompilingStage = "compiling pipelines";
    std::function<void(const std::string& stage, size_t steps)> stage;
    std::function<void(size_t done, size_t total)> progress;
    const std::atomic<bool>* interrupt = nullptr;
};

class PipelineRenderer final : public ShotRenderer {
public:
    // `scene` by value: a fisheye-lit one gets the studio stand-in environment before the renderer
    // is made (callers that are done with theirs move it in).
    static Result<std::unique_ptr<PipelineRenderer>> create(GpuContext& ctx, Scene scene,
                                                            const ServiceConfig& config,
                                                            const PipelineStartHooks& hooks = {});

    // Preview: this frame with its own pose and `lighting` (null = the scene's own), drawn with
    // the same random sequence as every preview frame.
    Status renderPreview(const TrackedFrame& frame,
                         const std::shared_ptr<const LiveLighting>& lighting) override;
    // Refinement: freezes frame, pose and lighting, and clears the accumulation.
    Status beginRefine(const TrackedFrame& frame,
                       const std::shared_ptr<const LiveLighting>& lighting) override;
    // Adds `samples` more paths per pixel to the frozen shot.
    Status refineStep(uint32_t samples) override;
    // The plate-consistency meter on the last frame rendered (preview's frame, or refinement's
    // accumulation so far): L_or and the plate averaged over cells of kPlateMeterCellSamples
    // samples or more (plateMeterGridWidth), plate pixels beyond plateLimits() left out. None while
    // nothing is rendered or the lighting is pending (a stand-in says nothing of the set's
    // lighting).
    Result<std::optional<PlateConsistency>> measurePlateConsistency() override;
    // [lighting] fit_to_plate after a meter reading (ShotRenderer::fitLighting): auto fits when
    // the snapshot has clipped light no fit has corrected yet or the meter is off; on at every
    // reading; off never. A fit that fails leaves the lighting as it was and says why.
    LightingFitReport fitLighting(const TrackedFrame& frame,
                                  const PlateConsistency& reading) override;
    // The correction the fits so far make (none before the first).
    const std::optional<LightingCorrection>& lightingCorrection() const { return correction_; }
    // Forgets it (render-session fits every frame on its own).
    void resetLightingCorrection() {
        correction_.reset();
        correctedLighting_.reset();
        fitsOnRaw_ = 0;
    }
    // Whether fitLighting can fit at all ([lighting] fit_to_plate not off, a real set).
    bool fitsLighting() const { return fitPolicy_ != FitToPlate::Off && realTracer_ != nullptr; }
    // The plate values the meter trusts: codes 16 to 249 of the scene camera's 8-bit frames
    // through its radiometry (render/plate_consistency.h says why).
    const PlateLimits& plateLimits() const { return plateLimits_; }
    // The convergence meter's look at the refinement (its composite's relative RMSE).
    Result<std::optional<double>> measureNoise() override;

    // The composite so far, linear (the plate alone before the first pose), denoised as
    // [render] denoise says: in preview at the dial's (or the config's) strength; in
    // refinement with "auto" while `noiseEstimate` (the meter's) is above target_noise. Once per
    // preview frame: with preview_accumulate it is also the step that adds the frame to the
    // history.
    Result<ImageF> composite(std::optional<double> noiseEstimate = {});
    // The denoiser's strength the last composite() used (à-trous levels; 0: not denoised).
    uint32_t lastDenoiseLevels() const { return lastDenoiseLevels_; }
    // The composite as the monitor shows it: the scene camera's own curve applied forward, so
    // the untouched parts of the picture look exactly as the camera delivered them. composite()
    // tone mapped, made on the device (Renderer::display): the service's frame.
    Result<DisplayImage> display(std::optional<double> noiseEstimate = {});
    // The same curve applied on the host to a composite (from composite()), taken by value: it is
    // changed in place (callers move a temporary in).
    // With [output.colour] both show the composite through OpenColorIO's display and view
    // instead (on the device, its 65³ table: DisplaySettings::viewLut).
    DisplayImage toDisplay(ImageF composite) const;

    uint64_t samples() const override;  // per pixel: this preview frame's, or the refinement's
    uint32_t width() const { return width_; }
    uint32_t height() const { return height_; }
    // Preview's settings, the one holder (issue 55): configured and in use. Its writers (create,
    // the dial, ShotController's cap and a reload through it) call setPreview on the render
    // thread; any thread may read (the status asks for the samples in use).
    PreviewState preview() const override;
    Status setPreview(const PreviewSettings& configured, uint32_t samplesInUse) override;
    // In use: samples, resolution scale, depth, denoiser strength (0: not denoised) and photons
    // per preview frame where the photon pass runs.
    uint32_t previewSamples() const { return preview().inUse.samplesPerFrame; }
    float previewResolutionScale() const { return preview().inUse.resolutionScale; }
    uint32_t previewMaxDepth() const { return preview().inUse.maxDepth; }
    uint32_t previewDenoiseLevels() const { return preview().inUse.denoiseLevels; }
    uint32_t previewPhotons() const { return preview().inUse.photons; }
    // What the dial ([render] preview_fps) measured and chose at start; empty without it.
    const std::vector<DialMeasurement>& dialMeasurements() const { return dial_; }
    std::optional<size_t> dialChoice() const { return dialChoice_; }
    // The dial, corrected live: the service's preview frames take longer than the dial measured
    // at start, with the CPU to itself (tracking, lighting and display share it). Given the
    // median live frame time of the point in use, every measurement is scaled by live/measured
    // (or costs its own live time where that was longer lately: liveCosts) and the choice made
    // again; a dearer point must fit within kDialUpgradeMargin of the budget, so the choice
    // does not swing back and forth. A held camera's frames at refinement's depth cost
    // `heldCost` times the point's: where that would not keep the rate (holdKeepsRefineDepth),
    // they trace the point's own depth (a held view that keeps the rate converges a little
    // slower; one that drops it stutters). Returns what changed.
    std::optional<std::string> adaptDial(double liveFrameSeconds, double heldCost) override;
    bool hasDial() const override { return !dial_.empty(); }
    bool lastPreviewOffDial() const override { return heldAtRefineDepth_; }
    // The fisheye is configured but no snapshot of it has arrived: the virtual objects are lit
    // meanwhile by the box's saved lighting (LiveLighting::restored) or, without one, by a
    // neutral environment at the plate's level (never black).
    bool lightingPending() const override { return lightingPending_; }
    // Preview frames averaged into the shown one (the temporal history; 0: fixed sequence).
    uint32_t previewHistoryFrames() const;
    // Whether the last frame rendered the virtual objects (false before the first pose).
    bool rendered() const override { return rendered_; }
    // What is read of the renderer inside (not handed out): its device memory; the photon
    // pass's photons per iteration and gather radius in the last frame (0 without the pass);
    // the frames the held view holds; an AOV of the last frame; the plate it was composited on
    // (null before the first).
    uint64_t deviceBytes() const { return renderer_->deviceBytes(); }
    uint32_t lastPhotonCount() const {
        return renderer_->photonsActive() ? renderer_->lastPhotonCount() : 0;
    }
    float lastPhotonRadius() const {
        return renderer_->photonsActive() ? renderer_->lastPhotonRadius() : 0.0f;
    }
    uint64_t heldViewFrames() const { return renderer_->film().heldFrames(); }
    Result<ImageF> image(Aov aov) const { return renderer_->image(aov); }
    const ImageF* plate() const { return renderer_->film().plate(); }
    // render-session: each frame's own random sequence, and the flag that interrupts a pass.
    void setSeed(uint32_t seed) { renderer_->setSeed(seed); }
    void setInterrupt(const std::atomic<bool>* stop) { renderer_->setInterrupt(stop); }

private:
    // Tests check the inner renderer's state and drive it directly
    // (tests/shot/pipeline_renderer_access.h).
    friend struct PipelineRendererAccess;
    PipelineRenderer() = default;
    // [render] preview_fps: times every preview setting on the scene (its own camera, a grey
    // plate) and scores it against a short full-resolution reference, then takes the most
    // accurate one that reaches `fps` (render/quality_dial.h).
    Status chooseByDial(double fps, const PipelineStartHooks& hooks);
    // The settings the dial sweeps on this scene and device (chooseByDial).
    DialAxes dialAxes() const;
    // Plate, pose and lighting for the next samples.
    Status prepare(const TrackedFrame& frame, const std::shared_ptr<const LiveLighting>& lighting);

    std::unique_ptr<Renderer> renderer_;
    uint32_t width_ = 0;
    uint32_t height_ = 0;
    mutable std::mutex previewMutex_;
    PreviewState preview_;
    uint32_t refineDepth_ = 8;
    uint32_t seed_ = 0;            // [render] seed: preview's fixed sequence
    std::string denoise_ = "off";  // [render] denoise
    uint32_t denoiseLevels_ = 5;   // [render] denoise_levels
    uint32_t lastDenoiseLevels_ = 0;
    // Refinement's last denoised frame and its samples (composite() and display() reuse it a
    // while: denoisedOnce).
    template <typename Image>
    struct RefineCache {
        std::optional<Image> image;
        uint64_t samples = 0;
    };
    RefineCache<ImageF> refineComposite_;
    RefineCache<DisplayImage> refineDisplay_;
    template <typename Image, typename Make>
    Result<Image> denoisedOnce(RefineCache<Image>& cache, Make make);
    // Sets the denoiser's strength for this frame (lastDenoiseLevels_); whether it is denoised
    // (through the temporal stage in preview with accumulation).
    Result<bool> chooseFilter(std::optional<double> noiseEstimate);
    double targetNoise_ = 0.0;  // [refine] target_noise
    bool refining_ = false;
    std::vector<DialMeasurement> dial_;
    std::optional<size_t> dialChoice_;
    size_t dialInUse_ = 0;  // the measurement preview renders with
    double dialFps_ = 0.0;
    // Each point's own live time (liveCosts), and adaptDial's calls: its windows.
    std::vector<std::optional<DialLiveTime>> dialLive_;
    uint64_t dialWindows_ = 0;
    // Makes preview render with dial_[i].
    Status useDialPoint(size_t i);
    InverseToneMapSettings radiometry_;
    PlateLimits plateLimits_;
    DisplaySettings display_;
    std::shared_ptr<const DisplayColourTransform> displayColour_;  // [output.colour]; null: curve
    ImageF plate_;  // this frame's plate until it is moved into the renderer
    bool rendered_ = false;
    bool sceneCameraUntilTracked_ = false;
    // [render] preview_accumulate: preview frame k draws sequence k (Renderer::
    // renderPreviewFrame) and is averaged through the denoiser's reprojection.
    bool accumulate_ = false;
    // [render] preview_hold_depth: a held camera traces refinement's depth while that keeps the
    // dial's rate (adaptDial); the last preview frame did (lastPreviewOffDial).
    bool holdDepth_ = true;
    bool holdDepthKeepsRate_ = true;
    bool heldAtRefineDepth_ = false;
    // [render] preview_follow: while the camera moves, the held view's samples follow it.
    bool follow_ = true;
    // adaptDial's two choices at a slowdown: the point, and whether a held camera traces
    // refinement's depth; each says what it changed.
    std::optional<std::string> choosePoint(double slowdown, double liveFrameSeconds);
    std::optional<std::string> chooseHoldDepth(double slowdown, double heldCost);
    uint64_t previewFrame_ = 0;
    double lightingThreshold_ = 0.0;  // [refine] lighting_threshold: a change that resets it
    std::shared_ptr<const LiveLighting> historyLighting_;  // the snapshot the history began with
    bool lightingPending_ = false;
    bool neutralShown_ = false;
    // The neutral environment until the first snapshot: a vertical gradient around the plate's
    // mean radiance.
    Status lightNeutrally(const ImageF& plate);
    // A new snapshot: uploads it; a change beyond lighting_threshold restarts the history.
    Status applyLighting(const std::shared_ptr<const LiveLighting>& lighting);
    // Whether the camera has held still since heldSince_ (within kHeldPixels of a pixel's
    // angle): the held view (render/held_view.h) then keeps this frame's samples per output
    // pixel. A move, a lost pose, a lighting change or refinement starts it afresh.
    bool cameraHolds(const TrackedFrame& frame);
    std::optional<cv::Matx44d> heldSince_;
    // Refinement's view and the history's lighting then: a preview that resumes on both starts
    // its held view from refinement's samples (renderPreview).
    std::optional<cv::Matx44d> refinedPose_;
    std::shared_ptr<const LiveLighting> refinedLighting_;
    // A tracked pose jitters by a fraction of a pixel (0.05° on the demo take); a blur of up to a
    // pixel in the held view costs less than restarting it on every jitter.
    static constexpr double kHeldPixels = 1.0;
    static constexpr double kMinHeldDistanceM = 0.1;
    // Held (not a raw pointer) so a new snapshot can never reuse the shown one's address.
    std::shared_ptr<const LiveLighting> lightingShown_;
    // Lighting fitted to the plate: the policy, the real geometry on the CPU (built only when a
    // fit can run), the lens's corner rays, the correction the fits made and the newest raw
    // snapshot with its corrected copy.
    FitToPlate fitPolicy_ = FitToPlate::Off;
    std::unique_ptr<CpuTracer> realTracer_;
    glm::dvec3 sceneOriginM_{0.0};
    std::vector<glm::vec2> lensGrid_;
    std::optional<LightingCorrection> correction_;
    std::shared_ptr<const LiveLighting> rawLighting_, correctedLighting_;
    int fitsOnRaw_ = 0;  // fits since rawLighting_ arrived
    static constexpr int kMaxFitsPerLighting = 3;
    // |ln ratio| beyond which a snapshot with clipped light is fitted again: the meter's 5 %.
    static constexpr double kFitAgainBand = 0.05;
    // The snapshot to render with: `raw` through the correction.
    std::shared_ptr<const LiveLighting> withCorrection(
        const std::shared_ptr<const LiveLighting>& raw);
    // The meter's real-surface cells of the last frame rendered as fit samples, each with the
    // real surface its centre's camera ray meets.
    Result<std::vector<PlateSample>> plateSamples(const cv::Matx44d& worldFromCamera) const;
};

// The render size a config asks for: [render] width/height, else the scene camera's.
void renderSize(const ServiceConfig& config, uint32_t& width, uint32_t& height);

}  // namespace previs
