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
// time of 16 one-sample dispatches (BENCHMARKS.md, "Issue 8: path regeneration"); more gains
// little and makes the progress line and --seconds coarser.
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

// A --timing field: the value, or "none".
std::string number(std::optional<double> v) {
    return v ? fmt::format("{:.6g}", *v) : std::string("none");
}

bool isGuideAov(const std::string& name) {
    return name == "albedo" || name == "normal" || name == "depth";
}

// `--out dir/name.exr` → `dir/name.<aov>.exr` (DESIGN.md §3).
std::string aovPath(const std::string& out, const std::string& aov) {
    std::filesystem::path p(out);
    return (p.parent_path() / (p.stem().string() + "." + aov + ".exr")).string();
}

int run(RenderOptions& o) {
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
    if (Status s = checkOutputFile("--out", o.out); !s) {
        logError("{}", s.message());
        return 2;
    }
    if (Status s = o.plateCurve.buildColour(); !s) {
        logError("{}", s.message());
        return 2;
    }
    // --timing: the stages from here to the image in memory (the file write excluded).
    using Clock = std::chrono::steady_clock;
    const auto runStart = Clock::now();
    auto since = [](Clock::time_point t) {
        return std::chrono::duration<double>(Clock::now() - t).count();
    };
    // The scene and its map load on a second core while this thread starts the Vulkan device
    // (lavapipe's start, LLVM's included, is about 0.1 s): neither needs the other, and every
    // Vulkan call stays on this thread. Errors are reported in the order of the work: the
    // scene's, the map's, then the device's.
    struct Loaded {
        Result<Scene> scene;
        std::optional<Result<EnvironmentMap>> env;
        double seconds;
    };
    auto loading = std::async(std::launch::async, [&o, runStart, since] {
        Loaded l{loadScene(o.scene), std::nullopt, 0.0};
        if (l.scene && !o.env.empty()) l.env.emplace(loadEnvironmentMap(o.env));
        l.seconds = since(runStart);
        return l;
    });
    auto ctx = GpuContext::create({});
    const double deviceAndLoadSeconds = since(runStart);
    Loaded loaded = loading.get();
    // device_s: the part of the device's start the loading did not hide.
    const double deviceSeconds = std::max(0.0, deviceAndLoadSeconds - loaded.seconds);
    auto& scene = loaded.scene;
    if (!scene) {
        logError("{}", scene.message());
        return 2;
    }
    if (loaded.env) {
        auto& env = *loaded.env;
        if (!env) {
            logError("{}", env.message());
            return 2;
        }
        // --env replaces the description's whole [environment]: its rotation and scale were
        // set for its own map, not for this one.
        scene->environment = std::move(env.value());
    }
    if (!scene->environment && !hasLightSource(*scene))
        logWarning(
            "{}: the scene has no light source (no KHR_lights_punctual light, no emissive "
            "material) and no environment map, so it renders black; add --env studio for "
            "neutral studio lighting, or --env MAP.exr",
            o.scene);
    if (scene->environment) {
        if (o.envRotationDeg)
            scene->environment->rotationRad = *o.envRotationDeg * float(M_PI / 180.0);
        if (o.envScale) scene->environment->scale = *o.envScale;
    }

    RenderSettings settings;
    // --camera wins over the scene description's camera.name.
    const std::string cameraName = !o.camera.empty() ? o.camera : scene->cameraName;
    if (!cameraName.empty()) {
        auto it = std::find_if(scene->cameras.begin(), scene->cameras.end(),
                               [&](const Camera& c) { return c.name == cameraName; });
        if (it == scene->cameras.end()) {
            logError("{}: no camera named '{}' ({} camera(s) in the file)", o.scene, cameraName,
                     scene->cameras.size());
            return 2;
        }
        settings.cameraIndex = int(it - scene->cameras.begin());
    }
    float aspect = 4.0f / 3.0f;
    if (!scene->cameras.empty() && scene->cameras[settings.cameraIndex].aspectRatio > 0.0f)
        aspect = scene->cameras[settings.cameraIndex].aspectRatio;
    settings.width =
        o.width ? o.width : (o.height ? uint32_t(std::lround(o.height * aspect)) : 640);
    settings.height = o.height ? o.height : uint32_t(std::lround(settings.width / aspect));
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
    // A lane whose path ends starts its next sample at once (trace_paths.comp). The renderer lowers
    // this inside lavapipe's loop limit; photon iterations dispatch one sample each.
    settings.samplesPerDispatch = kSamplesPerDispatch;

    // The plate: linear radiance at the render's resolution (its own resolution by default).
    std::optional<ImageF> plate;
    if (!o.plate.empty()) {
        auto img = readImage(o.plate);
        if (!img) {
            logError("{}", img.message());
            return 2;
        }
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
                "--plate {} is {}x{} but the render is {}x{}: render at the plate's "
                "resolution (omit --width/--height)",
                o.plate, plate->width, plate->height, settings.width, settings.height);
            return 2;
        }
    }
    if (!o.calibration.empty()) {
        auto calib = CameraCalibration::load(o.calibration);
        if (!calib) {
            logError("{}", calib.message());
            return 2;
        }
        if (!o.width && !o.height && !plate) {
            settings.width = uint32_t(calib->imageSize().width);
            settings.height = uint32_t(calib->imageSize().height);
        }
        auto grid = lensRayGrid(*calib, settings.width, settings.height);
        if (!grid) {
            logError("--calibration {}: {}", o.calibration, grid.message());
            return 2;
        }
        settings.lensGrid = std::move(grid.value());
    }
    bool wantsReal = std::find(o.aovs.begin(), o.aovs.end(), "real") != o.aovs.end();
    // The real-only solution costs extra rays: computed only when something uses it.
    settings.differential = plate.has_value() || wantsReal;
    settings.convergenceMeter = !o.noMeter;
    // Guides are written only when something may use them: the denoiser, or a guide AOV.
    settings.denoise = o.denoise != "off" || std::any_of(o.aovs.begin(), o.aovs.end(), isGuideAov);

    const double loadSeconds = since(runStart) - deviceSeconds;
    if (!ctx) {
        logError("{}", ctx.message());
        return 1;
    }
    const auto setupStart = Clock::now();
    auto renderer = Renderer::create(**ctx, *scene, settings);
    if (!renderer) {
        logError("{}: {}", o.scene, renderer.message());
        return 1;
    }
    if (plate) {
        if (Status s = (*renderer)->setPlate(*plate, fmt::format("--plate {}", o.plate)); !s) {
            logError("--plate {}: {}", o.plate, s.message());
            return 2;
        }
    }
    const double setupSeconds = since(setupStart);
    auto start = std::chrono::steady_clock::now();
    auto elapsed = [&] {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
    // --target-noise alone runs until the meter says so; with --spp or --seconds those cap it.
    uint32_t target = o.spp ? o.spp : (o.seconds > 0.0 || o.targetNoise > 0.0 ? UINT32_MAX : 64);
    ProgressLine progress("render", o.quiet);
    NoiseSchedule meter(o.targetNoise);
    auto showProgress = [&](uint64_t samples) {
        const Renderer& r = **renderer;
        // Photons: per iteration, and the radius the next iteration gathers with.
        std::string photons = r.photonsActive()
                                  ? fmt::format(", {} photons/iteration, radius {:.3g} m",
                                                r.photonsPerIteration(), r.nextPhotonRadius())
                                  : "";
        std::string noise;
        if (meter.noise()) {
            noise = fmt::format(", noise {:.2f} %", *meter.noise() * 100.0);
            const std::optional<double> eta =
                o.targetNoise > 0.0
                    ? etaSeconds(meter.noise(), samples, o.targetNoise, elapsed() / double(samples))
                    : std::nullopt;
            if (eta)
                noise +=
                    fmt::format(" (target {:.2f} %, ETA {:.0f} s)", o.targetNoise * 100.0, *eta);
        }
        progress.update(fmt::format("{}{} spp, {:.1f} s{}{}", samples,
                                    o.spp ? fmt::format("/{}", o.spp) : "", elapsed(), noise,
                                    photons));
    };
    while ((*renderer)->samplesPerPixel() < target) {
        const uint64_t before = (*renderer)->samplesPerPixel();
        // The next chunk ends where something must happen: the target, a checkpoint, the time
        // limit of --seconds (estimated from the samples so far), or with --target-noise the
        // meter's next look. Without a target the meter looks after the chunk that passes it.
        uint64_t chunk = std::min<uint64_t>(target - before, kSamplesPerDispatch);
        for (uint64_t c : o.checkpoints)
            if (c > before) chunk = std::min(chunk, c - before);
        if (o.targetNoise > 0.0)
            chunk = std::min(chunk, std::max<uint64_t>(meter.nextLook(), before + 1) - before);
        if (o.seconds > 0.0 && before > 0) {
            const double perSample = elapsed() / double(before);
            chunk = std::min(chunk, uint64_t(std::max(1.0, (o.seconds - elapsed()) / perSample)));
        }
        auto onDispatch = [&](const RenderProgress& p) {
            if (p.samplesDone < p.samplesTotal) showProgress(before + p.samplesDone);
        };
        if (Status s = (*renderer)->render(uint32_t(chunk), onDispatch); !s) {
            logError("{}", s.message());
            return 1;
        }
        if (meter.due((*renderer)->samplesPerPixel())) {
            auto c = (*renderer)->convergence();
            if (!c) {
                logError("{}", c.message());
                return 1;
            }
            meter.looked((*renderer)->samplesPerPixel(), c->composite.relativeRmse);
        }
        showProgress((*renderer)->samplesPerPixel());
        if (meter.reached()) break;
        const uint64_t done = (*renderer)->samplesPerPixel();
        if (std::find(o.checkpoints.begin(), o.checkpoints.end(), done) != o.checkpoints.end()) {
            // For convergence curves in one run: the image so far and the time it took (from
            // the start of the run, so device creation, BVH build and compile count).
            auto snapshot = (*renderer)->image();
            std::filesystem::path p(o.out);
            std::string path =
                (p.parent_path() / fmt::format("{}.spp{}.exr", p.stem().string(), done)).string();
            Status s = snapshot ? writeExr(path, *snapshot) : Status(snapshot.error());
            if (!s) {
                logError("{}", s.message());
                return 1;
            }
            std::printf("checkpoint spp=%llu total_s=%.4f file=%s\n", (unsigned long long)done,
                        since(runStart), path.c_str());
            std::fflush(stdout);
        }
        if (o.seconds > 0.0 && elapsed() >= o.seconds) break;
    }
    progress.finish();
    const double renderSeconds = elapsed();
    auto convergence = (*renderer)->convergence();
    if (!convergence) {
        logError("{}", convergence.message());
        return 1;
    }
    const std::optional<double> noise = convergence->composite.relativeRmse;
    auto percent = [](std::optional<double> v) {
        return v ? fmt::format("{:.2f} %", *v * 100.0) : std::string("unknown");
    };
    const auto readbackStart = Clock::now();
    auto stats = (*renderer)->stats();
    if (!stats) {
        logError("{}", stats.message());
        return 1;
    }
    const uint32_t dropped = stats->nonFiniteSamples;
    if (dropped > 0)
        logWarning(
            "{} sample(s) were NaN or infinite ({} ray(s) with a NaN/Inf origin or "
            "direction culled) and were dropped: each pixel is the mean of its remaining "
            "samples",
            dropped, stats->nonFiniteRays);

    // The one place --denoise auto decides (autoDenoise, render/denoiser.h).
    const bool denoised =
        o.denoise == "on" ||
        (o.denoise == "auto" && autoDenoise(noise, o.targetNoise, (*renderer)->samplesPerPixel()));
    auto image = (*renderer)->image(Aov::Composite, denoised);
    if (!image) {
        logError("{}", image.message());
        return 1;
    }
    if (o.timing) {
        // load: scene and environment files; device: Vulkan instance and device; setup: BVH
        // build, upload, pipeline compile; render: the samples; readback: the image to host;
        // gpu: the dispatches' GPU time, photon_gpu: of which the photon passes; dropped: the
        // NaN/Inf samples left out of the pixel means; noise, differential_noise: the
        // convergence meter's relative RMSE estimates ("none" below 2 spp).
        std::printf(
            "timing load_s=%.4f device_s=%.4f setup_s=%.4f render_s=%.4f readback_s=%.4f "
            "total_s=%.4f gpu_s=%.4f photon_gpu_s=%.4f dropped_samples=%u spp=%llu noise=%s "
            "differential_noise=%s\n",
            loadSeconds, deviceSeconds, setupSeconds, renderSeconds, since(readbackStart),
            since(runStart), (*renderer)->gpuMilliseconds() * 1e-3,
            (*renderer)->photonMilliseconds() * 1e-3, dropped,
            (unsigned long long)(*renderer)->samplesPerPixel(), number(noise).c_str(),
            number(convergence->differential.relativeRmse).c_str());
        std::fflush(stdout);
    }
    Status written;
    if (endsWith(o.out, ".exr")) {
        written = writeExr(o.out, *image);
    } else {
        written = writePng(o.out, image->width, image->height,
                           toneMapToSrgb8(*image, o.output.forward()));
    }
    if (!written) {
        logError("{}", written.message());
        return 1;
    }
    for (const std::string& name : o.aovs) {
        Aov aov = name == "mixed"    ? Aov::Mixed
                  : name == "real"   ? Aov::Real
                  : name == "mask"   ? Aov::Mask
                  : name == "albedo" ? Aov::Albedo
                  : name == "normal" ? Aov::Normal
                  : name == "depth"  ? Aov::Depth
                                     : Aov::Composite;
        auto buffer = (*renderer)->image(aov, denoised);
        Status s = buffer ? writeExr(aovPath(o.out, name), *buffer) : Status(buffer.error());
        if (!s) {
            logError("{}", s.message());
            return 1;
        }
    }
    if (!o.quiet)
        logInfo("wrote {} ({}x{}, {} spp{}, {:.1f} s on {}, noise {}{})", o.out, image->width,
                image->height, (*renderer)->samplesPerPixel(), denoised ? ", denoised" : "",
                elapsed(), (*ctx)->deviceName(), percent(noise),
                dropped > 0 ? fmt::format(", {} NaN/Inf sample(s) dropped", dropped) : "");
    return 0;
}

}  // namespace

std::function<int()> addRenderCommand(CLI::App& app) {
    auto o = std::make_shared<RenderOptions>();
    CLI::App* cmd = app.add_subcommand("render", "render a scene to an image");
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
        ->check(CLI::IsMember({"composite", "mixed", "real", "mask", "albedo", "normal", "depth"}));
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
    return [o] { return run(*o); };
}

}  // namespace previs
