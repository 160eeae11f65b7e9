#include "shot/pipeline_renderer.h"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "base/log.h"
#include "scene/environment_map.h"
#include "shot/refine_watch.h"
#include "vision/inverse_tone_map.h"
#include "vision/lens_grid.h"

namespace previs {

namespace {

// The dial's pan (DialMotion): the image moves this many pixels a frame, a steady operator's pan
// (at 15 fps and 640×360 with a 50° field, about 17° a second).
constexpr double kDialPanPixels = 8.0;

// The calibration of the same lens sampled at another resolution: focal lengths and principal
// point scale with the pixel size (pixel centres at x + 0.5), distortion is unitless.
Result<CameraCalibration> scaledCalibration(const CameraCalibration& c, uint32_t width,
                                            uint32_t height) {
    const cv::Size size = c.imageSize();
    if (size.width == int(width) && size.height == int(height)) return c;
    const double sx = double(width) / size.width, sy = double(height) / size.height;
    cv::Matx33d k = c.cameraMatrix();
    k(0, 0) *= sx;
    k(0, 1) *= sx;
    k(0, 2) = (k(0, 2) + 0.5) * sx - 0.5;
    k(1, 1) *= sy;
    k(1, 2) = (k(1, 2) + 0.5) * sy - 0.5;
    return CameraCalibration::create(k, c.distortion(), cv::Size(int(width), int(height)),
                                     c.model(), "scene camera scaled to the render size");
}

ToneMapSettings forwardOf(const InverseToneMapSettings& inverse) {
    ToneMapSettings t;
    t.exposureStops = inverse.exposureStops;
    t.maxRadiance = inverse.maxRadiance;
    t.whiteLuminance = inverse.whiteLuminance;
    switch (inverse.op) {
        case InverseToneMapOperator::Srgb:
            t.op = ToneMapOperator::Clamp;
            break;
        case InverseToneMapOperator::Reinhard:
            t.op = ToneMapOperator::Reinhard;
            break;
        case InverseToneMapOperator::Banterle:
            t.op = ToneMapOperator::ReinhardExtended;
            break;
    }
    return t;
}

std::vector<EstimatedLightSource> toLightSources(const std::vector<EstimatedLight>& lights) {
    std::vector<EstimatedLightSource> out;
    out.reserve(lights.size());
    for (const EstimatedLight& l : lights) {
        EstimatedLightSource s;
        s.direction = glm::normalize(glm::vec3(l.direction[0], l.direction[1], l.direction[2]));
        s.solidAngleSr = float(l.solidAngleSr);
        s.radiance = glm::vec3(l.radiance[0], l.radiance[1], l.radiance[2]);
        out.push_back(s);
    }
    return out;
}

// The darkest and the brightest 8-bit codes the plate-consistency meter trusts (PlateLimits): a
// JPEG's ringing spreads a saturated 255 a few codes down, so 250 and above count as clipped.
constexpr uint8_t kPlateDarkCode = 16;
constexpr uint8_t kPlateClippedCode = 250;

// The composite (scene radiance) back to the camera's exposure and white, as the curve path
// does (toDisplayImage), then through the display's view.
DisplayImage throughView(const DisplayColourTransform& view, ImageF composite,
                         const InverseToneMapSettings& radiometry) {
    std::array<float, 3> gain;
    for (int c = 0; c < 3; ++c)
        gain[c] = std::exp2(radiometry.exposureStops) / radiometry.whiteBalance[c];
    DisplayImage out{composite.width, composite.height,
                     std::vector<uint8_t>(size_t(composite.width) * composite.height * 3)};
    view.applyScaled(composite.pixels.data(), int(composite.channels), int(composite.width),
                     int(composite.height), gain, out.rgb.data());
    return out;
}

PlateLimits plateLimitsOf(const InverseToneMapSettings& radiometry) {
    cv::Mat codes(1, 2, CV_8UC3);
    codes.at<cv::Vec3b>(0, 0) = cv::Vec3b(kPlateDarkCode, kPlateDarkCode, kPlateDarkCode);
    codes.at<cv::Vec3b>(0, 1) = cv::Vec3b(kPlateClippedCode, kPlateClippedCode, kPlateClippedCode);
    const cv::Mat linear = inverseToneMapRgb8(codes, radiometry);
    PlateLimits limits;
    for (int c = 0; c < 3; ++c) {
        limits.dark[c] = linear.at<cv::Vec3f>(0, 0)[c];
        limits.clipped[c] = linear.at<cv::Vec3f>(0, 1)[c];
    }
    return limits;
}

}  // namespace

void renderSize(const ServiceConfig& config, uint32_t& width, uint32_t& height) {
    width = config.render.width ? config.render.width : config.sceneCamera.width;
    height = config.render.height ? config.render.height : config.sceneCamera.height;
}

Result<std::unique_ptr<PipelineRenderer>> PipelineRenderer::create(
    GpuContext& ctx, Scene scene, const ServiceConfig& config, const PipelineStartHooks& hooks) {
    std::unique_ptr<PipelineRenderer> p(new PipelineRenderer());
    renderSize(config, p->width_, p->height_);
    PreviewSettings preview;
    preview.samplesPerFrame = config.liveRender.samplesPerFrame;
    preview.resolutionScale = config.render.resolutionScale;
    p->radiometry_ = config.sceneCamera.radiometry;
    p->plateLimits_ = plateLimitsOf(p->radiometry_);
    p->display_.tone = forwardOf(p->radiometry_);
    p->display_.whiteBalance = p->radiometry_.whiteBalance;
    p->displayColour_ = config.output.colour;
    // The view on the device too: its table uploaded once, applied in the display pass.
    if (p->displayColour_) {
        p->display_.viewLut = p->displayColour_->lut();
        p->display_.viewLutSize = DisplayColourTransform::kLutSize;
    }
    p->sceneCameraUntilTracked_ = config.tracking.sceneCameraUntilTracked;

    RenderSettings settings;
    settings.width = p->width_;
    settings.height = p->height_;
    settings.maxDepth = config.render.maxDepth;
    settings.seed = config.render.seed;
    settings.photons = config.render.photons;
    settings.differential = true;
    settings.objectSamplesPerOutputPixel = float(config.render.previewObjectSamples);
    settings.previewSampleClamp = float(config.render.previewSampleClamp);
    settings.previewResampling = config.render.previewResampling;
    settings.previewPhases = config.render.previewPhases;
    settings.previewOutlineTest = config.render.previewOutlineTest;
    // Guides are written only when the denoiser may run: to filter, or to reproject preview's
    // accumulation.
    p->accumulate_ = config.render.previewAccumulate;
    p->holdDepth_ = config.render.previewHoldDepth;
    p->follow_ = config.render.previewFollow;
    settings.denoise = config.render.denoise != "off" || p->accumulate_;
    settings.denoiseSettings.iterations = config.render.denoiseLevels;
    if (p->accumulate_) {
        // A plain mean of up to N frames, then weight 1/N: a held camera converges as refinement
        // would at N times the samples.
        settings.denoiseSettings.maxHistoryFrames = float(config.render.previewHistoryFrames);
        settings.denoiseSettings.temporalAlpha = 1.0f / float(config.render.previewHistoryFrames);
    }
    p->lightingThreshold_ = config.refine.lightingThreshold;
    p->lightingPending_ = config.fisheyeCamera.has_value();
    settings.samplesPerDispatch = 64;  // the renderer lowers it inside the CPU loop limit
    Result<CameraCalibration> calibration =
        scaledCalibration(*config.sceneCamera.calibration, p->width_, p->height_);
    if (!calibration) return calibration.error();
    Result<std::vector<glm::vec2>> grid = lensRayGrid(*calibration, p->width_, p->height_);
    if (!grid) return makeError("{}: scene camera calibration: {}", config.path, grid.message());
    settings.lensGrid = *grid;
    // The fit to the plate needs the real set on the CPU: built only when the fisheye lights the
    // scene and the fit is not off, from the real triangles alone (the phantom set is small).
    p->fitPolicy_ = config.lighting.fitToPlate;
    if (config.fisheyeCamera && p->fitPolicy_ != FitToPlate::Off) {
        Result<CpuTracer> tracer = CpuTracer::create(realGeometry(scene.geometry));
        if (!tracer)
            return makeError("{}: the real set for the lighting fit: {}", config.scenePath,
                             tracer.message());
        if (tracer->triangles().empty())
            p->fitPolicy_ = FitToPlate::Off;  // nothing real to fit against: said by fitLighting
        else
            p->realTracer_ = std::make_unique<CpuTracer>(std::move(*tracer));
        p->sceneOriginM_ = scene.originM;
        p->lensGrid_ = std::move(*grid);
    }
    // The stage counts the renderer's pipelines, whose total it knows before its first compile
    // (and raises where its prediction from the file missed).
    size_t compilesStaged = 0;
    auto compiling = [&hooks, &compilesStaged](size_t done, size_t total) {
        if (total != compilesStaged && hooks.stage)
            hooks.stage(PipelineStartHooks::kCompilingStage, total);
        compilesStaged = total;
        if (hooks.progress) hooks.progress(done, total);
    };
    // Lit from the fisheye, every frame has an environment: the studio stand-in until the first
    // snapshot (lightNeutrally), then the captured one. The renderer is made with the stand-in
    // already in the scene, so the pipelines it compiles first are those frames render with; made
    // without, the first frame compiled them again (minutes on a slow CPU).
    if (config.fisheyeCamera && !scene.environment) scene.environment = studioEnvironment();
    Result<std::unique_ptr<Renderer>> renderer = Renderer::create(ctx, scene, settings, compiling);
    if (!renderer) return makeError("{}: {}", config.scenePath, renderer.message());
    p->renderer_ = std::move(*renderer);
    if (hooks.interrupt) p->renderer_->setInterrupt(hooks.interrupt);
    p->refineDepth_ = config.render.maxDepth;
    preview.maxDepth = config.render.previewMaxDepth > 0
                           ? std::min(config.render.previewMaxDepth, config.render.maxDepth)
                           : config.render.maxDepth;
    p->seed_ = config.render.seed;
    p->denoise_ = config.render.denoise;
    p->denoiseLevels_ = config.render.denoiseLevels;
    p->targetNoise_ = config.refine.targetNoise;
    preview.photons = config.render.photons.previewPerIteration;
    // Without the dial, "auto" follows autoDenoise for a preview frame: no estimate, its spp.
    const bool previewDenoised =
        p->denoise_ == "on" || (p->denoise_ == "auto" && autoDenoise(std::nullopt, p->targetNoise_,
                                                                     preview.samplesPerFrame));
    preview.denoiseLevels = previewDenoised ? p->denoiseLevels_ : 0;
    if (Status s = p->setPreview(preview, preview.samplesPerFrame); !s) return s.error();
    if (config.render.previewFps > 0.0)
        if (Status s = p->chooseByDial(config.render.previewFps, hooks); !s) return s.error();
    return p;
}

Status PipelineRenderer::chooseByDial(double fps, const PipelineStartHooks& hooks) {
    // Samples of the reference: its noise adds the same expected squared error to every point,
    // so it orders them as a converged one would, at a few seconds' cost.
    constexpr uint32_t kReferenceSpp = 16;
    const auto start = std::chrono::steady_clock::now();
    Renderer& r = *renderer_;
    // The grid first: the stage says from its start how many settings it times.
    const std::vector<DialPoint> grid = dialGrid(dialAxes());
    if (hooks.stage)
        hooks.stage(fmt::format("timing the preview's settings for {:.3g} fps", fps), grid.size());
    ImageF grey;
    grey.width = width_;
    grey.height = height_;
    grey.channels = 3;
    grey.pixels.assign(size_t(width_) * height_ * 3, 0.18f);
    if (Status s = r.film().setPlate(std::move(grey), "the dial's grey plate"); !s) return s;
    if (Status s = r.setResolutionScale(1.0f); !s) return s;
    r.setMaxDepth(refineDepth_);
    if (Status s = r.reset(); !s) return s;
    // A sequence of its own: with preview's, a preview frame's samples would be the first of
    // the reference's and look closer to it than they are.
    r.setSeed(seed_ ^ 0x9e3779b9u);
    if (Status s = r.render(kReferenceSpp); !s) return s;
    r.setSeed(seed_);
    Result<ImageF> reference = r.image(Aov::Composite);
    if (!reference) return reference.error();
    // Each point is timed on a pan that ends at the reference's view, through the same temporal
    // stage preview runs (DialMotion): what the denoiser and reprojection gain or cost in motion
    // decides, not a still camera's single frame. Points that cannot fit the frame budget are not
    // rendered (measureDial).
    DialMotion pan;
    pan.panStepRad = kDialPanPixels * double(r.camera().fovYRad) / double(height_);
    pan.accumulate = accumulate_;
    Result<std::vector<DialMeasurement>> measured =
        measureDial(r, grid, *reference, 2, 1.0 / fps, pan, hooks.progress);
    if (!measured) return measured.error();
    dial_ = std::move(*measured);
    if (dial_.empty()) return makeError("render: the dial measured no preview setting");
    // Live times are by measurement index: a new measurement's order is its own.
    dialLive_.clear();
    dialWindows_ = 0;
    dialChoice_ = chooseForFrameRate(dial_, fps);
    size_t chosen = 0;
    if (dialChoice_) {
        chosen = *dialChoice_;
    } else {
        // None fits: the fastest, and say so.
        chosen = fastest(dial_).value_or(0);
        logWarning(
            "render: no preview setting reaches {:.1f} fps on this scene and device; the "
            "fastest, {}, takes {:.0f} ms a frame (lower render.preview_fps or the render size)",
            fps, dial_[chosen].point.describe(), dial_[chosen].frameSeconds * 1e3);
    }
    dialFps_ = fps;
    if (Status s = useDialPoint(chosen); !s) return s;
    const DialMeasurement& m = dial_[chosen];
    logInfo(
        "render: preview at {:.3g} fps: {} ({:.0f} ms a frame here; {} settings timed in {:.1f} s)",
        fps, m.point.describe(), m.frameSeconds * 1e3, dial_.size(),
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    r.setMaxDepth(refineDepth_);
    if (Status s = r.setResolutionScale(1.0f); !s) return s;
    return r.reset();
}

DialAxes PipelineRenderer::dialAxes() const {
    const Renderer& r = *renderer_;
    DialAxes axes;
    // 1/6 is the floor for a loaded box: the demo's frames at 1/4 took 68 ms live on lavapipe (2
    // cores, tracking and lighting beside them), over a 15 fps budget; at 1/6 57 ms.
    axes.scales = {1.0f, 0.5f, 1.0f / 3.0f, 0.25f, 1.0f / 6.0f};
    axes.samples = {1, 2, 4};
    for (uint32_t d : {2u, 4u, 8u})
        if (d <= refineDepth_) axes.depths.push_back(d);
    if (axes.depths.empty()) axes.depths.push_back(refineDepth_);
    // The denoiser's strength: off or two strengths with "auto", the configured one with "on".
    if (denoise_ == "auto") axes.denoiseLevels = {0, 2, 4};
    if (denoise_ == "on") axes.denoiseLevels = {denoiseLevels_};
    // The photon budget, where the scene runs the photon pass: around the configured one.
    if (r.photonsActive()) {
        const uint32_t configured = std::max(128u, preview().configured.photons);
        for (uint32_t n : {configured / 4, configured, configured * 4})
            if (n >= 128 && n <= r.photonsPerIteration()) axes.photonBudgets.push_back(n);
        if (axes.photonBudgets.empty()) axes.photonBudgets.push_back(r.photonsPerIteration());
    }
    return axes;
}

Status PipelineRenderer::useDialPoint(size_t i) {
    const DialPoint& p = dial_[i].point;
    dialInUse_ = i;
    return setPreview(
        {p.samplesPerFrame, p.resolutionScale, p.maxDepth, p.denoiseIterations, p.photons},
        p.samplesPerFrame);
}

PreviewState PipelineRenderer::preview() const {
    std::lock_guard lock(previewMutex_);
    return preview_;
}

Status PipelineRenderer::setPreview(const PreviewSettings& configured, uint32_t samplesInUse) {
    PreviewState next{configured, configured};
    next.inUse.samplesPerFrame = std::max(1u, std::min(samplesInUse, configured.samplesPerFrame));
    // Set every time (it only writes the renderer's setting): the dial's timing leaves the
    // renderer at the budget it timed last, whatever the configured one was.
    if (configured.photons > 0)
        if (Status s = renderer_->setPreviewPhotons(configured.photons); !s) return s;
    std::lock_guard lock(previewMutex_);
    preview_ = next;
    return {};
}

std::optional<std::string> PipelineRenderer::adaptDial(double liveFrameSeconds, double heldCost) {
    if (dial_.empty() || !(dialFps_ > 0.0) || !(liveFrameSeconds > 0.0)) return std::nullopt;
    const double slowdown = liveFrameSeconds / dial_[dialInUse_].frameSeconds;
    dialLive_.resize(dial_.size());
    dialLive_[dialInUse_] =
        nextLiveTime(dialLive_[dialInUse_], liveFrameSeconds, ++dialWindows_, dialFps_);
    std::optional<std::string> point = choosePoint(slowdown, liveFrameSeconds);
    std::optional<std::string> hold = chooseHoldDepth(slowdown, heldCost);
    if (!hold) return point;
    return (point ? *point : dial_[dialInUse_].point.describe()) + "; " + *hold;
}

std::optional<std::string> PipelineRenderer::choosePoint(double slowdown, double liveFrameSeconds) {
    const DialMeasurement& current = dial_[dialInUse_];
    const std::vector<DialMeasurement> costs = liveCosts(dial_, slowdown, dialLive_, dialWindows_);
    const std::optional<size_t> fits = chooseForFrameRate(costs, dialFps_);
    // None fits even now: the fastest.
    const size_t next = fits ? *fits : fastest(costs).value_or(dialInUse_);
    if (next == dialInUse_) return std::nullopt;
    const DialMeasurement& candidate = dial_[next];
    if (candidate.frameSeconds > current.frameSeconds &&
        costs[next].frameSeconds > kDialUpgradeMargin / dialFps_)
        return std::nullopt;
    if (Status s = useDialPoint(next); !s) {
        logWarning("render: the dial cannot switch to {}: {}", candidate.point.describe(),
                   s.message());
        return std::nullopt;
    }
    dialChoice_ = fits;
    return fmt::format("{} (live frames took {:.0f} ms, {:.2f}x the {:.0f} ms measured at start)",
                       candidate.point.describe(), liveFrameSeconds * 1e3, slowdown,
                       current.frameSeconds * 1e3);
}

std::optional<std::string> PipelineRenderer::chooseHoldDepth(double slowdown, double heldCost) {
    const DialMeasurement& point = dial_[dialInUse_];
    const double heldSeconds = point.frameSeconds * slowdown * heldCost;
    // The point's depth gains nothing where it is refinement's or deeper.
    const bool keeps = !holdDepth_ || point.point.maxDepth >= refineDepth_ ||
                       holdKeepsRefineDepth(heldSeconds, heldCost, dialFps_, holdDepthKeepsRate_);
    if (keeps == holdDepthKeepsRate_) return {};
    holdDepthKeepsRate_ = keeps;
    if (keeps)
        return fmt::format("a held camera at refinement's depth {} again ({:.0f} ms a frame)",
                           refineDepth_, heldSeconds * 1e3);
    return fmt::format(
        "a held camera at depth {}: at refinement's depth {} its frames would take {:.0f} ms "
        "({:.2f}x the point's), over the {:.0f} ms budget",
        point.point.maxDepth, refineDepth_, heldSeconds * 1e3, heldCost, 1e3 / dialFps_);
}

Status PipelineRenderer::prepare(const TrackedFrame& tracked,
                                 const std::shared_ptr<const LiveLighting>& lighting) {
    const Frame& frame = *tracked.frame;
    cv::Mat rgb(int(frame.height), int(frame.width), CV_8UC3,
                const_cast<uint8_t*>(frame.rgb.data()));
    cv::Mat sized;
    if (frame.width == width_ && frame.height == height_)
        sized = rgb;
    else
        cv::resize(rgb, sized, cv::Size(int(width_), int(height_)), 0, 0, cv::INTER_AREA);
    const cv::Mat linear = inverseToneMapRgb8(sized, radiometry_);
    plate_.width = width_;
    plate_.height = height_;
    plate_.channels = 3;
    plate_.ldrSrgb = false;
    plate_.pixels.assign(linear.ptr<float>(0), linear.ptr<float>(0) + size_t(width_) * height_ * 3);
    rendered_ = tracked.worldFromCamera.has_value() || sceneCameraUntilTracked_;
    if (!rendered_) return {};
    // Before the first snapshot a scene without an environment of its own would light the
    // virtual objects with nothing: black.
    if (lightingPending_ && !lighting && !neutralShown_ && !renderer_->features().environment) {
        if (Status s = lightNeutrally(plate_); !s) return s;
        neutralShown_ = true;
    }
    // The renderer keeps the plate; plate_ is needed only while there is nothing to render.
    if (Status s = renderer_->film().setPlate(std::move(plate_), "scene camera frame"); !s)
        return s;
    // Without a pose yet the renderer keeps the scene file's camera (until_tracked).
    if (tracked.worldFromCamera) {
        // The translation in double: it keeps its millimetres however far the board's world
        // is from the origin (camera-relative rendering, Renderer::setCameraPose).
        glm::dmat4 pose(renderWorldFromOpenCvCamera(*tracked.worldFromCamera));
        for (int r = 0; r < 3; ++r) pose[3][r] = (*tracked.worldFromCamera)(r, 3);
        renderer_->setCameraPose(pose);
    }
    // Lighting reaches the GPU only when a new snapshot arrived (no BVH rebuild, ever).
    const std::shared_ptr<const LiveLighting> lit = withCorrection(lighting);
    if (lit && lit != lightingShown_) return applyLighting(lit);
    return {};
}

std::shared_ptr<const LiveLighting> PipelineRenderer::withCorrection(
    const std::shared_ptr<const LiveLighting>& raw) {
    if (raw != rawLighting_) {
        rawLighting_ = raw;
        correctedLighting_.reset();
        fitsOnRaw_ = 0;
    }
    if (!correction_ || !raw) return raw;
    if (!correctedLighting_) correctedLighting_ = correctedLighting(raw, *correction_);
    return correctedLighting_;
}

Result<std::vector<PlateSample>> PipelineRenderer::plateSamples(
    const cv::Matx44d& worldFromCamera) const {
    const ImageF* plate = renderer_->film().plate();
    if (!plate) return makeError("no plate rendered");
    Result<ImageF> traced = renderer_->realSurfaceMeans();
    if (!traced) return traced.error();
    const PlateMeterGrid grid =
        plateMeterGrid(*traced, *plate, plateLimits_,
                       plateMeterGridWidth(traced->width, renderer_->samplesPerPixel()));
    // Rays from the camera through each cell's centre, in the tracer's frame (the scene's).
    const glm::vec3 origin(
        glm::dvec3(worldFromCamera(0, 3), worldFromCamera(1, 3), worldFromCamera(2, 3)) -
        sceneOriginM_);
    std::vector<glm::vec3> directions;
    std::vector<size_t> cells;
    const uint32_t w = plate->width, h = plate->height;
    for (uint32_t cy = 0; cy < grid.height; ++cy)
        for (uint32_t cx = 0; cx < grid.width; ++cx) {
            const size_t cell = size_t(cy) * grid.width + cx;
            if (!grid.realSurface[cell]) continue;
            const PlateMeterCell c = plateMeterCell(grid, cx, cy, w, h);
            // The lens grid's corners are pixel corners: the cell's centre lies between them.
            const double u = 0.5 * (c.x0 + c.x1), v = 0.5 * (c.y0 + c.y1);
            const uint32_t i = std::min(uint32_t(u), w - 1), j = std::min(uint32_t(v), h - 1);
            const float fu = float(u - i), fv = float(v - j);
            auto corner = [&](uint32_t a, uint32_t b) {
                return lensGrid_[size_t(b) * (w + 1) + a];
            };
            const glm::vec2 n = (1 - fv) * ((1 - fu) * corner(i, j) + fu * corner(i + 1, j)) +
                                fv * ((1 - fu) * corner(i, j + 1) + fu * corner(i + 1, j + 1));
            cv::Vec3d d(n.x, n.y, 1.0);
            d = cv::Matx33d(worldFromCamera.get_minor<3, 3>(0, 0)) * (d / cv::norm(d));
            directions.emplace_back(float(d[0]), float(d[1]), float(d[2]));
            cells.push_back(cell);
        }
    const std::vector<std::optional<PlateSample>> hits =
        realSurfacesAlongRays(*realTracer_, origin, directions);
    std::vector<PlateSample> out;
    for (size_t k = 0; k < hits.size(); ++k) {
        if (!hits[k]) continue;
        PlateSample s = *hits[k];
        s.plate = grid.plate[cells[k]];
        s.real = grid.real[cells[k]];
        out.push_back(s);
    }
    return out;
}

LightingFitReport PipelineRenderer::fitLighting(const TrackedFrame& frame,
                                                const PlateConsistency& reading) {
    LightingFitReport r;
    r.frame = frame.frame ? frame.frame->sequence : 0;
    if (fitPolicy_ == FitToPlate::Off || !realTracer_) {
        r.state = LightingFitReport::State::Off;
        return r;
    }
    if (!rawLighting_ || !lightingShown_ || !lightingShown_->captured || !frame.worldFromCamera)
        return r;
    const std::vector<std::vector<int>> clusters = clippedClusters(rawLighting_->clippedTexels);
    // Auto: clipped light no fit has corrected yet, or a plate the lighting does not explain.
    size_t uncorrected = clusters.size();
    if (correction_ && !clusters.empty())
        (void)applyCorrection(environmentMapToMat(*rawLighting_->captured), clusters, *correction_,
                              &uncorrected);
    // A fit leaves the interreflections of the light it adds to the next one (lighting_fit.h):
    // with clipped light, auto fits again while the meter is beyond kFitAgainBand of 1 and the
    // fits keep improving, at most kMaxFitsPerLighting times a snapshot.
    bool again = false;
    if (!clusters.empty() && fitsOnRaw_ < kMaxFitsPerLighting)
        for (double x : reading.ratio) again = again || std::abs(std::log(x)) > kFitAgainBand;
    if (fitPolicy_ == FitToPlate::Auto && reading.ok && uncorrected == 0 && !again) return r;
    // The map the frame was rendered with, converted once for the fit and its correction.
    const cv::Mat shown = environmentMapToMat(*lightingShown_->captured);
    Result<std::vector<PlateSample>> samples = plateSamples(*frame.worldFromCamera);
    Result<LightingFit> fit = samples ? fitLightingToPlate(*realTracer_, shown, clusters, *samples)
                                      : Result<LightingFit>(samples.error());
    if (!fit) {
        r.state = LightingFitReport::State::Failed;
        r.why = fit.message();
        return r;
    }
    // The fit is relative to the lighting the frame was rendered with: it composes.
    const LightingCorrection step = correctionFromFit(shown, clusters, *fit);
    correction_ = correction_ ? composeCorrections(*correction_, step) : step;
    correctedLighting_.reset();
    ++fitsOnRaw_;
    r.state = LightingFitReport::State::Fitted;
    r.changed = true;
    r.fit = *fit;
    return r;
}

Status PipelineRenderer::applyLighting(const std::shared_ptr<const LiveLighting>& lighting) {
    if (Status s = renderer_->setEnvironment(lighting->environment); !s) return s;
    const std::vector<EstimatedLightSource> sources = toLightSources(lighting->lights);
    if (Status s = renderer_->setEstimatedLights(sources); !s) return s;
    lightingShown_ = lighting;
    // The history holds the old lighting's shading: past the threshold (or after a stand-in: the
    // neutral studio or the saved lighting) it starts afresh; below it, it is the fisheye's noise
    // and averages out.
    const bool changed = !historyLighting_ || lightingPending_ ||
                         lightingDelta(*lighting, *historyLighting_).change > lightingThreshold_;
    // The saved lighting is the set as last seen, not as it is now: still pending.
    lightingPending_ = lighting->restored;
    if (changed) {
        if (Denoiser* d = renderer_->film().denoiser()) d->resetHistory();
        if (Status s = renderer_->holdView(false); !s) return s;
        heldSince_.reset();
        historyLighting_ = lighting;
    }
    return {};
}

Status PipelineRenderer::lightNeutrally(const ImageF& plate) {
    double sum = 0.0;
    const size_t pixels = size_t(plate.width) * plate.height;
    for (size_t i = 0; i < pixels; ++i)
        for (int c = 0; c < 3; ++c) sum += plate.pixels[i * plate.channels + c];
    const double plateMean = pixels > 0 ? sum / (3.0 * double(pixels)) : 0.18;
    // The bundled studio (lit from above, colourless), scaled so that its mean over the sphere is
    // the plate's mean: a white surface under a uniform environment L shows L, so the virtual
    // objects come out near the set's level, not at the studio's absolute one.
    auto map = std::make_shared<EnvironmentMap>(studioEnvironment());
    double weighted = 0.0, solidAngle = 0.0;
    for (uint32_t y = 0; y < map->height; ++y) {
        const double w = std::sin(M_PI * (double(y) + 0.5) / double(map->height));
        for (uint32_t x = 0; x < map->width; ++x)
            weighted += w * map->radiance[size_t(y) * map->width + x].r;
        solidAngle += w * map->width;
    }
    const float scale = weighted > 0.0 ? float(plateMean * solidAngle / weighted) : 1.0f;
    for (glm::vec3& r : map->radiance) r *= scale;
    map->path = "the studio environment (lighting pending)";
    return renderer_->setEnvironment(std::move(map));
}

Status PipelineRenderer::renderPreview(const TrackedFrame& frame,
                                       const std::shared_ptr<const LiveLighting>& lighting) {
    if (Status s = prepare(frame, lighting); !s) return s;
    if (!rendered_) return {};
    // Back from refinement under the same lighting: its samples carry over where the camera
    // still holds on the refined view (cameraHolds measures from that view).
    std::optional<std::vector<glm::vec4>> refined;
    if (refining_ && accumulate_ && refinedPose_ && historyLighting_ == refinedLighting_) {
        Result<std::vector<glm::vec4>> samples = renderer_->refinedSamples();
        if (!samples) return samples.error();
        refined = std::move(*samples);
        heldSince_ = refinedPose_;
    }
    // Nothing happens unless the traced size changes (entering preview from refinement).
    const PreviewSettings preview = this->preview().inUse;
    if (Status s = renderer_->setResolutionScale(preview.resolutionScale); !s) return s;
    const bool holds = accumulate_ && cameraHolds(frame);
    // A held camera's frames trace refinement's depth ([render] preview_hold_depth): the held
    // view then converges toward refinement's picture, not the dial's shallower one, whose
    // bias no number of frames averages away.
    heldAtRefineDepth_ = holds && holdDepth_ && holdDepthKeepsRate_;
    renderer_->setMaxDepth(heldAtRefineDepth_ ? refineDepth_ : preview.maxDepth);
    refining_ = false;
    // Preview denoises with temporal reprojection: the history follows the tracked camera.
    renderer_->film().setTemporalDenoise(true);
    // A moving camera's samples follow it at the output's resolution; a held one's add up.
    // Without a trusted pose there is nothing to follow (the history is dropped, as before).
    const bool follows = accumulate_ && follow_ && !holds && frame.worldFromCamera && !frame.lost;
    if (Status s = follows ? renderer_->followView() : renderer_->holdView(holds); !s) return s;
    if (refined && holds)
        if (Status s = renderer_->seedHeldView(*refined); !s) return s;
    return renderer_->renderPreviewFrame(preview.samplesPerFrame,
                                         accumulate_ ? ++previewFrame_ : 0);
}

bool PipelineRenderer::cameraHolds(const TrackedFrame& frame) {
    if (!frame.worldFromCamera || frame.lost) {
        heldSince_.reset();
        return false;
    }
    const cv::Matx44d& pose = *frame.worldFromCamera;
    // What moves a pixel: the rotation's angle, and the translation over the distance to the
    // board's origin (where the set's virtual objects stand), against one pixel's angle.
    const double pixelRad = renderer_->camera().fovYRad / double(height_);
    const double distanceM =
        std::max(kMinHeldDistanceM, cv::norm(cv::Vec3d(pose(0, 3), pose(1, 3), pose(2, 3))));
    bool holds = false;
    if (heldSince_) {
        const PoseDelta d = poseDelta(*heldSince_, pose);
        holds = d.rotationDeg * M_PI / 180.0 + d.translationM / distanceM <= kHeldPixels * pixelRad;
    }
    if (!holds) heldSince_ = pose;
    return holds;
}

Status PipelineRenderer::beginRefine(const TrackedFrame& frame,
                                     const std::shared_ptr<const LiveLighting>& lighting) {
    if (Status s = prepare(frame, lighting); !s) return s;
    if (!rendered_) return {};
    // Refinement converges to the full-resolution image: every pixel traced.
    if (Status s = renderer_->setResolutionScale(1.0f); !s) return s;
    renderer_->setMaxDepth(refineDepth_);
    refining_ = true;
    refineComposite_ = {};
    refineDisplay_ = {};
    // Refinement filters its own accumulation, never a history; preview starts a new one after.
    renderer_->film().setTemporalDenoise(false);
    if (Denoiser* d = renderer_->film().denoiser()) d->resetHistory();
    heldSince_.reset();
    refinedPose_ = frame.worldFromCamera;
    refinedLighting_ = historyLighting_;
    if (Status s = renderer_->holdView(false); !s) return s;
    return renderer_->reset();
}

Status PipelineRenderer::refineStep(uint32_t samples) {
    if (!rendered_) return {};
    return renderer_->refine(samples);
}

Result<std::optional<PlateConsistency>> PipelineRenderer::measurePlateConsistency() {
    const ImageF* plate = renderer_->film().plate();
    if (!rendered_ || lightingPending_ || !plate) return std::optional<PlateConsistency>{};
    Result<ImageF> traced = renderer_->realSurfaceMeans();
    if (!traced) return traced.error();
    const uint32_t across = plateMeterGridWidth(traced->width, renderer_->samplesPerPixel());
    return previs::measurePlateConsistency(plateMeterGrid(*traced, *plate, plateLimits_, across),
                                           plateLimits_);
}

Result<std::optional<double>> PipelineRenderer::measureNoise() {
    Result<Convergence> c = renderer_->convergence();
    if (!c) return c.error();
    return c->composite.relativeRmse;
}

uint32_t PipelineRenderer::previewHistoryFrames() const {
    const Denoiser* d = renderer_->film().denoiser();
    return accumulate_ && d ? d->historyFrames() : 0;
}

uint64_t PipelineRenderer::samples() const { return rendered_ ? renderer_->samplesPerPixel() : 0; }

Result<bool> PipelineRenderer::chooseFilter(std::optional<double> noiseEstimate) {
    lastDenoiseLevels_ = 0;
    uint32_t levels = preview().inUse.denoiseLevels;
    if (refining_)
        levels = denoise_ == "on" ||
                         (denoise_ == "auto" && autoDenoise(noiseEstimate, targetNoise_, samples()))
                     ? denoiseLevels_
                     : 0;
    // Preview's accumulation runs through the denoiser's temporal stage, spatial filter or not.
    const bool temporal = accumulate_ && !refining_;
    if (levels == 0 && !temporal) return false;
    if (Status s = renderer_->setDenoiseIterations(levels); !s) return s.error();
    lastDenoiseLevels_ = levels;
    return true;
}

template <typename Image, typename Make>
Result<Image> PipelineRenderer::denoisedOnce(RefineCache<Image>& cache, Make make) {
    // A denoise costs what a refinement step does (~0.2 s at 640×480): refinement shows its last
    // denoised frame until the samples have grown by a quarter (the noise by 11 %), so a
    // refinement to 1024 spp denoises ~30 times, not at every step, and keeps its samples/s.
    if (refining_ && cache.image && samples() < cache.samples * 5 / 4) return *cache.image;
    Result<Image> image = make();
    if (image && refining_) cache = {*image, samples()};
    return image;
}

Result<ImageF> PipelineRenderer::composite(std::optional<double> noiseEstimate) {
    if (!rendered_) return plate_;
    const Result<bool> denoised = chooseFilter(noiseEstimate);
    if (!denoised) return denoised.error();
    if (!*denoised) return renderer_->image(Aov::Composite);
    return denoisedOnce(refineComposite_, [&] { return renderer_->image(Aov::Composite, true); });
}

Result<DisplayImage> PipelineRenderer::display(std::optional<double> noiseEstimate) {
    if (!rendered_) return toDisplay(plate_);
    const Result<bool> denoised = chooseFilter(noiseEstimate);
    if (!denoised) return denoised.error();
    if (!*denoised) return renderer_->display(false, display_);
    return denoisedOnce(refineDisplay_, [&] { return renderer_->display(true, display_); });
}

DisplayImage PipelineRenderer::toDisplay(ImageF composite) const {
    if (displayColour_) return throughView(*displayColour_, std::move(composite), radiometry_);
    return toDisplayImage(std::move(composite), display_);
}

}  // namespace previs
