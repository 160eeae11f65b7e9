#include "render/renderer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <future>
#include <glm/gtc/matrix_transform.hpp>

#include "base/log.h"
#include "gpu/shaders/shared/denoise.h"
#include "gpu/shaders/shared/photon_records.h"
#include "gpu/shaders/shared/scene_types.h"
#include "gpu/shaders/shared/specular_albedo.h"
#include "gpu/shaders/shared/texture_sampling.h"
#include "scene/environment_map.h"

namespace previs {

namespace {

using shader::BvhNode;

// Paths per pixel in one dispatch at most: short dispatches keep a desktop GPU's watchdog away.
constexpr uint32_t kMaxSamplesPerDispatch = 1024;

// llvmpipe (lavapipe, Mesa's CPU device) ends all loops of a shader invocation once 65535
// iterations of all its loops together have run on one SIMD batch (gallivm's
// LP_MAX_TGSI_LOOP_ITERATIONS): a longer dispatch silently loses BVH traversal steps, bounces
// and samples. A batch runs a loop iteration whenever any of its lanes does, so it runs at most
// subgroupSize × (the most iterations one lane ran). The shader reports that per-lane maximum
// (PV_COUNT_LOOP_ITERATION); dispatches are sized to keep the batch bound under half the limit.
constexpr double kCpuLoopLimit = 65535.0;
constexpr double kCpuLoopSafety = 0.5;

// Specular bounces a photon follows at most (also bounded by the path depth).
constexpr uint32_t kMaxPhotonBounces = 32;

// A camera that frames the whole scene from +Z when the file has none.
Camera defaultCamera(const Geometry& geometry) {
    Camera camera;
    camera.name = "default";
    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const auto& p : geometry.positions) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    if (geometry.positions.empty()) lo = hi = glm::vec3(0.0f);
    glm::vec3 center = 0.5f * (lo + hi);
    float radius = std::max(0.5f * glm::length(hi - lo), 1e-3f);
    float distance = radius / std::tan(0.5f * camera.fovYRad) * 1.1f;
    camera.worldFromCamera = glm::translate(glm::mat4(1.0f), center + glm::vec3(0, 0, distance));
    camera.focusDistanceM = distance;
    return camera;
}

// The GPU's origin for a camera at `positionM` (world; Renderer::setCameraPose): snapped to a
// grid, so that renderers created at nearby poses share it (the same float positions: the same
// pixels), and a set at the world origin seen from within half a cell keeps origin 0 (GPU
// positions are then the scene's own, bit for bit).
// A camera at a NaN or infinite position (a bad pose) gets none: its rays are culled anyway.
std::optional<glm::dvec3> renderOriginFor(const glm::dvec3& positionM) {
    if (!std::isfinite(positionM.x) || !std::isfinite(positionM.y) || !std::isfinite(positionM.z))
        return std::nullopt;
    return glm::round(positionM / Renderer::kRecentreGridM) * Renderer::kRecentreGridM;
}

glm::mat4 renderFromCamera(const glm::dvec3& renderOriginM, const glm::dmat4& worldFromCamera) {
    return glm::mat4(glm::translate(glm::dmat4(1.0), -renderOriginM) * worldFromCamera);
}

// The camera `settings` select in `scene`, with their lens, once the settings are in range.
Result<Camera> checkedCamera(const Scene& scene, const RenderSettings& settings) {
    if (settings.width == 0 || settings.height == 0 || settings.width > 16384 ||
        settings.height > 16384)
        return makeError("image size {}x{} is out of range (1..16384)", settings.width,
                         settings.height);
    Camera camera;
    if (scene.cameras.empty()) {
        camera = defaultCamera(scene.geometry);
    } else {
        if (settings.cameraIndex < 0 || size_t(settings.cameraIndex) >= scene.cameras.size())
            return makeError("camera index {} does not exist; the scene has {} camera(s)",
                             settings.cameraIndex, scene.cameras.size());
        camera = scene.cameras[settings.cameraIndex];
    }
    if (settings.apertureRadiusM) camera.apertureRadiusM = *settings.apertureRadiusM;
    if (settings.focusDistanceM) camera.focusDistanceM = *settings.focusDistanceM;
    if (!settings.lensGrid.empty() &&
        settings.lensGrid.size() != size_t(settings.width + 1) * (settings.height + 1))
        return makeError("lens grid has {} entries; a {}x{} render needs {}",
                         settings.lensGrid.size(), settings.width, settings.height,
                         size_t(settings.width + 1) * (settings.height + 1));
    const PhotonSettings& ph = settings.photons;
    if (ph.perIteration == 0 || ph.perIteration > kMaxPhotonsPerIteration ||
        ph.previewPerIteration == 0 || !(ph.alpha > 0.0f) || !(ph.alpha <= 1.0f) ||
        !(ph.initialRadius >= 0.0f) || !std::isfinite(ph.initialRadius) || ph.gatherCap == 0)
        return makeError(
            "photon settings out of range ({} photons per iteration, radius {} m, "
            "alpha {}, gather cap {}): photons 1..{}, radius >= 0 (0 = from the "
            "scene), alpha in (0, 1], cap >= 1",
            ph.perIteration, ph.initialRadius, ph.alpha, ph.gatherCap, kMaxPhotonsPerIteration);
    if (!(settings.resolutionScale > 0.0f) || !(settings.resolutionScale <= 1.0f))
        return makeError(
            "resolution scale {} is out of range: it must be in (0, 1] (1 traces "
            "every output pixel)",
            settings.resolutionScale);
    if (!(camera.apertureRadiusM >= 0.0f) || !(camera.focusDistanceM > 0.0f))
        return makeError(
            "thin lens needs aperture radius >= 0 and focus distance > 0 (got {} m, "
            "{} m)",
            camera.apertureRadiusM, camera.focusDistanceM);
    return camera;
}

// Counts the pipelines compiled on a context while it lives and tells `progress` (done of
// total) after each (GpuContext::setCompileListener); nothing without `progress`.
class CompileCount {
public:
    CompileCount(GpuContext& ctx, const Renderer::CompileProgress& progress, size_t total)
        : ctx_(ctx), progress_(progress), total_(total) {
        if (!progress_) return;
        ctx_.setCompileListener([this] {
            ++done_;
            progress_(done_, total_);
        });
        progress_(done_, total_);
    }
    ~CompileCount() {
        if (progress_) ctx_.setCompileListener({});
    }
    CompileCount(const CompileCount&) = delete;
    CompileCount& operator=(const CompileCount&) = delete;
    // More compiles than foreseen (create's prediction of the lights missed).
    void expectMore(size_t n) {
        total_ += n;
        if (progress_) progress_(done_, total_);
    }

private:
    GpuContext& ctx_;
    const Renderer::CompileProgress& progress_;
    size_t total_;
    size_t done_ = 0;
};

}  // namespace

Result<std::unique_ptr<Renderer>> Renderer::create(GpuContext& ctx, const Scene& scene,
                                                   const RenderSettings& settings,
                                                   const CompileProgress& progress,
                                                   const RendererTestOptions& testOptions) {
    Result<Camera> camera = checkedCamera(scene, settings);
    if (!camera) return camera.error();
    std::unique_ptr<Renderer> r(new Renderer());
    r->ctx_ = &ctx;
    r->settings_ = settings;
    r->testOptions_ = testOptions;
    r->camera_ = std::move(camera.value());

    r->worldFromCameraM_ =
        glm::translate(glm::dmat4(1.0), scene.originM) * glm::dmat4(r->camera_.worldFromCamera);
    r->camera_.worldFromCamera = glm::mat4(r->worldFromCameraM_);
    const glm::dvec3 renderOriginM =
        renderOriginFor(glm::dvec3(r->worldFromCameraM_[3])).value_or(glm::dvec3(0.0));

    const SceneFeatures features = detectSceneFeatures(scene, r->camera_);
    // Positions in the GPU's frame (setCameraPose); a copy only where the frames differ.
    const glm::dvec3 offset = scene.originM - renderOriginM;
    Geometry shifted;
    if (offset != glm::dvec3(0.0)) {
        shifted = scene.geometry;
        for (glm::vec3& p : shifted.positions) p = toRenderFrame(p, offset);
    }
    const Geometry& g = offset != glm::dvec3(0.0) ? shifted : scene.geometry;
    // Two slow steps that need nothing of each other, on two cores: the BVH builds on a second
    // thread (CPU work only) while this one compiles the pipelines (all Vulkan calls stay on one
    // thread). The pipelines' photon switch is predicted from what the scene holds: photons
    // run where they may (photonsPossible) and the scene has an emitter, a light or an
    // environment lamp to send them from. Where the uploaded scene finds otherwise (emitters of
    // zero area or power), ensurePipelines compiles again: a prediction costs time, never a
    // wrong pipeline.
    const PhotonAim aim = photonAimFor(g, scene.materials);
    r->photonSplats_ = r->photonSplatBytes(aim) > 0;
    const bool environmentLamp =
        scene.environment &&
        environmentPhotonLuminance(*scene.environment,
                                   buildEnvironmentDistribution(*scene.environment)) > 0.0;
    const bool photonsLikely =
        r->photonsPossible(aim) && (features.emissive || !scene.lights.empty() || environmentLamp);
    auto bvh = std::async(std::launch::async, [&g] { return buildSceneBvh(g); });
    r->pipelines_.emplace(ctx, testOptions.specialise);
    const PipelineConstants predicted = r->pipelineConstants(features, photonsLikely);
    CompileCount compiles(ctx, progress,
                          PathPipelines::pipelineCount(predicted) +
                              (settings.denoise ? Denoiser::kPipelineCount : 0));
    const Status compiled = r->pipelines_->ensure(predicted);
    Result<SceneBvh> built = bvh.get();
    if (!compiled) return compiled.error();
    if (!built) return built.error();
    ++r->sceneBuilds_;
    auto gpuScene = GpuScene::create(ctx, scene, g, std::move(built.value()), features, aim,
                                     scene.originM, renderOriginM, r->params_);
    if (!gpuScene) return gpuScene.error();
    r->scene_.emplace(std::move(gpuScene.value()));
    r->setFrameParams();
    if (Status s = r->sizeBands(settings.width, settings.height); !s) return s.error();
    auto buffers = r->createFrameBuffers();
    if (!buffers) return buffers.error();
    r->buffers_.emplace(std::move(buffers.value()));
    r->traceLensGrid_ = settings.lensGrid;
    r->virtualBoxes_ = r->scene_->virtualBoxes(kObjectBoxLevels);
    if (Status s = r->scene_->updatePhotonLights(r->params_); !s) return s.error();
    const PipelineConstants needed =
        r->pipelineConstants(r->scene_->features(), r->photonsActive());
    if (!r->pipelines_->current(needed)) compiles.expectMore(PathPipelines::pipelineCount(needed));
    if (Status s = r->ensurePipelines(); !s) return s.error();
    // The accumulation was sized for the output; a fraction shrinks it.
    r->settings_.resolutionScale = 1.0f;
    if (Status s = r->setResolutionScale(settings.resolutionScale); !s) return s.error();
    if (Status s = r->reset(); !s) return s.error();
    // The denoiser follows the traced size (setResolutionScale) at the first denoised image();
    // creating it here checks the settings early.
    auto film = Film::create(ctx, settings, r->params_.width, r->params_.height);
    if (!film) return film.error();
    r->film_.emplace(std::move(film.value()));
    return Result<std::unique_ptr<Renderer>>(std::move(r));
}

PipelineConstants Renderer::pipelineConstants(const SceneFeatures& features, bool photons) const {
    SceneFeatures spec = features;
    if (testOptions_.generalPipeline)
        spec = SceneFeatures{.environment = true,
                             .emissive = true,
                             .punctual = true,
                             .specular = true,
                             .transmission = true,
                             .thinLens = true,
                             .textures = true,
                             .coneLights = true,
                             .glossy = true};
    PipelineConstants constants{};
    constants[PV_SPEC_DIFFERENTIAL] = settings_.differential;
    constants[PV_SPEC_HAS_LENS_GRID] = !settings_.lensGrid.empty();
    constants[PV_SPEC_HAS_ENV] = spec.environment;
    constants[PV_SPEC_HAS_EMISSIVE] = spec.emissive;
    // Cone lights share the lights buffer and its sampling with the punctual lights.
    constants[PV_SPEC_HAS_PUNCTUAL] = spec.punctual || spec.coneLights;
    constants[PV_SPEC_HAS_SPECULAR] = spec.specular;
    constants[PV_SPEC_HAS_TRANSMISSION] = spec.transmission;
    constants[PV_SPEC_HAS_THIN_LENS] = spec.thinLens;
    constants[PV_SPEC_HAS_TEXTURES] = spec.textures;
    constants[PV_SPEC_HAS_CONE_LIGHTS] = spec.coneLights;
    constants[PV_SPEC_HAS_GLOSSY] = spec.glossy;
    constants[PV_SPEC_COUNT_LOOPS] = ctx_->isCpuDevice();
    constants[PV_SPEC_SAMPLER] =
        settings_.sampler == Sampler::Sobol ? PV_SAMPLER_SOBOL : PV_SAMPLER_INDEPENDENT;
    constants[PV_SPEC_LIGHT_SOLID_ANGLE] = settings_.lightSampling == LightSampling::SolidAngle;
    constants[PV_SPEC_PHOTONS] = photons;
    constants[PV_SPEC_PHOTON_SPLAT] = photons && photonSplats_;
    constants[PV_SPEC_DENOISE_GUIDES] = settings_.denoise;
    constants[PV_SPEC_RESAMPLING] = settings_.previewResampling;
    return constants;
}

Status Renderer::ensurePipelines() {
    if (Status s = pipelines_->ensure(pipelineConstants(scene_->features(), photonsActive())); !s)
        return s;
    return bindBuffers();
}

Status Renderer::sizeBands(uint32_t width, uint32_t height) {
    // A device binds at most maxStorageBufferRange bytes of a storage buffer (128 MiB on
    // lavapipe: 1.4 Mpixel of accumulation); a larger frame renders in bands of rows, each
    // dispatch binding its band's part. Bands are whole workgroups tall, which also keeps their
    // offsets aligned (a multiple of 8 rows of 96-byte pixels is a multiple of 256 bytes).
    const uint64_t limit = ctx_->physicalDevice().getProperties().limits.maxStorageBufferRange;
    const uint64_t bytesPerRow = uint64_t(width) * PV_ACCUM_COUNT * sizeof(glm::vec4);
    const uint64_t rows = limit / bytesPerRow / PV_WORKGROUP_SIZE_Y * PV_WORKGROUP_SIZE_Y;
    if (rows == 0)
        return makeError(
            "a {}-pixel-wide frame needs {} bytes of accumulation per row of 8, more than "
            "this device binds at once ({}): render narrower",
            width, bytesPerRow * PV_WORKGROUP_SIZE_Y, limit);
    bandRows_ = uint32_t(std::min<uint64_t>(rows, height));
    return {};
}

std::vector<BufferRange> Renderer::accumulationBand(uint32_t firstRow) const {
    std::vector<BufferRange> ranges(PV_BINDING_COUNT);
    const uint64_t bytesPerRow = uint64_t(params_.width) * PV_ACCUM_COUNT * sizeof(glm::vec4);
    const uint32_t rows = std::min(bandRows_, params_.height - firstRow);
    for (int b : {PV_BINDING_ACCUM_SUM, PV_BINDING_ACCUM_COMPENSATION})
        ranges[b] = {firstRow * bytesPerRow, rows * bytesPerRow};
    // The denoiser's guides, half as many bytes a pixel, in the same bands.
    if (settings_.denoise) {
        const uint64_t guideBytesPerRow =
            uint64_t(params_.width) * PV_GUIDE_COUNT * sizeof(glm::vec4);
        ranges[PV_BINDING_GUIDES] = {firstRow * guideBytesPerRow, rows * guideBytesPerRow};
    }
    return ranges;
}

std::array<GpuBuffer*, PV_BINDING_COUNT> Renderer::bindingTable() {
    std::array<GpuBuffer*, PV_BINDING_COUNT> table{};
    scene_->bindInto(table);
    for (auto [binding, buffer] : kFrameBindings) table[binding] = &(*buffers_.*buffer);
    return table;
}

Status Renderer::bindBuffers(uint32_t bandFirstRow) {
    // Without pipelines (their last compile failed) the next render() compiles and binds them.
    const std::array<GpuBuffer*, PV_BINDING_COUNT> table = bindingTable();
    const std::vector<const GpuBuffer*> bound(table.begin(), table.end());
    return pipelines_->bind(bound, accumulationBand(bandFirstRow));
}

Status Renderer::setEnvironment(std::shared_ptr<const EnvironmentMap> map) {
    // The next render() compiles for the features and binds the buffers. The preview's
    // reservoirs start afresh: their weights were computed under the old light, and the biased
    // 1/M combination let a direction that was dim then and is bright now carry its old weight
    // (the demo's turning map: held 64 0.527 with them kept, 0.131 with this and a count cap of
    // 4; BENCHMARKS.md).
    params_.reservoirHistory = 0u;
    return scene_->setEnvironment(std::move(map), params_);
}

Status Renderer::setEstimatedLights(std::span<const EstimatedLightSource> estimated) {
    // The next render() compiles for the features and binds the buffers; the reservoirs start
    // afresh, as for setEnvironment.
    params_.reservoirHistory = 0u;
    return scene_->setEstimatedLights(estimated, params_);
}

size_t Renderer::photonSplatBytes(const PhotonAim& aim) const {
    if (!photonsPossible(aim) || !settings_.photons.splatToCamera) return 0;
    // Mixed; with the real solution also real and real-unhidden (scene_types.h).
    const size_t sums = settings_.differential ? 3 : 1;
    const size_t bytes =
        size_t(settings_.width) * settings_.height * sums * PV_SPLAT_WORDS * sizeof(uint32_t);
    // One binding holds them all (the photon pass writes anywhere in the frame): a frame too
    // large for the device's range gathers at the first vertex instead.
    const uint64_t limit = ctx_->physicalDevice().getProperties().limits.maxStorageBufferRange;
    return bytes <= limit ? bytes : 0;
}

bool Renderer::photonsPossible(const PhotonAim& aim) const {
    // Auto needs a specular object; its lights may still come from the captured environment.
    const PhotonSettings& ph = settings_.photons;
    return ph.mode == PhotonMode::On || (ph.mode == PhotonMode::Auto && aim.any);
}

void Renderer::setFrameParams() {
    // Parameters that do not change between dispatches.
    shader::FrameParams& p = params_;
    p.worldFromCamera = renderFromCamera(scene_->renderOriginM(), worldFromCameraM_);
    float tanY = std::tan(0.5f * camera_.fovYRad);
    p.tanHalfFov = glm::vec2(tanY * float(settings_.width) / float(settings_.height), tanY);
    p.apertureRadiusM = camera_.apertureRadiusM;
    p.focusDistanceM = camera_.focusDistanceM;
    p.width = settings_.width;
    p.height = settings_.height;
    p.seed = settings_.seed;
    p.replicates = 1u;  // set per accumulation by render() (shared/sampler.h)
    p.maxDepth = settings_.maxDepth;
    p.fireflyClamp = settings_.fireflyClamp;
    p.rouletteStartDepth = settings_.rouletteStartDepth;
    // Photon buffers exist only where photons may run.
    const PhotonSettings& ph = settings_.photons;
    // A multiple of 128: whole photon workgroups, and records (four a photon) in whole sort
    // blocks.
    static_assert(128u % PV_PHOTON_GROUP_SIZE == 0u &&
                  128u * PV_PHOTON_RECORDS_PER_PHOTON % PV_PHOTON_SORT_BLOCK == 0u);
    p.photonCount =
        photonsPossible(scene_->photonAim()) ? (ph.perIteration + 127u) / 128u * 128u : 0u;
    p.photonMaxBounces = std::min(settings_.maxDepth, kMaxPhotonBounces + 1u) - 1u;
    p.photonGatherCap = ph.gatherCap;
    p.photonGatherNeighbours = ph.gatherNeighbours;
}

Result<Renderer::FrameBuffers> Renderer::createFrameBuffers() const {
    const size_t pixels = size_t(settings_.width) * settings_.height;
    const size_t accumBytes = pixels * PV_ACCUM_COUNT * sizeof(glm::vec4);
    auto make = [this](size_t bytes, const char* label) {
        return GpuBuffer::create(*ctx_, bytes, label);
    };
    auto photons = [&](int binding) {
        return make(photonBufferBytes(binding, params_.photonCount), "photons");
    };
    auto params = GpuBuffer::createWith(*ctx_, std::span(&params_, 1), "params");
    auto sum = make(accumBytes, "accumSum");
    auto compensation = make(accumBytes, "accumCompensation");
    auto stats = make(sizeof(shader::RenderStats), "stats");
    auto lensGrid = GpuBuffer::createWith(
        *ctx_, std::span(settings_.lensGrid.data(), settings_.lensGrid.size()), "lensGrid");
    auto records = photons(PV_BINDING_PHOTON_RECORDS);
    auto sorted = photons(PV_BINDING_PHOTON_SORTED);
    auto sortA = photons(PV_BINDING_PHOTON_SORT_A);
    auto sortB = photons(PV_BINDING_PHOTON_SORT_B);
    auto blockCounts = photons(PV_BINDING_PHOTON_BLOCK_COUNTS);
    auto cells = photons(PV_BINDING_PHOTON_CELLS);
    auto guides =
        make(settings_.denoise ? pixels * PV_GUIDE_COUNT * sizeof(glm::vec4) : 0, "guides");
    auto splats = make(photonSplats_ ? photonSplatBytes(scene_->photonAim()) : 0, "photonSplats");
    auto held = make(0, "heldSamples");       // holdView makes it when needed
    auto reservoirs = make(0, "reservoirs");  // the first preview frame that resamples
    for (const Result<GpuBuffer>* r :
         {&params, &sum, &compensation, &stats, &lensGrid, &records, &sorted, &sortA, &sortB,
          &blockCounts, &cells, &guides, &splats, &held, &reservoirs})
        if (!*r) return r->error();
    return FrameBuffers{std::move(*params),      std::move(*sum),      std::move(*compensation),
                        std::move(*stats),       std::move(*lensGrid), std::move(*records),
                        std::move(*sorted),      std::move(*sortA),    std::move(*sortB),
                        std::move(*blockCounts), std::move(*cells),    std::move(*guides),
                        std::move(*splats),      std::move(*held),     std::move(*reservoirs)};
}

void Renderer::setCameraPose(const glm::dmat4& worldFromCamera) {
    worldFromCameraM_ = worldFromCamera;
    camera_.worldFromCamera = glm::mat4(worldFromCamera);
    params_.worldFromCamera = renderFromCamera(scene_->renderOriginM(), worldFromCamera);
}

Status Renderer::recentre(const glm::dvec3& originM) {
    Status s = scene_->recentre(originM, params_);
    params_.worldFromCamera = renderFromCamera(scene_->renderOriginM(), worldFromCameraM_);
    return s;
}

float Renderer::nextPhotonRadius() const {
    // The default follows the iteration's photon count: a preview frame's budget too.
    const float first = settings_.photons.initialRadius > 0.0f
                            ? settings_.photons.initialRadius
                            : defaultPhotonRadius(scene_->photonAim().radius, params_.photonCount);
    return shader::photonRadius(first, settings_.photons.alpha, uint32_t(samples_));
}

void Renderer::traceSize(float scale, uint32_t& width, uint32_t& height) const {
    auto scaled = [scale](uint32_t n) {
        return std::clamp(uint32_t(std::lround(double(n) * scale)), 1u, n);
    };
    width = scaled(settings_.width);
    height = scaled(settings_.height);
}

std::vector<glm::vec2> Renderer::traceLensGrid(uint32_t width, uint32_t height) const {
    const uint32_t fullW = settings_.width, fullH = settings_.height;
    if (settings_.lensGrid.empty() || (width == fullW && height == fullH))
        return settings_.lensGrid;
    // Traced pixel corner (i, j) is the output's corner (i·W/w, j·H/h): bilinear in the
    // output's corner grid (exact where that lands on an output corner, as at 1/2 of 640×480).
    const auto& g = settings_.lensGrid;
    const uint32_t row = fullW + 1;
    std::vector<glm::vec2> out(size_t(width + 1) * (height + 1));
    for (uint32_t j = 0; j <= height; ++j) {
        const double y = double(j) * fullH / height;
        const uint32_t y0 = std::min(uint32_t(y), fullH - 1);
        const double fy = y - y0;
        for (uint32_t i = 0; i <= width; ++i) {
            const double x = double(i) * fullW / width;
            const uint32_t x0 = std::min(uint32_t(x), fullW - 1);
            const double fx = x - x0;
            const size_t k = size_t(y0) * row + x0;
            const glm::dvec2 top = glm::mix(glm::dvec2(g[k]), glm::dvec2(g[k + 1]), fx);
            const glm::dvec2 bottom =
                glm::mix(glm::dvec2(g[k + row]), glm::dvec2(g[k + row + 1]), fx);
            out[size_t(j) * (width + 1) + i] = glm::vec2(glm::mix(top, bottom, fy));
        }
    }
    return out;
}

Status Renderer::setResolutionScale(float scale) {
    if (!(scale > 0.0f) || !(scale <= 1.0f))
        return makeError(
            "resolution scale {} is out of range: it must be in (0, 1] (1 traces "
            "every output pixel)",
            scale);
    uint32_t width = 0, height = 0;
    traceSize(scale, width, height);
    settings_.resolutionScale = scale;
    if (width == params_.width && height == params_.height) return {};
    // Dispatches are synchronous (ComputePipeline::dispatch waits): the GPU is done with the
    // buffers replaced here.
    const size_t accumBytes = size_t(width) * height * PV_ACCUM_COUNT * sizeof(glm::vec4);
    for (auto [buffer, label] : {std::pair{&buffers_->accumSum, "accumSum"},
                                 std::pair{&buffers_->accumCompensation, "accumCompensation"}}) {
        auto fresh = GpuBuffer::create(*ctx_, accumBytes, label);
        if (!fresh) return fresh.error();
        *buffer = std::move(fresh.value());
    }
    if (settings_.denoise) {
        auto fresh = GpuBuffer::create(
            *ctx_, size_t(width) * height * PV_GUIDE_COUNT * sizeof(glm::vec4), "guides");
        if (!fresh) return fresh.error();
        buffers_->guides = std::move(fresh.value());
    }
    if (!settings_.lensGrid.empty()) {
        std::vector<glm::vec2> grid = traceLensGrid(width, height);
        if (Status s = buffers_->lensGrid.replaceContents(
                grid.data(), grid.size() * sizeof(glm::vec2), "lensGrid");
            !s)
            return s;
        traceLensGrid_ = std::move(grid);
    }
    // The pinhole keeps tanHalfFov: the traced pixels span the same image plane.
    params_.width = width;
    params_.height = height;
    if (Status s = sizeBands(width, height); !s) return s;
    if (Status s = bindBuffers(); !s) return s;
    return reset();
}

Status Renderer::holdView(bool on) {
    return useHeldView(film_->holdView(on, params_.width, params_.height));
}

Status Renderer::followView() {
    if (Status s = useHeldView(film_->followView(params_.width, params_.height)); !s) return s;
    if (params_.heldWidth == 0u) return {};
    return film_->reprojectHeld(buffers_->heldSamples, denoiseCamera());
}

Result<std::vector<glm::vec4>> Renderer::heldSamples() const {
    if (params_.heldWidth == 0u) return std::vector<glm::vec4>{};
    std::vector<glm::vec4> samples(buffers_->heldSamples.size() / sizeof(glm::vec4));
    if (Status s = buffers_->heldSamples.download(samples.data(), buffers_->heldSamples.size()); !s)
        return s.error();
    return samples;
}

Status Renderer::useHeldView(bool on) {
    params_.heldWidth = params_.heldHeight = 0u;
    if (!on) return {};
    // The output's samples, made when first needed (a renderer that never previews below full
    // resolution never pays for them) and bound whole; summed over the frames the view holds,
    // cleared when it starts.
    GpuBuffer& held = buffers_->heldSamples;
    const uint64_t bytes = uint64_t(settings_.width) * settings_.height * 2 * sizeof(glm::vec4);
    const bool made = held.size() != bytes;
    if (made) {
        const uint64_t limit = ctx_->physicalDevice().getProperties().limits.maxStorageBufferRange;
        if (bytes > limit) return {};  // an output too large to bind whole: no held view
        auto fresh = GpuBuffer::create(*ctx_, bytes, "heldSamples");
        if (!fresh) return fresh.error();
        held = std::move(fresh.value());  // dispatches are synchronous: the old one is unused
    }
    params_.heldWidth = settings_.width;
    params_.heldHeight = settings_.height;
    if (made || !film_->heldCamera()) return held.fill(0);
    return {};
}

Status Renderer::seedHeldView(std::span<const glm::vec4> samples) {
    if (params_.heldWidth == 0u || film_->heldCamera()) return {};
    GpuBuffer& held = buffers_->heldSamples;
    if (samples.size_bytes() != held.size())
        return makeError("the held view holds {} bytes, not the {} given", held.size(),
                         samples.size_bytes());
    if (Status s = held.upload(samples.data(), samples.size_bytes()); !s) return s;
    film_->heldFrameAdded(denoiseCamera());
    return {};
}

void Renderer::setMaxDepth(uint32_t maxDepth) {
    settings_.maxDepth = std::max(1u, maxDepth);
    params_.maxDepth = settings_.maxDepth;
    params_.photonMaxBounces = std::min(settings_.maxDepth, kMaxPhotonBounces + 1u) - 1u;
}

Status Renderer::setDenoiseIterations(uint32_t iterations) {
    Denoiser* denoiser = film_->denoiser();
    if (!denoiser)
        return makeError(
            "the denoiser's strength needs a renderer created with denoising on (--denoise "
            "on|auto, [render] denoise)");
    // New settings for the same pipelines: the temporal history is kept.
    DenoiseSettings d = denoiser->settings();
    d.iterations = iterations;
    if (Status s = denoiser->setSettings(d); !s) return s;
    settings_.denoiseSettings = d;
    return {};
}

Status Renderer::setPreviewPhotons(uint32_t photons) {
    if (photons == 0 || photons > kMaxPhotonsPerIteration)
        return makeError("preview photon budget {} is out of range: 1..{} photons per frame",
                         photons, kMaxPhotonsPerIteration);
    settings_.photons.previewPerIteration = photons;
    return {};
}

Status Renderer::reset() {
    samples_ = 0;
    accumulationReplicates_ = 0;
    gpuMs_ = 0.0;
    photonMs_ = 0.0;
    // Not the held view's samples: they outlive a preview frame (holdView clears them).
    FrameBuffers& b = *buffers_;
    for (GpuBuffer* buffer : {&b.accumSum, &b.accumCompensation, &b.stats, &b.guides})
        if (Status s = buffer->fill(0); !s) return s;
    return {};
}

uint32_t Renderer::previewFrameSeed(uint32_t seed, uint64_t frameIndex) {
    if (frameIndex == 0) return seed;
    // A 64-bit mix (splitmix64's finaliser) of the base seed and k, so neighbouring frames'
    // scrambles are unrelated.
    uint64_t z = (uint64_t(seed) << 32) + frameIndex * 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return uint32_t(z ^ (z >> 31));
}

Status Renderer::renderPreviewFrame(uint32_t spp, uint64_t frameIndex) {
    if (Status s = reset(); !s) return s;
    params_.seed = previewFrameSeed(settings_.seed, frameIndex);
    // The preview's photon budget (never more than the buffers hold), then refinement's again.
    const uint32_t full = params_.photonCount;
    params_.photonCount =
        std::min(full, (settings_.photons.previewPerIteration + 127u) / 128u * 128u);
    // One random sequence: a preview frame reports no noise estimate, so it keeps all of the
    // sampler's stratification (the convergence meter's replicates are refinement's).
    accumulationReplicates_ = 1;
    params_.estimateClamp = params_.heldClamp = settings_.previewSampleClamp;
    usePhaseSchedule(uint32_t(frameIndex * spp));
    film_->setFrameSamples(spp);
    Status s = useReservoirs();
    if (s) s = render(spp);
    if (s) s = traceObjectRegions(spp);
    params_.estimateClamp = params_.heldClamp = 0.0f;
    params_.heldPhaseCells = 0u;
    if (params_.resampling != 0u) {
        // This frame's reservoirs are the next one's history.
        params_.resampling = 0u;
        params_.reservoirHistory = s ? 1u : 0u;
        params_.reservoirHalf ^= 1u;
    }
    params_.photonCount = full;
    if (s && params_.heldWidth != 0u) film_->heldFrameAdded(denoiseCamera());
    return s;
}

void Renderer::usePhaseSchedule(uint32_t firstPhase) {
    params_.heldPhaseCells = 0u;
    if (!settings_.previewPhases || params_.heldWidth == 0u) return;
    // Cells no larger than an output pixel: k output pixels a side or fewer to a traced pixel's
    // footprint (a fraction that is not a whole one gives cells a little smaller).
    const double span = std::max(double(params_.heldWidth) / params_.width,
                                 double(params_.heldHeight) / params_.height);
    params_.heldPhaseCells = std::max(1u, uint32_t(std::ceil(span - 1e-3)));
    params_.heldPhase = firstPhase;
    params_.heldPhaseSeed = settings_.seed;
}

Status Renderer::useReservoirs() {
    if (!settings_.previewResampling) return {};
    const uint64_t bytes =
        2ull * params_.width * params_.height * PV_RESERVOIR_VEC4S * sizeof(glm::vec4);
    GpuBuffer& reservoirs = buffers_->reservoirs;
    if (reservoirs.size() != bytes) {
        const uint64_t limit = ctx_->physicalDevice().getProperties().limits.maxStorageBufferRange;
        if (bytes > limit) return {};  // a traced size too large to bind whole: no resampling
        auto fresh = GpuBuffer::create(*ctx_, bytes, "reservoirs");
        if (!fresh) return fresh.error();
        reservoirs = std::move(fresh.value());  // render() binds it
        params_.reservoirHistory = 0u;
    }
    params_.resampling = 1u;
    return {};
}

uint32_t Renderer::samplesForNextDispatch(uint32_t remaining) const {
    uint32_t n =
        std::min({remaining, std::max(1u, settings_.samplesPerDispatch), kMaxSamplesPerDispatch});
    if (!ctx_->isCpuDevice() || !testOptions_.respectCpuLoopLimit) return n;
    // Until one sample has been measured, one at a time.
    if (loopIterationsPerSample_ <= 0.0) return 1;
    const double laneBudget = kCpuLoopLimit * kCpuLoopSafety / double(ctx_->subgroupSize());
    return std::clamp(uint32_t(laneBudget / loopIterationsPerSample_), 1u, n);
}

Status Renderer::render(uint32_t samples,
                        const std::function<void(const RenderProgress&)>& progress) {
    if (Status s = ensurePipelines(); !s) return s;
    constexpr size_t kMaxLoopOffset = offsetof(shader::RenderStats, maxLoopIterations);
    // Camera-relative rendering: the GPU's origin follows the camera, with hysteresis.
    const glm::dvec3 cameraM(worldFromCameraM_[3]);
    const glm::dvec3 away = glm::abs(cameraM - scene_->renderOriginM());
    const std::optional<glm::dvec3> origin = renderOriginFor(cameraM);
    if (origin && std::max({away.x, away.y, away.z}) > kRecentreDistanceM)
        if (Status s = recentre(*origin); !s) return s;
    // The accumulation keeps the sequence layout it started with (a refinement continuing a
    // preview frame stays one sequence: its samples never repeat one another).
    if (accumulationReplicates_ == 0)
        accumulationReplicates_ = settings_.convergenceMeter ? 2u : 1u;
    params_.replicates = accumulationReplicates_;
    uint32_t done = 0;
    const std::array<GpuBuffer*, PV_BINDING_COUNT> table = bindingTable();
    while (done < samples) {
        // Each sample is a photon iteration of its own (its own photon map and radius).
        const uint32_t n = photonsActive() ? 1u : samplesForNextDispatch(samples - done);
        // The sample index selects the random sequence; it wraps after 2^32 samples.
        params_.sampleBase = uint32_t(samples_);
        params_.samplesPerDispatch = n;
        if (photonsActive()) {
            params_.photonIteration = uint32_t(samples_);
            params_.photonRadius = nextPhotonRadius();
            lastPhotonCount_ = params_.photonCount;
            auto photonMs = pipelines_->photons()->run(params_, table, interrupt_);
            if (!photonMs) return photonMs.error();
            photonMs_ += photonMs.value();
            gpuMs_ += photonMs.value();
        }
        if (Status s = buffers_->params.upload(&params_, sizeof(params_)); !s) return s;
        // Only a CPU device has the loop limit: elsewhere the per-dispatch readback (a staging
        // copy on a discrete GPU) is skipped.
        const bool watchLoops = ctx_->isCpuDevice();
        const uint32_t zero = 0;
        if (watchLoops) {
            if (Status s = buffers_->stats.upload(&zero, sizeof(zero), kMaxLoopOffset); !s)
                return s;
        }
        auto ms = dispatchPaths({0, 0, params_.width, params_.height});
        if (!ms) return ms.error();
        uint32_t maxLoop = 0;
        if (watchLoops) {
            if (Status s = buffers_->stats.download(&maxLoop, sizeof(maxLoop), kMaxLoopOffset); !s)
                return s;
        }
        // The costliest sample so far decides (a camera move can make paths longer).
        loopIterationsPerSample_ = std::max(loopIterationsPerSample_, double(maxLoop) / n);
        const double batchBound = double(maxLoop) * ctx_->subgroupSize();
        if (watchLoops && batchBound >= kCpuLoopLimit && loopLimitRisks_++ == 0)
            logWarning(
                "{}: a dispatch of {} sample(s) may have reached the CPU device's loop "
                "limit ({} iterations per lane x {} lanes >= {}): parts of paths may be "
                "missing",
                ctx_->deviceName(), n, maxLoop, ctx_->subgroupSize(), kCpuLoopLimit);
        gpuMs_ += *ms;
        samples_ += n;
        done += n;
        if (progress) progress({done, samples});
    }
    return {};
}

Result<double> Renderer::dispatchPaths(const TraceRegion& region) {
    params_.columnFirst = region.x0;
    params_.columnEnd = region.x1;
    const uint32_t groupsX =
        (region.x1 - region.x0 + PV_WORKGROUP_SIZE_X - 1) / PV_WORKGROUP_SIZE_X;
    const bool banded = bandRows_ < params_.height;
    double ms = 0.0;
    for (uint32_t first = region.y0 / bandRows_ * bandRows_; first < region.y1;
         first += bandRows_) {
        params_.bandFirstRow = banded ? first : 0u;
        params_.rowFirst = std::max(first, region.y0);
        params_.rowEnd = std::min({first + bandRows_, region.y1, params_.height});
        if (Status s = buffers_->params.upload(&params_, sizeof(params_)); !s) return s.error();
        if (banded)
            if (Status s = bindBuffers(first); !s) return s.error();
        const uint32_t rows = params_.rowEnd - params_.rowFirst;
        const uint32_t groupsY = (rows + PV_WORKGROUP_SIZE_Y - 1) / PV_WORKGROUP_SIZE_Y;
        ComputePipeline& paths = pipelines_->paths();
        auto bandMs = interrupt_ ? pathParts_.run(paths, groupsX, groupsY, *interrupt_)
                                 : paths.dispatch(groupsX, groupsY);
        if (!bandMs) return bandMs.error();
        ms += bandMs.value();
    }
    if (banded) {
        params_.bandFirstRow = 0;
        if (Status s = bindBuffers(0); !s) return s.error();
    }
    return ms;
}

std::optional<Renderer::TraceRegion> Renderer::boxRegion(const WorldBox& box) const {
    const TraceRegion whole{0, 0, params_.width, params_.height};
    // The box's corners in normalised camera coordinates (OpenCV's: x right, y down, over z).
    const glm::dmat4 cameraFromWorld = glm::inverse(worldFromCameraM_);
    glm::dvec2 lo(std::numeric_limits<double>::max()), hi(-std::numeric_limits<double>::max());
    for (int corner = 0; corner < 8; ++corner) {
        const glm::dvec3 w(corner & 1 ? box.hi.x : box.lo.x, corner & 2 ? box.hi.y : box.lo.y,
                           corner & 4 ? box.hi.z : box.lo.z);
        const glm::dvec3 c(cameraFromWorld * glm::dvec4(w, 1.0));
        if (c.z > -kObjectRegionNearM) return whole;  // the box reaches behind the camera
        const glm::dvec2 n(c.x / -c.z, c.y / c.z);
        lo = glm::min(lo, n);
        hi = glm::max(hi, n);
    }
    // The traced pixels whose corners fall in that rectangle: through the calibrated lens where
    // there is one (its distortion moves the edge of the picture by many pixels), else the
    // pinhole's. A margin of kObjectRegionMargin traced pixels takes the corners' neighbours.
    uint32_t x0 = params_.width, y0 = params_.height, x1 = 0, y1 = 0;
    const uint32_t row = params_.width + 1;
    const bool lens = traceLensGrid_.size() == size_t(row) * (params_.height + 1);
    for (uint32_t j = 0; j <= params_.height; ++j)
        for (uint32_t i = 0; i <= params_.width; ++i) {
            glm::dvec2 n;
            if (lens) {
                n = glm::dvec2(traceLensGrid_[size_t(j) * row + i]);
            } else {
                const double ndcX = 2.0 * i / params_.width - 1.0;
                const double ndcY = 1.0 - 2.0 * j / params_.height;
                n = glm::dvec2(ndcX * params_.tanHalfFov.x, -ndcY * params_.tanHalfFov.y);
            }
            if (n.x < lo.x || n.x > hi.x || n.y < lo.y || n.y > hi.y) continue;
            x0 = std::min(x0, i);
            y0 = std::min(y0, j);
            x1 = std::max(x1, i);
            y1 = std::max(y1, j);
        }
    if (x0 > x1 || y0 > y1) return std::nullopt;  // not in view
    const uint32_t m = kObjectRegionMargin;
    return TraceRegion{x0 > m ? x0 - m : 0u, y0 > m ? y0 - m : 0u, std::min(x1 + m, params_.width),
                       std::min(y1 + m, params_.height)};
}

std::vector<Renderer::TraceRegion> Renderer::objectRegions() const {
    std::vector<TraceRegion> regions;
    for (const WorldBox& box : virtualBoxes_)
        if (std::optional<TraceRegion> r = boxRegion(box)) regions.push_back(*r);
    // Overlapping rectangles become their bounding one, so no pixel is traced twice.
    auto overlap = [](const TraceRegion& a, const TraceRegion& b) {
        return a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1;
    };
    for (bool merged = true; merged;) {
        merged = false;
        for (size_t i = 0; i < regions.size() && !merged; ++i)
            for (size_t j = i + 1; j < regions.size() && !merged; ++j) {
                if (!overlap(regions[i], regions[j])) continue;
                TraceRegion& a = regions[i];
                const TraceRegion& b = regions[j];
                a = {std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1),
                     std::max(a.y1, b.y1)};
                regions.erase(regions.begin() + std::ptrdiff_t(j));
                merged = true;
            }
    }
    return regions;
}

Status Renderer::traceObjectRegions(uint32_t frameSamples) {
    const double outputPerTraced =
        double(settings_.width) * settings_.height / (double(params_.width) * params_.height);
    objectRegionSamples_ = 0;
    if (settings_.objectSamplesPerOutputPixel <= 0.0f || outputPerTraced <= 1.0) return {};
    const std::vector<TraceRegion> regions = objectRegions();
    double regionPixels = 0.0;
    for (const TraceRegion& r : regions) regionPixels += double(r.x1 - r.x0) * (r.y1 - r.y0);
    if (regionPixels == 0.0) return {};
    const double budget =
        kObjectSampleBudget * frameSamples * params_.width * params_.height / regionPixels;
    const uint32_t total = uint32_t(std::min(
        std::ceil(settings_.objectSamplesPerOutputPixel * outputPerTraced), std::floor(budget)));
    params_.objectSamples = 1u;
    Status s;
    for (uint32_t done = 0; s && done < total;) {
        // The frame's photon map serves them all (the splats stay the frame's own).
        const uint32_t n = samplesForNextDispatch(total - done);
        params_.sampleBase = uint32_t(samples_) + done;
        params_.samplesPerDispatch = n;
        for (const TraceRegion& r : regions) {
            Result<double> ms = dispatchPaths(r);
            if (!ms) {
                s = ms.error();
                break;
            }
            gpuMs_ += *ms;
        }
        done += n;
    }
    params_.objectSamples = 0u;
    if (s) objectRegionSamples_ = uint64_t(total) * uint64_t(regionPixels);
    return s;
}

TracedBuffers Renderer::traced() const {
    return {&buffers_->accumSum,
            &buffers_->accumCompensation,
            settings_.denoise ? &buffers_->guides : nullptr,
            params_.heldWidth ? &buffers_->heldSamples : nullptr,
            params_.width,
            params_.height};
}

Result<shader::RenderStats> Renderer::stats() const {
    shader::RenderStats stats{};
    if (Status s = buffers_->stats.download(&stats, sizeof(stats)); !s) return s.error();
    return stats;
}

Result<uint32_t> Renderer::nonFiniteSamples() const {
    auto s = stats();
    if (!s) return s.error();
    return s->nonFiniteSamples;
}

Result<uint32_t> Renderer::raysTraced() const {
    shader::RenderStats stats{};
    if (Status s = buffers_->stats.download(&stats, sizeof(stats)); !s) return s.error();
    return stats.raysTraced;
}

}  // namespace previs
