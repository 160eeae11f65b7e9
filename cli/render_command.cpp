#include "cli/render_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <future>
#include <optional>

#include "base/log.h"
#include "base/output_path.h"
#include "base/progress.h"
#include "base/strings.h"
#include "cli/tone_curve_options.h"
#include "gpu/context.h"
#include "image/image.h"
#include "render/convergence.h"
#include "render/renderer.h"
#include "render/tonemap.h"
#include "scene/environment_map.h"
#include "scene/scene_description.h"
#include "vision/inverse_tone_map.h"
#include "vision/lens_grid.h"

namespace previs {

namespace {

// Samples per dispatch at most (the renderer may lower it): on lavapipe 16 take about 0.75 of the
// time of 16 one-sample dispatches (bench/results/benchmarks_2026-11-29.md, "Issue 8: path
// regeneration"); more gains little and makes the progress line and --seconds coarser.
constexpr uint32_t kSamplesPerDispatch = 16;

struct RenderOptions {
    std::string scene;
    std::string env;
    // Unset: the scene description's value (or the default); set: overrides it.
    std::optional<float> envRotationDeg;
    std::optional<float> envScale;
    std::string camera;
    uint32_t width = 0;
    uint32_t height = 0;
    uint32_t spp = 0;
    double seconds = 0.0;
    double targetNoise = 0.0;  // 0: none
    bool noMeter = false;
    uint32_t maxDepth = 16;
    std::optional<float> apertureRadiusM;
    std::optional<float> focusDistanceM;
    uint32_t seed = 0;
    std::string sampler = "sobol";
    std::string lightSampling = "solid-angle";
    std::string photons = "auto";
    float photonRadius = 0.0f;
    float photonAlpha = 2.0f / 3.0f;
    uint32_t photonGatherCap = PhotonSettings{}.gatherCap;
    uint32_t photonNeighbours = PhotonSettings{}.gatherNeighbours;
    bool photonSplat = PhotonSettings{}.splatToCamera;
    std::string out;
    ToneCurveOptions output;  // PNG output
    float fireflyClamp = 0.0f;
    float resolutionScale = 1.0f;
    bool quiet = false;
    bool timing = false;
    std::string plate;
    ToneCurveOptions plateCurve;
    std::vector<std::string> aovs;
    std::string calibration;
    std::vector<uint32_t> checkpoints;  // also write the image at these sample counts
    std::string denoise = "off";        // on | off | auto (render/denoiser.h: autoDenoise)
};

// The file AOVs (--aov), in the order `--help` lists them.
struct FileAov {
    const char* name;
    Aov aov;
    bool guide;  // one of the denoiser's guides (written only when asked for or denoising)
};
constexpr FileAov kFileAovs[] = {
    {"composite", Aov::Composite, false}, {"mixed", Aov::Mixed, false},
    {"real", Aov::Real, false},           {"mask", Aov::Mask, false},
    {"albedo", Aov::Albedo, true},        {"normal", Aov::Normal, true},
    {"depth", Aov::Depth, true},
};

// The one place an --aov name is read (the option's validator only lets these through).
const FileAov& fileAov(const std::string& name) {
    for (const FileAov& a : kFileAovs)
        if (name == a.name) return a;
    return kFileAovs[0];
}

std::vector<std::string> fileAovNames() {
    std::vector<std::string> names;
    for (const FileAov& a : kFileAovs) names.emplace_back(a.name);
    return names;
}

// `--out dir/name.exr` → `dir/name.<aov>.exr` (DESIGN.md §3).
std::string aovPath(const std::string& out, const std::string& aov) {
    std::filesystem::path p(out);
    return (p.parent_path() / (p.stem().string() + "." + aov + ".exr")).string();
}

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
}

// --timing's stages: from the start of the run to the image in memory (the file write excluded).
struct RunTimes {
    Clock::time_point start = Clock::now();
    Clock::time_point renderStart{};
    double load = 0.0, device = 0.0, setup = 0.0, render = 0.0;
};

// Logs `s`'s error; `code` when it is one, 0 when `s` is fine.
int failed(const Status& s, int code) {
    if (s) return 0;
    logError("{}", s.message());
    return code;
}

// What the options' own validators cannot check: exit code 2 on the first one wrong.
int checkOptions(RenderOptions& o) {
    if (!endsWith(o.out, ".exr") && !endsWith(o.out, ".png")) {
        logError("--out {}: the output must end in .exr (linear HDR) or .png (tone mapped)", o.out);
        return 2;
    }
    if (o.noMeter && o.targetNoise > 0.0) {
        logError("--target-noise needs the convergence meter: drop --no-meter");
        return 2;
    }
    if (o.spp > 0 && o.seconds > 0.0) {
        logError("give either --spp or --seconds, not both");
        return 2;
    }
    if (int rc = failed(checkOutputFile("--out", o.out), 2)) return rc;
    return failed(o.plateCurve.buildColour(), 2);
}

// The scene with its --env map, and the Vulkan device.
struct Inputs {
    Result<Scene> scene;
    std::optional<Result<EnvironmentMap>> env;
    double loadedAt = 0.0;  // seconds into the run
    std::optional<Result<std::unique_ptr<GpuContext>>> ctx;
};

// The scene and its map load on a second core while this thread starts the Vulkan device
// (lavapipe's start, LLVM's included, is about 0.1 s): neither needs the other, and every Vulkan
// call stays on this thread. Errors are reported in the order of the work: the scene's, the
// map's, then the device's.
Inputs loadInputs(const RenderOptions& o, RunTimes& times) {
    auto loading = std::async(std::launch::async, [&o, &times] {
        Inputs in{loadScene(o.scene), std::nullopt, 0.0, std::nullopt};
        if (in.scene && !o.env.empty()) in.env.emplace(loadEnvironmentMap(o.env));
        in.loadedAt = secondsSince(times.start);
        return in;
    });
    auto ctx = GpuContext::create({});
    const double deviceAndLoadSeconds = secondsSince(times.start);
    Inputs in = loading.get();
    in.ctx.emplace(std::move(ctx));
    // device_s: the part of the device's start the loading did not hide.
    times.device = std::max(0.0, deviceAndLoadSeconds - in.loadedAt);
    return in;
}

// The scene's environment after --env, --env-rotation and --env-scale; exit code 2 on a load
// error.
int applyEnvironment(const RenderOptions& o, Inputs& in) {
    if (!in.scene) return failed(in.scene.error(), 2);
    Scene& scene = *in.scene;
    if (in.env) {
        if (!*in.env) return failed(in.env->error(), 2);
        // --env replaces the description's whole [environment]: its rotation and scale were set
        // for its own map, not for this one.
        scene.environment = std::move(in.env->value());
    }
    if (!scene.environment && !hasLightSource(scene))
        logWarning(
            "{}: the scene has no light source (no KHR_lights_punctual light, no emissive "
            "material) and no environment map, so it renders black; add --env studio for "
            "neutral studio lighting, or --env MAP.exr",
            o.scene);
    if (scene.environment) {
        if (o.envRotationDeg)
            scene.environment->rotationRad = *o.envRotationDeg * float(M_PI / 180.0);
        if (o.envScale) scene.environment->scale = *o.envScale;
    }
    return 0;
}

// --camera (else the scene description's camera.name) and the image size it implies.
int chooseCamera(const RenderOptions& o, const Scene& scene, RenderSettings& settings) {
    const std::string cameraName = !o.camera.empty() ? o.camera : scene.cameraName;
    if (!cameraName.empty()) {
        auto it = std::find_if(scene.cameras.begin(), scene.cameras.end(),
                               [&](const Camera& c) { return c.name == cameraName; });
        if (it == scene.cameras.end()) {
            logError("{}: no camera named '{}' ({} camera(s) in the file)", o.scene, cameraName,
                     scene.cameras.size());
            return 2;
        }
        settings.cameraIndex = int(it - scene.cameras.begin());
    }
    float aspect = 4.0f / 3.0f;
    if (!scene.cameras.empty() && scene.cameras[settings.cameraIndex].aspectRatio > 0.0f)
        aspect = scene.cameras[settings.cameraIndex].aspectRatio;
    settings.width =
        o.width ? o.width : (o.height ? uint32_t(std::lround(o.height * aspect)) : 640);
    settings.height = o.height ? o.height : uint32_t(std::lround(settings.width / aspect));
    return 0;
}

// The options that map straight onto RenderSettings; exit code 2 on a bad --photons.
int applySamplingOptions(const RenderOptions& o, RenderSettings& settings) {
    settings.maxDepth = o.maxDepth;
    settings.seed = o.seed;
    settings.sampler = o.sampler == "independent" ? Sampler::Independent : Sampler::Sobol;
    settings.lightSampling =
        o.lightSampling == "area" ? LightSampling::Area : LightSampling::SolidAngle;
    settings.apertureRadiusM = o.apertureRadiusM;
    settings.focusDistanceM = o.focusDistanceM;
    settings.fireflyClamp = o.fireflyClamp;
    settings.resolutionScale = o.resolutionScale;
    if (Status s = applyPhotonSpec(o.photons, settings.photons); !s) {
        logError("--photons: {}", s.message());
        return 2;
    }
    settings.photons.initialRadius = o.photonRadius;
    settings.photons.alpha = o.photonAlpha;
    settings.photons.gatherCap = o.photonGatherCap;
    settings.photons.gatherNeighbours = o.photonNeighbours;
    settings.photons.splatToCamera = o.photonSplat;
    // A lane whose path ends starts its next sample at once (trace_paths.comp). The renderer
    // lowers this inside lavapipe's loop limit; photon iterations dispatch one sample each.
    settings.samplesPerDispatch = kSamplesPerDispatch;
    return 0;
}

// The plate: linear radiance at the render's resolution (its own resolution by default).
int loadPlate(const RenderOptions& o, RenderSettings& settings, std::optional<ImageF>& plate) {
    if (o.plate.empty()) return 0;
    auto img = readImage(o.plate);
    if (!img) return failed(img.error(), 2);
    if (img->ldrSrgb) {
        plate = inverseToneMap(*img, o.plateCurve.inverse());
    } else {
        plate = std::move(img.value());
    }
    if (!o.width && !o.height) {
        settings.width = plate->width;
        settings.height = plate->height;
    }
    if (plate->width != settings.width || plate->height != settings.height) {
        logError(
            "--plate {} is {}x{} but the render is {}x{}: render at the plate's resolution "
            "(omit --width/--height)",
            o.plate, plate->width, plate->height, settings.width, settings.height);
        return 2;
    }
    return 0;
}

// --calibration: primary rays through the calibrated lens (its image size by default).
int loadLensGrid(const RenderOptions& o, bool havePlate, RenderSettings& settings) {
    if (o.calibration.empty()) return 0;
    auto calib = CameraCalibration::load(o.calibration);
    if (!calib) return failed(calib.error(), 2);
    if (!o.width && !o.height && !havePlate) {
        settings.width = uint32_t(calib->imageSize().width);
        settings.height = uint32_t(calib->imageSize().height);
    }
    auto grid = lensRayGrid(*calib, settings.width, settings.height);
    if (!grid) {
        logError("--calibration {}: {}", o.calibration, grid.message());
        return 2;
    }
    settings.lensGrid = std::move(grid.value());
    return 0;
}

// The buffers the renderer keeps beyond the composite: only those something uses.
void chooseBuffers(const RenderOptions& o, bool havePlate, RenderSettings& settings) {
    const bool wantsReal = std::find(o.aovs.begin(), o.aovs.end(), "real") != o.aovs.end();
    // The real-only solution costs extra rays.
    settings.differential = havePlate || wantsReal;
    settings.convergenceMeter = !o.noMeter;
    // Guides: for the denoiser, or a guide AOV.
    settings.denoise = o.denoise != "off" ||
                       std::any_of(o.aovs.begin(), o.aovs.end(),
                                   [](const std::string& name) { return fileAov(name).guide; });
}

// Options → settings and plate; exit code 2 on the first error.
int settingsFromOptions(const RenderOptions& o, const Scene& scene, RenderSettings& settings,
                        std::optional<ImageF>& plate) {
    if (int rc = chooseCamera(o, scene, settings)) return rc;
    if (int rc = applySamplingOptions(o, settings)) return rc;
    if (int rc = loadPlate(o, settings, plate)) return rc;
    if (int rc = loadLensGrid(o, plate.has_value(), settings)) return rc;
    chooseBuffers(o, plate.has_value(), settings);
    return 0;
}

// --checkpoints: for convergence curves in one run, the image at `done` samples and the time it
// took (from the start of the run, so device creation, BVH build and compile count).
int writeCheckpoint(const RenderOptions& o, const Renderer& r, uint64_t done,
                    const RunTimes& times) {
    auto snapshot = r.image();
    std::filesystem::path p(o.out);
    std::string path =
        (p.parent_path() / fmt::format("{}.spp{}.exr", p.stem().string(), done)).string();
    if (int rc = failed(snapshot ? writeExr(path, *snapshot) : Status(snapshot.error()), 1))
        return rc;
    std::printf("checkpoint spp=%llu total_s=%.4f file=%s\n", (unsigned long long)done,
                secondsSince(times.start), path.c_str());
    std::fflush(stdout);
    return 0;
}

// The stopping rule (render/convergence.h): --target-noise alone runs until the meter says so;
// --spp caps it (--seconds is a time limit of the loop's own); neither: 64 samples.
StoppingRule stoppingRule(const RenderOptions& o) {
    const bool open = o.seconds > 0.0 || o.targetNoise > 0.0;
    return StoppingRule(o.targetNoise, o.spp ? o.spp : (open ? 0 : 64));
}

// The progress line: samples, time, the meter's estimate with the rule's ETA, photons.
void showProgress(ProgressLine& progress, const RenderOptions& o, const Renderer& r,
                  const StoppingRule& rule, uint64_t samples, double seconds) {
    // Photons: per iteration, and the radius the next iteration gathers with.
    std::string photons = r.photonsActive()
                              ? fmt::format(", {} photons/iteration, radius {:.3g} m",
                                            r.photonsPerIteration(), r.nextPhotonRadius())
                              : "";
    std::string noise;
    if (rule.measured()) {
        noise = fmt::format(", noise {:.2f} %", *rule.measured() * 100.0);
        const std::optional<double> eta =
            o.targetNoise > 0.0 ? rule.eta(samples, seconds / double(samples)) : std::nullopt;
        if (eta)
            noise += fmt::format(" (target {:.2f} %, ETA {:.0f} s)", o.targetNoise * 100.0, *eta);
    }
    progress.update(fmt::format("{}{} spp, {:.1f} s{}{}", samples,
                                o.spp ? fmt::format("/{}", o.spp) : "", seconds, noise, photons));
}

// The next chunk ends where something must happen: the rule's maximum or, with --target-noise,
// the meter's next look; a checkpoint; the time limit of --seconds (estimated from the samples so
// far). Without a target the meter looks after the chunk that passes its look.
uint64_t nextChunk(const RenderOptions& o, const StoppingRule& rule, uint64_t before,
                   double seconds) {
    uint64_t chunk = std::min<uint64_t>(rule.nextStop(before) - before, kSamplesPerDispatch);
    for (uint64_t c : o.checkpoints)
        if (c > before) chunk = std::min(chunk, c - before);
    if (o.seconds > 0.0 && before > 0) {
        const double perSample = seconds / double(before);
        chunk = std::min(chunk, uint64_t(std::max(1.0, (o.seconds - seconds) / perSample)));
    }
    return chunk;
}

// The sample loop: chunks until the stopping rule says done or --seconds runs out, the meter
// looking when the rule says, checkpoints written on the way. 0, or 1 after logging an error.
int renderSamples(const RenderOptions& o, Renderer& r, RunTimes& times) {
    const auto start = times.renderStart = Clock::now();
    ProgressLine progress("render", o.quiet);
    StoppingRule rule = stoppingRule(o);
    auto look = [&r]() -> Result<std::optional<double>> {
        auto c = r.convergence();
        if (!c) return c.error();
        return c->composite.relativeRmse;
    };
    while (!rule.done(r.samplesPerPixel())) {
        const uint64_t before = r.samplesPerPixel();
        auto onDispatch = [&](const RenderProgress& p) {
            if (p.samplesDone < p.samplesTotal)
                showProgress(progress, o, r, rule, before + p.samplesDone, secondsSince(start));
        };
        const uint64_t chunk = nextChunk(o, rule, before, secondsSince(start));
        if (int rc = failed(r.render(uint32_t(chunk), onDispatch), 1)) return rc;
        const uint64_t done = r.samplesPerPixel();
        if (int rc = failed(rule.lookIfDue(done, look), 1)) return rc;
        showProgress(progress, o, r, rule, done, secondsSince(start));
        if (rule.reachedTarget()) break;
        if (std::find(o.checkpoints.begin(), o.checkpoints.end(), done) != o.checkpoints.end())
            if (int rc = writeCheckpoint(o, r, done, times)) return rc;
        if (o.seconds > 0.0 && secondsSince(start) >= o.seconds) break;
    }
    progress.finish();
    times.render = secondsSince(start);
    return 0;
}

// A --timing field: the value, or "none".
std::string number(std::optional<double> v) {
    return v ? fmt::format("{:.6g}", *v) : std::string("none");
}

// --timing's line. load: scene and environment files; device: Vulkan instance and device;
// setup: BVH build, upload, pipeline compile; render: the samples; readback: the image to host;
// gpu: the dispatches' GPU time, photon_gpu: of which the photon passes; dropped: the NaN/Inf
// samples left out of the pixel means; noise, differential_noise: the convergence meter's
// relative RMSE estimates ("none" below 2 spp).
void printTiming(const RunTimes& t, double readbackSeconds, const Renderer& r, uint32_t dropped,
                 const Convergence& c) {
    std::printf(
        "timing load_s=%.4f device_s=%.4f setup_s=%.4f render_s=%.4f readback_s=%.4f "
        "total_s=%.4f gpu_s=%.4f photon_gpu_s=%.4f dropped_samples=%u spp=%llu noise=%s "
        "differential_noise=%s\n",
        t.load, t.device, t.setup, t.render, readbackSeconds, secondsSince(t.start),
        r.gpuMilliseconds() * 1e-3, r.photonMilliseconds() * 1e-3, dropped,
        (unsigned long long)r.samplesPerPixel(), number(c.composite.relativeRmse).c_str(),
        number(c.differential.relativeRmse).c_str());
    std::fflush(stdout);
}

// The image (--out) and the --aov buffers, denoised as the image is.
int writeOutputs(const RenderOptions& o, Renderer& r, const ImageF& image, bool denoised) {
    const Status written =
        endsWith(o.out, ".exr")
            ? writeExr(o.out, image)
            : writePng(o.out, image.width, image.height, toneMapToSrgb8(image, o.output.forward()));
    if (int rc = failed(written, 1)) return rc;
    for (const std::string& name : o.aovs) {
        auto buffer = r.image(fileAov(name).aov, denoised);
        Status s = buffer ? writeExr(aovPath(o.out, name), *buffer) : Status(buffer.error());
        if (int rc = failed(s, 1)) return rc;
    }
    return 0;
}

// After the samples: the meter's last word, the dropped samples, the image (denoised as
// --denoise says), --timing's line, the files, and the summary.
int finish(const RenderOptions& o, Renderer& r, const GpuContext& ctx, RunTimes& times) {
    auto convergence = r.convergence();
    if (!convergence) return failed(convergence.error(), 1);
    const std::optional<double> noise = convergence->composite.relativeRmse;
    const auto readbackStart = Clock::now();
    auto stats = r.stats();
    if (!stats) return failed(stats.error(), 1);
    const uint32_t dropped = stats->nonFiniteSamples;
    if (dropped > 0)
        logWarning(
            "{} sample(s) were NaN or infinite ({} ray(s) with a NaN/Inf origin or direction "
            "culled) and were dropped: each pixel is the mean of its remaining samples",
            dropped, stats->nonFiniteRays);
    // The one place --denoise auto decides (autoDenoise, render/denoiser.h).
    const bool denoised =
        o.denoise == "on" ||
        (o.denoise == "auto" && autoDenoise(noise, o.targetNoise, r.samplesPerPixel()));
    auto image = r.image(Aov::Composite, denoised);
    if (!image) return failed(image.error(), 1);
    if (o.timing) printTiming(times, secondsSince(readbackStart), r, dropped, *convergence);
    if (int rc = writeOutputs(o, r, *image, denoised)) return rc;
    auto percent = [](std::optional<double> v) {
        return v ? fmt::format("{:.2f} %", *v * 100.0) : std::string("unknown");
    };
    if (!o.quiet)
        logInfo("wrote {} ({}x{}, {} spp{}, {:.1f} s on {}, noise {}{})", o.out, image->width,
                image->height, r.samplesPerPixel(), denoised ? ", denoised" : "",
                secondsSince(times.renderStart), ctx.deviceName(), percent(noise),
                dropped > 0 ? fmt::format(", {} NaN/Inf sample(s) dropped", dropped) : "");
    return 0;
}

int run(RenderOptions& o) {
    if (int rc = checkOptions(o)) return rc;
    RunTimes times;
    Inputs in = loadInputs(o, times);
    if (int rc = applyEnvironment(o, in)) return rc;
    RenderSettings settings;
    std::optional<ImageF> plate;
    if (int rc = settingsFromOptions(o, *in.scene, settings, plate)) return rc;
    times.load = secondsSince(times.start) - times.device;
    if (!*in.ctx) return failed(in.ctx->error(), 1);
    GpuContext& ctx = ***in.ctx;
    const auto setupStart = Clock::now();
    auto renderer = Renderer::create(ctx, *in.scene, settings);
    if (!renderer) {
        logError("{}: {}", o.scene, renderer.message());
        return 1;
    }
    if (plate) {
        if (Status s = (*renderer)->film().setPlate(*plate, fmt::format("--plate {}", o.plate));
            !s) {
            logError("--plate {}: {}", o.plate, s.message());
            return 2;
        }
    }
    times.setup = secondsSince(setupStart);
    if (int rc = renderSamples(o, **renderer, times)) return rc;
    return finish(o, **renderer, ctx, times);
}

// The scene, its lighting, the camera and the image size.
void addSceneOptions(CLI::App* cmd, RenderOptions* o) {
    cmd->add_option("SCENE", o->scene, "scene: .gltf, .glb or previs.toml")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--env", o->env,
                    "equirectangular HDR environment map (.exr or .hdr), or 'studio' for the "
                    "bundled neutral studio lighting")
        ->check(CLI::Validator(
            [](std::string& value) {
                return value == kStudioEnvironment ? std::string() : CLI::ExistingFile(value);
            },
            "FILE|studio"));
    cmd->add_option("--env-rotation", o->envRotationDeg,
                    "rotate the map about +Y, degrees (counter-clockwise seen from above)");
    cmd->add_option("--env-scale", o->envScale, "multiply the map's radiance")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--camera", o->camera, "camera node name (default: the first camera)");
    cmd->add_option("--width", o->width, "image width in pixels")->check(CLI::Range(1, 16384));
    cmd->add_option("--height", o->height, "image height in pixels")->check(CLI::Range(1, 16384));
}

// How many samples, and how they are drawn.
void addSamplingOptions(CLI::App* cmd, RenderOptions* o) {
    cmd->add_option("--spp", o->spp, "samples per pixel (default 64)")->check(CLI::PositiveNumber);
    cmd->add_option("--seconds", o->seconds, "render for this long instead of --spp")
        ->check(CLI::PositiveNumber);
    cmd->add_option("--target-noise", o->targetNoise,
                    "stop when the convergence meter's estimate of the relative RMSE (DESIGN.md "
                    "§4, e.g. 0.01 = 1 %) reaches this; --spp or --seconds cap it")
        ->check(CLI::PositiveNumber);
    cmd->add_flag("--no-meter", o->noMeter,
                  "one random sequence instead of the convergence meter's two (a little less "
                  "noise at equal samples; no noise estimate, no --target-noise)");
    cmd->add_option("--max-depth", o->maxDepth, "most scattering events on a path (1 = direct)");
    cmd->add_option("--resolution-scale", o->resolutionScale,
                    "trace this fraction of width and height, (0, 1], and upsample (guided by "
                    "the plate when there is one): preview speed at a measured error (default 1)")
        ->check(CLI::Range(1e-4f, 1.0f));
    cmd->add_option("--aperture-radius", o->apertureRadiusM, "thin lens aperture radius, metres")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--focus-distance", o->focusDistanceM, "thin lens focus distance, metres")
        ->check(CLI::PositiveNumber);
    cmd->add_option("--seed", o->seed, "random seed");
    cmd->add_option("--sampler", o->sampler,
                    "random numbers: sobol (Owen-scrambled Sobol', stratified; default) or "
                    "independent (PCG, for comparison)")
        ->check(CLI::IsMember({"sobol", "independent"}));
    cmd->add_option("--light-sampling", o->lightSampling,
                    "points on emissive triangles: solid-angle (uniform in the solid angle they "
                    "subtend; default) or area (uniform in area, for comparison)")
        ->check(CLI::IsMember({"solid-angle", "area"}));
}

// Caustics by progressive photon mapping.
void addPhotonOptions(CLI::App* cmd, RenderOptions* o) {
    cmd->add_option("--photons", o->photons,
                    "caustics by photon mapping: auto (default: when the scene has a smooth mirror "
                    "or glass and a light), on, off, or N photons per iteration (implies on)");
    cmd->add_option("--photon-radius", o->photonRadius,
                    "first gather radius, metres (default: 2.5% of the sphere around the specular "
                    "objects at 32768 photons per iteration, times sqrt(32768/photons))")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option(
           "--photon-alpha", o->photonAlpha,
           "progressive photon mapping's alpha in (0, 1]: radius ~ iteration^((alpha-1)/2); "
           "1 keeps it fixed (default 2/3)")
        ->check(CLI::Range(1e-3f, 1.0f));
    cmd->add_option("--photon-gather-cap", o->photonGatherCap,
                    "photon records a gather examines per grid cell at most; a fuller cell is "
                    "subsampled without bias (more: less noise in bright caustics, longer loops)")
        ->check(CLI::Range(1u, 1u << 20));
    cmd->add_option("--photon-neighbours", o->photonNeighbours,
                    "a gather that finds more photons than this within the radius shrinks its "
                    "radius to hold about this many: sharper caustics where photons are dense "
                    "(0: never)")
        ->capture_default_str()
        ->check(CLI::Range(0u, 1u << 20));
    cmd->add_option("--photon-splat", o->photonSplat,
                    "photons the camera sees directly go to the pixels they land in (true) "
                    "instead of a gather at the first hit (false); a lens grid or an aperture "
                    "always gathers")
        ->capture_default_str();
}

// What is written: the image, checkpoints, the plate, AOVs, denoising, the lens.
void addOutputOptions(CLI::App* cmd, RenderOptions* o) {
    cmd->add_option("--checkpoints", o->checkpoints,
                    "also write OUT_STEM.sppN.exr at these sample counts (N1,N2,...), and print "
                    "each one's time since start: a convergence curve from one run")
        ->delimiter(',');
    o->output.addTo(cmd, "", "PNG output", false);
    cmd->add_option("--firefly-clamp", o->fireflyClamp,
                    "clamp each sample's luminance to this (biased; off by default)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--out", o->out, "output: FILE.exr (linear HDR) or FILE.png")->required();
    cmd->add_flag("--quiet", o->quiet, "no progress on stderr");
    cmd->add_flag("--timing", o->timing,
                  "print one line on stdout: seconds spent loading, creating the device, "
                  "building the renderer (BVH, upload, pipeline), rendering and reading back, "
                  "and the GPU time of all dispatches and of the photon passes");
    cmd->add_option("--plate", o->plate,
                    "camera image to composite into: PNG/JPEG (sRGB, inverse tone mapped) or "
                    "OpenEXR (linear, used as is); sets the resolution")
        ->check(CLI::ExistingFile);
    o->plateCurve.addTo(cmd, "plate-", "LDR plate", true);
    o->plateCurve.addColourTo(cmd, "plate-", "LDR plate");
    cmd->add_option("--aov", o->aovs,
                    "also write buffers as OUT.<aov>.exr: composite, mixed, real, mask, and the "
                    "denoiser's guides albedo, normal, depth (first hit, mean over the samples)")
        ->delimiter(',')
        ->check(CLI::IsMember(fileAovNames()));
    cmd->add_option("--denoise", o->denoise,
                    "edge-avoiding a-trous denoiser on the rendered signal, never on the plate: "
                    "on, off (default), or auto (on below " +
                        std::to_string(kAutoDenoiseBelowSpp) +
                        " spp); composite, mixed and real AOVs are denoised with it")
        ->check(CLI::IsMember({"on", "off", "auto"}));
    cmd->add_option("--calibration", o->calibration,
                    "OpenCV calibration YAML of the scene camera: primary rays follow its lens "
                    "(pinhole + radial-tangential or fisheye) so the plate needs no resampling")
        ->check(CLI::ExistingFile);
}

}  // namespace

std::function<int()> addRenderCommand(CLI::App& app) {
    auto o = std::make_shared<RenderOptions>();
    CLI::App* cmd = app.add_subcommand("render", "render a scene to an image");
    addSceneOptions(cmd, o.get());
    addSamplingOptions(cmd, o.get());
    addPhotonOptions(cmd, o.get());
    addOutputOptions(cmd, o.get());
    return [o] { return run(*o); };
}

}  // namespace previs
