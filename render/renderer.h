#pragma once

// Runs the path tracer on a scene it uploads (render/gpu_scene.h: BVHs, materials, textures,
// lights, environment tables): progressive, exact accumulation of samples per pixel into its
// buffers, which its Film reads.

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string_view>
#include <utility>
#include <vector>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/compute_pipeline.h"
#include "gpu/context.h"
#include "gpu/interruptible_dispatch.h"
#include "gpu/specialise_mode.h"
#include "image/image.h"
#include "render/bvh.h"
#include "render/convergence.h"
#include "render/denoiser.h"
#include "render/film.h"
#include "render/gpu_scene.h"
#include "render/path_pipelines.h"
#include "render/photon_map.h"
#include "render/render_settings.h"
#include "render/renderer_diagnostics.h"
#include "render/upsample.h"
#include "scene/scene.h"

namespace previs {

// Switches only tests and benchmarks turn, to show or measure what the renderer's defaults buy
// (RenderSettings holds what a user sets).
struct RendererTestOptions {
    // Off only to demonstrate what happens without it: llvmpipe drops work (renderer.cpp).
    bool respectCpuLoopLimit = true;
    // Every feature's code in the pipelines, whatever the scene holds (benchmarks the saving).
    bool generalPipeline = false;
    // Where the feature constants are applied (gpu/compute_pipeline.h): on the host, so the
    // driver compiles only what the scene needs; InDriver only to compare against.
    Specialise specialise = Specialise::OnHost;
};

struct RenderProgress {
    uint64_t samplesDone;
    uint64_t samplesTotal;
};

class Renderer {
public:
    // How far create() is through the pipelines it compiles: `done` of `total`, first with 0
    // (the total is known before the first compile), then after each compile. The total grows
    // only where the uploaded scene's lights differ from what create() predicted from the file.
    using CompileProgress = std::function<void(size_t done, size_t total)>;
    static Result<std::unique_ptr<Renderer>> create(GpuContext& ctx, const Scene& scene,
                                                    const RenderSettings& settings,
                                                    const CompileProgress& progress = {},
                                                    const RendererTestOptions& testOptions = {});

    // Adds `samples` paths per pixel to the accumulation.
    Status render(uint32_t samples,
                  const std::function<void(const RenderProgress&)>& progress = {});
    // Clears the accumulation (refinement restarts at sample 0).
    Status reset();
    // Preview mode: one frame of `spp` samples per pixel that replaces the previous one. With
    // `frameIndex` 0 every frame draws the same random sequence, so the noise stays put while the
    // camera, plate or lighting change (the paper's interactive mode); frame k > 0 draws a
    // sequence of its own (its own scramble), so frames a temporal accumulation averages
    // (Denoiser::applyTemporal) are independent and a held camera converges. One sequence,
    // without the convergence meter's replicates: convergence() says nothing after it.
    Status renderPreviewFrame(uint32_t spp, uint64_t frameIndex = 0);
    // The seed preview frame `frameIndex` draws its sequence with, from the base `seed`
    // (RenderSettings::seed): frame 0's is the base itself.
    static uint32_t previewFrameSeed(uint32_t seed, uint64_t frameIndex);
    // Refinement mode: adds `spp` more samples to the accumulation, continuing the sequence, so
    // the image converges frame after frame (exact over millions of samples).
    Status refine(uint32_t spp) { return render(spp); }
    // The tracked camera pose for the next frames (world from camera, looking along −Z; world
    // coordinates, i.e. Scene::originM + the scene's own). Double keeps a far set's millimetres.
    //
    // Camera-relative rendering: the GPU sees positions relative to renderOriginM(), a point
    // near the camera, converted to float from double on the host, so precision (and the
    // self-intersection offset, which grows with the distance from the GPU's origin) is that
    // of a scene at the world origin wherever the set is. The origin is the camera position
    // snapped to a kRecentreGridM grid; it moves only when the camera gets more than
    // kRecentreDistanceM (per axis) from it, and then the next render re-uploads vertices, BVH
    // boxes and lights once (no BVH rebuild): a camera moving about a set never re-uploads
    // every frame.
    void setCameraPose(const glm::dmat4& worldFromCamera);
    void setCameraPose(const glm::mat4& worldFromCamera) {
        setCameraPose(glm::dmat4(worldFromCamera));
    }
    static constexpr double kRecentreGridM = 16.0;
    static constexpr double kRecentreDistanceM = 12.0;
    // The world position of the GPU's coordinate origin.
    glm::dvec3 renderOriginM() const { return scene_->renderOriginM(); }

    // Live lighting: each fisheye snapshot replaces the environment and the estimated lights
    // without touching the scene's geometry or BVH. Like setCameraPose, they take effect with
    // the next render and do not clear the accumulation (reset() before refining on).
    //
    // The environment's radiance, sampling tables and FrameParams; null or an empty map removes
    // it. Buffers are reallocated only when the map's size changes; the pipelines are
    // re-specialised only when the environment appears or disappears, by the next render()
    // (which returns a failed compile's error; render/path_pipelines.h).
    Status setEnvironment(std::shared_ptr<const EnvironmentMap> map);
    // Replaces the estimated lights (the scene's own lights stay). A new count reallocates the
    // lights buffer; lights appearing or disappearing re-specialise the pipelines, as above.
    Status setEstimatedLights(std::span<const EstimatedLightSource> lights);

    // Whether renders run the photon pass (the settings' mode and the scene decide; estimated
    // lights can switch an Auto renderer on), its photons per iteration and the gather radius
    // the next sample will use (metres).
    bool photonsActive() const { return params_.photonLightCount > 0; }
    uint32_t photonsPerIteration() const { return params_.photonCount; }
    float nextPhotonRadius() const;
    // The photons and gather radius of the last photon iteration rendered (a preview frame's
    // budget and its radius, which differ from refinement's); 0 before any. The diagnostics'
    // photonRecords and photonGrid hold that iteration.
    uint32_t lastPhotonCount() const { return lastPhotonCount_; }
    float lastPhotonRadius() const { return params_.photonRadius; }
    const PhotonAim& photonAim() const { return scene_->photonAim(); }
    // GPU time of the photon passes so far (ms; part of gpuMilliseconds()).
    double photonMilliseconds() const { return photonMs_; }

    // Changes RenderSettings::resolutionScale (preview renders at a fraction, refinement at 1).
    // When the traced size changes, the accumulation is reallocated and cleared; otherwise
    // nothing happens. An out-of-range scale is an error and changes nothing.
    Status setResolutionScale(float scale);
    float resolutionScale() const { return settings_.resolutionScale; }
    // The pixels the path tracer traces (the output size at resolution scale 1).
    uint32_t traceWidth() const { return params_.width; }
    uint32_t traceHeight() const { return params_.height; }

    // A held camera's preview (render/held_view.h, Film::holdView): on, the next frames also add
    // each sample to the output pixel it landed in and the composite keeps those per output
    // pixel; off, the kept samples are forgotten. On does nothing at full resolution (there is
    // nothing to gain).
    Status holdView(bool on);
    // The camera moved since the last preview frame (set its pose first): the held view stays on
    // and its samples follow the camera (render/held_reprojection.h), so the output's resolution
    // keeps a short history while the camera moves too.
    Status followView();
    // The held view's samples as kept (PV_BINDING_HELD_SAMPLES' layout); none while it is off.
    Result<std::vector<glm::vec4>> heldSamples() const;
    // Refinement's samples so far, as the held view keeps samples (Film::heldSamplesOf): read
    // them before the preview's resolution scale replaces the accumulation, and hand them to
    // seedHeldView once the held view is on, so a preview that resumes on the refined view shows
    // what refinement reached instead of starting again.
    Result<std::vector<glm::vec4>> refinedSamples() const { return film_->heldSamplesOf(traced()); }
    // The held view, on and empty, starts from `samples` (refinedSamples, traced from the camera
    // now set); nothing while it is off.
    Status seedHeldView(std::span<const glm::vec4> samples);

    // The most scattering events on a path for the next renders (RenderSettings::maxDepth; the
    // preview can trace shorter paths than refinement). Call reset() before refining on.
    void setMaxDepth(uint32_t maxDepth);
    uint32_t maxDepth() const { return params_.maxDepth; }

    // The denoiser's strength for the next denoised image(): its à-trous levels (DenoiseSettings::
    // iterations, 1..10; needs RenderSettings::denoise). The dial sweeps it.
    Status setDenoiseIterations(uint32_t iterations);
    // The budget of preview frames' photon pass (PhotonSettings::previewPerIteration; at most
    // the buffers' per-iteration count). Nothing changes without an active photon pass.
    Status setPreviewPhotons(uint32_t photons);

    // A flag that, once set, ends the render in progress early with an error (a service
    // stopping; a partial render's buffers are not to be shown). While a flag is set up here,
    // each pass runs in parts of about kInterruptiblePartMs so a stop never waits for a whole
    // frame on a slow device; the parts change no result. nullptr: one dispatch per pass.
    void setInterrupt(const std::atomic<bool>* stop) { interrupt_ = stop; }

    // Selects another random sequence (takes effect with the next render; call reset() first
    // unless the new samples are meant to join the old ones).
    void setSeed(uint32_t seed) { params_.seed = seed; }

    // The film (render/film.h): the plate, upsampling, the denoiser and the held view's frames.
    // The queries below that read the accumulation stay here, since they hand the film this
    // renderer's buffers.
    Film& film() { return *film_; }
    const Film& film() const { return *film_; }

    // The mean per pixel so far (RGB linear; the mask one channel), at the output size. At a
    // resolution scale below 1 the traced means are upsampled (render/upsample.h; guided by the
    // plate when there is one); the composite upsamples its two plate-free terms of Eq. 1, the
    // mean of M·L_om + (1−M)(L_om − L_or) and the mask M, and adds (1 − M)·L_oc with the
    // full-resolution plate.
    Result<ImageF> image(Aov aov = Aov::Composite) const { return film_->image(traced(), aov); }
    // The convergence meter (render/convergence.h): the estimated relative RMSE of the
    // composite and of L_om − L_or so far, from the two interleaved replicates (none without
    // RenderSettings::convergenceMeter). One readback of the accumulation, as image() does.
    Result<Convergence> convergence() const { return film_->convergence(traced(), samples_); }
    // What the plate-consistency meter needs (render/plate_consistency.h), at the traced size
    // (never upsampled: the meter averages cells of it) from one readback: 5 channels, the mean
    // of L_or (RGB), the fraction of samples whose camera ray first hit phantom geometry, and the
    // mask M. An error in a render that is not differential.
    Result<ImageF> realSurfaceMeans() const { return film_->realSurfaceMeans(traced()); }
    // The same, denoised where `denoised` (needs RenderSettings::denoise): Composite, Mixed and
    // Real are filtered, the composite before Eq. 1 adds the plate term (1 − M)·L_oc, so the
    // camera image itself is never filtered; the other AOVs are returned as image(aov). At a
    // resolution scale below 1 the traced pixels are filtered, then upsampled as image() does.
    Result<ImageF> image(Aov aov, bool denoised) {
        return film_->image(traced(), aov, denoised, denoiseCamera());
    }
    // image(Composite, denoised) as the monitor shows it (Film::display): composited and tone
    // mapped to 8-bit sRGB on the device.
    Result<DisplayImage> display(bool denoised, const DisplaySettings& settings) {
        return film_->display(traced(), denoised, denoiseCamera(), settings);
    }
    // GPU time of the last denoised image()'s filter dispatches (ms).
    double denoiseMilliseconds() const {
        return film_->denoiser() ? film_->denoiser()->lastGpuMilliseconds() : 0.0;
    }
    // The camera of the next render, for the denoiser's temporal reprojection
    // (Denoiser::applyTemporal).
    DenoiseCamera denoiseCamera() const { return {worldFromCameraM_, params_.tanHalfFov}; }

    uint64_t samplesPerPixel() const { return samples_; }
    RendererDiagnostics diagnostics() const { return RendererDiagnostics(*this); }
    const SceneFeatures& features() const { return scene_->features(); }
    const SceneBvh& bvh() const { return scene_->bvh(); }
    // GPU time of all dispatches so far (ms), and of the last one.
    double gpuMilliseconds() const { return gpuMs_; }
    // Samples the shader found NaN or infinite, or that cast a ray with a NaN/Inf origin or
    // direction, and dropped (should be 0; tests check it). Pixel means are over the samples
    // that were kept (image()).
    Result<uint32_t> nonFiniteSamples() const;
    // The shader's counters since the last reset (RenderStats: dropped samples, culled
    // non-finite rays, rays traced).
    Result<shader::RenderStats> stats() const;
    // Rays traced since the last reset (closest-hit and shadow; wraps at 2^32).
    Result<uint32_t> raysTraced() const;
    // The camera, its pose in world coordinates in float (worldFromCameraM() in double).
    const Camera& camera() const { return camera_; }
    const glm::dmat4& worldFromCameraM() const { return worldFromCameraM_; }
    // Bytes of device memory in this renderer's buffers (scene, accumulation, lighting, the
    // held view) and its film's (the denoiser's with its history, the display pass's); the
    // staging copies of an upload or readback come and go on top.
    uint64_t deviceBytes() const {
        uint64_t total = film_->deviceBytes();
        for (auto [binding, buffer] : kFrameBindings) total += ((*buffers_).*buffer).size();
        return total + scene_->deviceBytes();
    }

private:
    // The held view's buffer for the film's answer `on` (made when first needed, cleared while
    // the film keeps no samples) and the path tracer's parameters that write it.
    Status useHeldView(bool on);
    // The reservoirs' buffer at the traced size for a preview frame that resamples (made when
    // first needed; its history forgotten when remade).
    Status useReservoirs();
    // A preview frame's phase schedule (RenderSettings::previewPhases) where it has a held view:
    // its samples' phases from `firstPhase` on (frame k of spp samples: k·spp, so a frame
    // rendered alone draws what it draws in its sequence).
    void usePhaseSchedule(uint32_t firstPhase);
    friend class RendererDiagnostics;
    // The renderer's own device buffers (the scene's are GpuScene's), one per PV_BINDING_*.
    struct FrameBuffers {
        GpuBuffer params;             // shader::FrameParams
        GpuBuffer accumSum;           // the accumulation (Film's TracedBuffers)
        GpuBuffer accumCompensation;  // its Kahan compensation
        GpuBuffer stats;              // shader::RenderStats
        GpuBuffer lensGrid;           // at the traced size (empty without a calibrated lens)
        // One photon iteration's records, their sorted copy and the grid (render/photon_map.h):
        // sized where photons may run.
        GpuBuffer photonRecords, photonSorted, photonSortA, photonSortB, photonBlockCounts,
            photonCells;
        GpuBuffer guides;        // the denoiser's guides, in the accumulation's bands
        GpuBuffer photonSplats;  // photonSplatBytes(); empty where the renderer does not splat
        GpuBuffer heldSamples;   // the held view's, made by holdView when first needed
        GpuBuffer reservoirs;    // the preview's resampling, made by its first frame
    };
    static constexpr std::pair<int, GpuBuffer FrameBuffers::*> kFrameBindings[] = {
        {PV_BINDING_PARAMS, &FrameBuffers::params},
        {PV_BINDING_ACCUM_SUM, &FrameBuffers::accumSum},
        {PV_BINDING_ACCUM_COMPENSATION, &FrameBuffers::accumCompensation},
        {PV_BINDING_STATS, &FrameBuffers::stats},
        {PV_BINDING_LENS_GRID, &FrameBuffers::lensGrid},
        {PV_BINDING_PHOTON_RECORDS, &FrameBuffers::photonRecords},
        {PV_BINDING_PHOTON_SORTED, &FrameBuffers::photonSorted},
        {PV_BINDING_PHOTON_SORT_A, &FrameBuffers::photonSortA},
        {PV_BINDING_PHOTON_SORT_B, &FrameBuffers::photonSortB},
        {PV_BINDING_PHOTON_BLOCK_COUNTS, &FrameBuffers::photonBlockCounts},
        {PV_BINDING_PHOTON_CELLS, &FrameBuffers::photonCells},
        {PV_BINDING_GUIDES, &FrameBuffers::guides},
        {PV_BINDING_PHOTON_SPLATS, &FrameBuffers::photonSplats},
        {PV_BINDING_HELD_SAMPLES, &FrameBuffers::heldSamples},
        {PV_BINDING_RESERVOIRS, &FrameBuffers::reservoirs},
    };
    // The accumulation as the film reads it.
    TracedBuffers traced() const;

    Renderer() = default;
    // The frame's parameters that the scene does not set (camera, size, depth, photons).
    void setFrameParams();
    // The renderer's own buffers for the output's size (params_ set).
    Result<FrameBuffers> createFrameBuffers() const;
    // Every binding's buffer, the scene's and the renderer's (PV_BINDING_* order).
    std::array<GpuBuffer*, PV_BINDING_COUNT> bindingTable();
    // Photon mapping may run in this scene: forced on, or --photons auto with a specular object.
    bool photonsPossible(const PhotonAim& aim) const;
    // Bytes of the photon splat sums (PV_BINDING_PHOTON_SPLATS) at the output's size; 0 where
    // the renderer does not splat.
    size_t photonSplatBytes(const PhotonAim& aim) const;
    // The specialization constants of the pipelines for `features` and the settings, with
    // photon mapping on or off.
    PipelineConstants pipelineConstants(const SceneFeatures& features, bool photons) const;
    // The pipelines for the current features (compiled where they changed: one compile for a
    // whole lighting snapshot, at the next render), with the buffers bound.
    Status ensurePipelines();
    // Binds the buffers, the accumulation from row `bandFirstRow` on (accumulationBand).
    Status bindBuffers(uint32_t bandFirstRow = 0);
    // Sets bandRows_ for a traced frame of width × height (an error when one row of
    // workgroups is already more than the device binds).
    Status sizeBands(uint32_t width, uint32_t height);
    // The accumulation's part for the band of rows from `firstRow` (bandRows_ rows, fewer at
    // the bottom); the other bindings whole.
    std::vector<BufferRange> accumulationBand(uint32_t firstRow) const;
    uint32_t samplesForNextDispatch(uint32_t remaining) const;
    // Traced pixels [x0, x1) × [y0, y1).
    struct TraceRegion {
        uint32_t x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    };
    // One path-tracing dispatch of params_'s samples over `region`, band by band; its GPU ms.
    Result<double> dispatchPaths(const TraceRegion& region);
    // The traced pixels `box` covers from this frame's pose; none when it is out of view.
    std::optional<TraceRegion> boxRegion(const WorldBox& box) const;
    // The virtual objects' regions this frame: virtualBoxes_' regions, overlapping ones merged.
    std::vector<TraceRegion> objectRegions() const;
    // A preview frame below full resolution adds samples over objectRegions()
    // (RenderSettings::objectSamplesPerOutputPixel), at most kObjectSampleBudget of its own
    // `frameSamples` a traced pixel, in the accumulation and the held view alike.
    Status traceObjectRegions(uint32_t frameSamples);
    // Moves the GPU's origin to `originM` (world): the scene re-uploads what moved.
    Status recentre(const glm::dvec3& originM);
    // The traced size for a resolution scale, and the lens grid resampled to it.
    void traceSize(float scale, uint32_t& width, uint32_t& height) const;
    std::vector<glm::vec2> traceLensGrid(uint32_t width, uint32_t height) const;

    GpuContext* ctx_ = nullptr;
    RenderSettings settings_;
    RendererTestOptions testOptions_;
    Camera camera_;
    shader::FrameParams params_{};
    // The scene and the renderer's buffers: optional only so that create() can make them.
    std::optional<GpuScene> scene_;
    std::optional<FrameBuffers> buffers_;
    std::optional<PathPipelines> pipelines_;  // set in create(): it needs the context
    const std::atomic<bool>* interrupt_ = nullptr;
    InterruptibleDispatch pathParts_{kInterruptiblePartMs};
    glm::dmat4 worldFromCameraM_{1.0};
    // Boxes around the virtual geometry (GpuScene::virtualBoxes), kObjectBoxLevels below the
    // root.
    std::vector<WorldBox> virtualBoxes_;
    // The lens grid at the traced size (empty without a calibrated lens), as the device has it.
    std::vector<glm::vec2> traceLensGrid_;
    // The added samples' pixels, in traced pixels × samples, of the last preview frame.
    uint64_t objectRegionSamples_ = 0;
    // objectRegion: a box corner this close to the camera plane (or behind it) makes it the
    // whole frame; the region's margin in traced pixels. traceObjectRegion: its samples are at
    // most this fraction of the frame's own (an object filling the frame costs at most 1.5×).
    static constexpr double kObjectRegionNearM = 0.01;
    static constexpr uint32_t kObjectRegionMargin = 2;
    static constexpr double kObjectSampleBudget = 0.5;
    static constexpr uint32_t kObjectBoxLevels = 3;
    uint64_t sceneBuilds_ = 0;
    uint64_t samples_ = 0;
    uint32_t bandRows_ = 0;  // rows per dispatch: the storage-buffer range limits it
    // The accumulation's interleaved sequences (shared/sampler.h): 2 with the convergence meter,
    // 1 for preview frames; 0 until its first sample.
    uint32_t accumulationReplicates_ = 0;
    double gpuMs_ = 0.0;
    double loopIterationsPerSample_ = 0.0;  // the most one lane ran per sample, measured
    uint64_t loopLimitRisks_ = 0;
    bool photonSplats_ = false;  // the splat buffer exists (PV_SPEC_PHOTON_SPLAT)
    double photonMs_ = 0.0;
    uint32_t lastPhotonCount_ = 0;  // params_.photonCount is refinement's again after a preview
    // Means, AOVs, Eq. 1, upsampling, the denoiser and the meter (render/film.h); optional only
    // so that create() can make it once the traced size is known.
    std::optional<Film> film_;
};

}  // namespace previs
