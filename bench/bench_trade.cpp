#include "bench/bench_trade.h"

#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <optional>
#include <vector>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/bench_scenes.h"
#include "bench/bench_stats.h"
#include "gpu/context.h"
#include "image/image.h"
#include "image/image_compare.h"
#include "render/quality_dial.h"
#include "render/renderer.h"
#include "render/tonemap.h"

namespace previs::bench {

namespace {

// One line of settings the trade is measured under.
struct TradeSetting {
    std::string name;  // e.g. "refinement depth 8"
    std::string mode;  // "refinement" (samples accumulate) or "preview" (each point one frame)
    uint32_t maxDepth = 8;
    float resolutionScale = 1.0f;
    bool denoise = false;     // each point's image denoised (its filter time counted)
    uint32_t sizeFactor = 1;  // the curve's width and height: this many times the bench's
};

// One measured point of a curve.
struct TradePoint {
    uint64_t spp = 0;
    double seconds = 0.0;  // wall time of the renders so far (readbacks and meter excluded)
    double rmse = 0.0;
    double relMse = 0.0;
    double noiseEstimate = -1.0;  // the meter's √relMSE estimate; -1 below 2 spp
};

RenderSettings baseSettings(uint32_t width, uint32_t height, uint32_t maxDepth) {
    RenderSettings rs;
    rs.width = width;
    rs.height = height;
    rs.maxDepth = maxDepth;
    rs.differential = true;
    rs.samplesPerDispatch = 64;  // lowered inside lavapipe's loop limit by the renderer
    return rs;
}

// The set filmed: the converged real-only solution is the plate, so the composite is what a
// camera filming that set would see with the bunny added; and the converged composite.
struct ConvergedSet {
    ImageF plate, reference;
};
Result<ConvergedSet> convergedSet(GpuContext& ctx, const Scene& scene, uint32_t width,
                                  uint32_t height, uint32_t maxDepth, uint32_t spp) {
    auto created = Renderer::create(ctx, scene, baseSettings(width, height, maxDepth));
    if (!created) return created.error();
    Renderer& r = **created;
    r.setSeed(0x5eed);
    if (Status s = r.render(spp); !s) return s.error();
    auto real = r.image(Aov::Real);
    if (!real) return real.error();
    ConvergedSet set;
    set.plate = *real;
    if (Status s = r.film().setPlate(set.plate, "the set's real-only render"); !s) return s.error();
    auto composite = r.image(Aov::Composite);
    if (!composite) return composite.error();
    set.reference = std::move(*composite);
    return set;
}

// The composite so far (denoised when asked, its filter time added to `seconds`) against the
// reference, and the meter.
Result<TradePoint> measurePoint(Renderer& r, const ImageF& reference, double seconds,
                                bool denoise) {
    const auto start = Clock::now();
    auto image = r.image(Aov::Composite, denoise);
    if (!image) return image.error();
    if (denoise) seconds += secondsSince(start);
    auto difference = compareImages(*image, reference);
    if (!difference) return difference.error();
    auto meter = r.convergence();
    if (!meter) return meter.error();
    TradePoint p;
    p.spp = r.samplesPerPixel();
    p.seconds = seconds;
    p.rmse = difference->rmse;
    p.relMse = difference->relMse;
    p.noiseEstimate = meter->composite.relativeRmse.value_or(-1.0);
    return p;
}

// A point at every power of two up to `maxSpp`. Refinement: one progressive render, time
// accumulating (and the figure-2 frame counts in `frames` written as PNGs). Preview: each point
// a preview frame of that many samples on its own, timed alone.
Result<std::vector<TradePoint>> measureCurve(GpuContext& ctx, const Scene& scene,
                                             const TradeSetting& setting, RenderSettings rs,
                                             const ImageF& plate, const ImageF& reference,
                                             uint32_t maxSpp, const std::vector<uint32_t>& frames,
                                             const std::filesystem::path& frameStem) {
    rs.resolutionScale = setting.resolutionScale;
    rs.denoise = setting.denoise;
    auto created = Renderer::create(ctx, scene, rs);
    if (!created) return created.error();
    Renderer& r = **created;
    if (Status s = r.film().setPlate(plate, "the set's real-only render"); !s) return s.error();
    // Warm-up: the first dispatch also sizes dispatches to the CPU loop limit.
    if (Status s = r.render(1); !s) return s.error();
    if (Status s = r.reset(); !s) return s.error();
    const bool preview = setting.mode == "preview";
    std::vector<uint32_t> stops;
    for (uint32_t n = 1; n <= maxSpp; n *= 2) stops.push_back(n);
    if (!preview) stops.insert(stops.end(), frames.begin(), frames.end());
    std::sort(stops.begin(), stops.end());
    stops.erase(std::unique(stops.begin(), stops.end()), stops.end());
    std::vector<TradePoint> curve;
    double seconds = 0.0;
    for (uint32_t stop : stops) {
        const auto start = Clock::now();
        if (preview) {
            if (Status s = r.renderPreviewFrame(stop); !s) return s.error();
            seconds = secondsSince(start);
        } else {
            if (Status s = r.render(uint32_t(stop - r.samplesPerPixel())); !s) return s.error();
            seconds += secondsSince(start);
        }
        if (std::find(frames.begin(), frames.end(), stop) != frames.end()) {
            auto image = r.image(Aov::Composite);
            if (!image) return image.error();
            const std::string path = frameStem.string() + fmt::format("_{:04d}.png", stop);
            if (Status s = writePng(path, image->width, image->height,
                                    toneMapToSrgb8(*image, ToneMapSettings{}));
                !s)
                return s.error();
        }
        if ((stop & (stop - 1)) != 0) continue;  // a figure-2 frame only
        auto point = measurePoint(r, reference, seconds, setting.denoise);
        if (!point) return point.error();
        curve.push_back(*point);
    }
    return curve;
}

extern "C" char** environ;

// Runs `python3 script dir` and waits: posix_spawn, as the process holds a Vulkan device's
// threads (no fork). Debian's own interpreter, which has Debian's matplotlib, where there is
// one: a python3 earlier on PATH (a virtualenv, pyenv) may not.
Status runPlotter(const std::filesystem::path& script, const std::filesystem::path& dir) {
    std::string python =
        std::filesystem::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
    std::string scriptArg = script.string(), dirArg = dir.string();
    char* argv[] = {python.data(), scriptArg.data(), dirArg.data(), nullptr};
    pid_t pid = 0;
    if (int e = posix_spawnp(&pid, python.c_str(), nullptr, nullptr, argv, environ); e != 0)
        return makeError("cannot run python3 {}: {}", scriptArg, std::strerror(e));
    int status = 0;
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
        return makeError(
            "python3 {} {} failed (is python3-matplotlib installed? scripts/setup.sh installs "
            "it)",
            scriptArg, dirArg);
    return {};
}

// Figure 4: median wall time of one 1-spp frame at each resolution.
Result<std::vector<std::pair<std::string, double>>> measureResolutions(
    GpuContext& ctx, const Scene& scene, const std::vector<std::pair<uint32_t, uint32_t>>& sizes,
    uint32_t maxDepth, int reps) {
    std::vector<std::pair<std::string, double>> out;
    for (auto [w, h] : sizes) {
        benchProgress("trade: figure 4, {}x{}", w, h);
        auto created = Renderer::create(ctx, scene, baseSettings(w, h, maxDepth));
        if (!created) return created.error();
        Renderer& r = **created;
        if (Status s = r.renderPreviewFrame(1); !s) return s.error();  // warm-up
        std::vector<double> times;
        for (int i = 0; i < reps; ++i) {
            const auto start = Clock::now();
            if (Status s = r.renderPreviewFrame(1); !s) return s.error();
            times.push_back(secondsSince(start));
        }
        out.emplace_back(fmt::format("{}x{}", w, h), median(times));
    }
    return out;
}

}  // namespace

int runTradeBench(const TradeBenchOptions& o) {
    auto fail = [](const Error& e) {
        logError("bench trade: {}", e.message);
        return 1;
    };
    std::error_code ec;
    std::filesystem::create_directories(o.outDir, ec);
    if (ec) {
        logError("bench trade: cannot create {}: {}", o.outDir.string(), ec.message());
        return 1;
    }
    auto ctx = GpuContext::create({});
    if (!ctx) return fail(ctx.error());

    // The bunny (virtual) on the floor (real), as the differential section has it.
    const std::string env = o.dataDir + "/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr";
    auto bunny = bunnyScene(o.dataDir, env);
    if (!bunny) return fail(bunny.error());
    Scene scene = *bunny;
    for (size_t t = 0; t < 2; ++t) scene.geometry.triangleIsReal[t] = 1;

    const uint32_t width = o.quick ? 48 : 96, height = o.quick ? 36 : 72;
    const uint32_t referenceSpp = o.quick ? 256 : 4096, maxSpp = o.quick ? 64 : 1024;
    const uint32_t referenceDepth = 16;
    std::printf(
        "## The speed/accuracy trade: bunny (virtual) on a real floor, environment light, "
        "%ux%u, against a %u-spp reference at max depth %u (CSV and plots in %s)\n\n",
        width, height, referenceSpp, referenceDepth, o.outDir.string().c_str());

    // The reference and the plate (convergedSet).
    benchProgress("trade: reference, {} spp", referenceSpp);
    auto set = convergedSet(**ctx, scene, width, height, referenceDepth, referenceSpp);
    if (!set) return fail(set.error());
    const ImageF& reference = set->reference;
    if (Status s = writeExr((o.outDir / "reference.exr").string(), reference); !s)
        return fail(s.error());

    std::vector<TradeSetting> settings;
    for (uint32_t depth : {1u, 2u, 4u, 8u, 16u})
        settings.push_back({fmt::format("refinement depth {}", depth), "refinement", depth});
    settings.push_back({"refinement depth 8 denoised", "refinement", 8, 1.0f, true});
    // Preview frames: the fixed sequence, each point one frame; at full resolution and at the
    // dial's 640×480 choice (BENCHMARKS.md), a third of it upsampled.
    settings.push_back({"preview depth 2", "preview", 2});
    settings.push_back({"preview depth 2 scale 1/3", "preview", 2, 1.0f / 3.0f});
    // Per resolution: the same refinement at twice the width and height, against its own
    // reference of a quarter of the samples (same cost; its noise is then a quarter of the
    // 256-spp point's MSE), to 256 spp.
    const std::string doubled = fmt::format("{}x{}", 2 * width, 2 * height);
    settings.push_back({"refinement depth 8 at " + doubled, "refinement", 8, 1.0f, false, 2});
    settings.push_back(
        {"refinement depth 8 at " + doubled + " denoised", "refinement", 8, 1.0f, true, 2});
    const std::vector<uint32_t> figure2Frames =
        o.quick ? std::vector<uint32_t>{1, 10} : std::vector<uint32_t>{1, 10, 100, 1000};

    std::ofstream csv(o.outDir / "trade.csv");
    csv << "setting,mode,width,height,max_depth,resolution_scale,denoise,spp,seconds,rmse,relmse,"
           "noise_estimate\n";
    std::printf("| setting | spp | seconds | RMSE | √relMSE | meter's estimate |\n");
    std::printf("|---|---|---|---|---|---|\n");
    std::optional<ConvergedSet> doubleSet;
    for (const TradeSetting& s : settings) {
        benchProgress("trade: {}", s.name);
        const bool figure2 = s.mode == "refinement" && s.maxDepth == 8 && s.sizeFactor == 1;
        const uint32_t w = width * s.sizeFactor, h = height * s.sizeFactor;
        const uint32_t factor2 = s.sizeFactor * s.sizeFactor;
        if (s.sizeFactor != 1 && !doubleSet) {
            benchProgress("trade: reference at {}x{}, {} spp", w, h, referenceSpp / factor2);
            auto other = convergedSet(**ctx, scene, w, h, referenceDepth, referenceSpp / factor2);
            if (!other) return fail(other.error());
            doubleSet = std::move(*other);
        }
        const ConvergedSet& curveSet = s.sizeFactor == 1 ? *set : *doubleSet;
        auto curve = measureCurve(**ctx, scene, s, baseSettings(w, h, s.maxDepth), curveSet.plate,
                                  curveSet.reference, maxSpp / factor2,
                                  figure2 && !s.denoise ? figure2Frames : std::vector<uint32_t>{},
                                  o.outDir / "figure2");
        if (!curve) return fail(curve.error());
        for (const TradePoint& p : *curve) {
            // (Setting names hold no comma.)
            csv << fmt::format("{},{},{},{},{},{:.4f},{},{},{:.6f},{:.6g},{:.6g},{:.6g}\n", s.name,
                               s.mode, w, h, s.maxDepth, s.resolutionScale, int(s.denoise), p.spp,
                               p.seconds, p.rmse, p.relMse, p.noiseEstimate);
            if ((p.spp & 0x55555555u) != 0 || p.spp == 1)  // 1, 4, 16, 64, 256, 1024
                std::printf(
                    "| %s | %llu | %.3f | %.4f | %.4f | %s |\n", s.name.c_str(),
                    (unsigned long long)p.spp, p.seconds, p.rmse, std::sqrt(p.relMse),
                    p.noiseEstimate < 0 ? "-" : fmt::format("{:.4f}", p.noiseEstimate).c_str());
        }
        std::fflush(stdout);
    }
    csv.close();

    const std::vector<std::pair<uint32_t, uint32_t>> sizes =
        o.quick ? std::vector<std::pair<uint32_t, uint32_t>>{{80, 60}, {160, 120}}
                : std::vector<std::pair<uint32_t, uint32_t>>{
                      {160, 120}, {320, 240}, {640, 480}, {1280, 720}, {1920, 1080}};
    auto times = measureResolutions(**ctx, scene, sizes, 8, o.quick ? 1 : o.repetitions);
    if (!times) return fail(times.error());
    std::ofstream resolution(o.outDir / "resolution.csv");
    resolution << "resolution,pixels,seconds_per_frame\n";
    std::printf("\n| resolution | ms per 1-spp frame (median) |\n|---|---|\n");
    for (size_t i = 0; i < times->size(); ++i) {
        const auto& [name, seconds] = (*times)[i];
        resolution << fmt::format("{},{},{:.6f}\n", name,
                                  uint64_t(sizes[i].first) * sizes[i].second, seconds);
        std::printf("| %s | %.1f |\n", name.c_str(), seconds * 1e3);
    }
    resolution.close();

    // The dial: preview at 640×480 (the target, 10 frames per second).
    {
        const uint32_t w = o.quick ? 64 : 640, h = o.quick ? 48 : 480;
        const uint32_t dialReferenceSpp = o.quick ? 32 : 128;
        const double targetFps = 10.0;
        benchProgress("trade: dial reference {}x{}, {} spp", w, h, dialReferenceSpp);
        auto dialSet = convergedSet(**ctx, scene, w, h, referenceDepth, dialReferenceSpp);
        if (!dialSet) return fail(dialSet.error());
        const ImageF& dialPlate = dialSet->plate;
        const ImageF& dialReference = dialSet->reference;
        // The scene has no specular object a small light reaches: no photon axis.
        const DialAxes axes = {
            {1.0f, 0.5f, 1.0f / 3.0f, 0.25f}, {1, 2, 4}, {2, 4, 8}, {0, 2, 4}, {}};
        const std::vector<DialPoint> grid = dialGrid(axes);
        benchProgress("trade: dial, {} settings at {}x{}", grid.size(), w, h);
        // Guides written for every point, as in a service that may denoise.
        RenderSettings dialSettings = baseSettings(w, h, referenceDepth);
        dialSettings.denoise = true;
        auto dialRenderer = Renderer::create(**ctx, scene, dialSettings);
        if (!dialRenderer) return fail(dialRenderer.error());
        if (Status s = (*dialRenderer)->film().setPlate(dialPlate, "the set's real-only render");
            !s)
            return fail(s.error());
        auto measured =
            measureDial(**dialRenderer, grid, dialReference, o.quick ? 1 : o.repetitions);
        if (!measured) return fail(measured.error());
        const std::vector<size_t> front = paretoFront(*measured);
        const std::optional<size_t> chosen = chooseForFrameRate(*measured, targetFps);
        std::ofstream dial(o.outDir / "dial.csv");
        dial << "scale,spp,max_depth,denoise_levels,photons,frame_seconds,rmse,pareto,chosen\n";
        for (size_t i = 0; i < measured->size(); ++i) {
            const DialMeasurement& m = (*measured)[i];
            dial << fmt::format("{:.4f},{},{},{},{},{:.6f},{:.6g},{},{}\n", m.point.resolutionScale,
                                m.point.samplesPerFrame, m.point.maxDepth,
                                m.point.denoiseIterations, m.point.photons, m.frameSeconds, m.error,
                                int(std::find(front.begin(), front.end(), i) != front.end()),
                                int(chosen == i));
        }
        dial.close();
        std::printf(
            "\n## The dial: preview at %ux%u, target %.0f frames per second (RMSE of one frame "
            "against a %u-spp reference)\n\n| point | ms per frame | fps | RMSE | |\n"
            "|---|---|---|---|---|\n",
            w, h, targetFps, dialReferenceSpp);
        if (!chosen) {
            std::printf("no grid point reaches %.0f fps on this machine\n", targetFps);
        } else {
            auto row = [&](size_t i, const char* note) {
                const DialMeasurement& m = (*measured)[i];
                std::printf("| %s | %.1f | %.1f | %.4f | %s |\n", m.point.describe().c_str(),
                            m.frameSeconds * 1e3, 1.0 / m.frameSeconds, m.error, note);
            };
            row(*chosen, "**chosen**");
            for (size_t n : gridNeighbours(*measured, *chosen, axes)) {
                const DialMeasurement& m = (*measured)[n];
                const DialMeasurement& c = (*measured)[*chosen];
                const bool dominates = m.frameSeconds <= c.frameSeconds && m.error <= c.error;
                row(n, dominates                          ? "DOMINATES the choice"
                       : m.frameSeconds > 1.0 / targetFps ? "neighbour: over the frame budget"
                                                          : "neighbour: less accurate");
            }
        }
        std::printf("\nPareto front (fastest first):\n\n");
        for (size_t i : front)
            std::printf("- %s: %.1f ms, RMSE %.4f\n", (*measured)[i].point.describe().c_str(),
                        (*measured)[i].frameSeconds * 1e3, (*measured)[i].error);
    }

    if (!o.plotter.empty()) {
        benchProgress("trade: plots");
        if (Status s = runPlotter(o.plotter, o.outDir); !s) return fail(s.error());
    }
    std::printf("\n");
    return 0;
}

}  // namespace previs::bench
