#include "bench/bench_runner.h"

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <vector>

#include "base/log.h"
#include "bench/bench_denoise.h"
#include "bench/bench_memory.h"
#include "bench/bench_network.h"
#include "bench/bench_pose_filter.h"
#include "bench/bench_preview.h"
#include "bench/bench_progress.h"
#include "bench/bench_recorder.h"
#include "bench/bench_scenes.h"
#include "bench/bench_service.h"
#include "bench/bench_shot.h"
#include "bench/bench_stats.h"
#include "bench/bench_trade.h"
#include "bench/pose_accuracy.h"
#include "gpu/context.h"
#include "render/renderer.h"
#include "scene/gltf_loader.h"

namespace previs::bench {

namespace {

struct Measurement {
    double seconds = 0.0;  // median wall time of `spp` samples per pixel
    double gpuMs = 0.0;    // median GPU (timestamp) time of the same
    double pathsPerSecond = 0.0;
    double raysPerSecond = 0.0;
    double bvhSeconds = 0.0;
    double sahCost = 0.0;
    size_t triangles = 0;
};

// Builds a renderer (BVH, upload, pipeline), renders one warm-up sample, then times `spp`
// samples per pixel `reps` times.
Result<Measurement> measure(GpuContext& ctx, const Scene& scene, RenderSettings settings,
                            uint32_t spp, int reps, const RendererTestOptions& testOptions = {}) {
    auto renderer = Renderer::create(ctx, scene, settings, {}, testOptions);
    if (!renderer) return renderer.error();
    Renderer& r = **renderer;
    if (Status s = r.render(1); !s) return s.error();
    std::vector<double> wall, gpu, rays;
    for (int i = 0; i < reps; ++i) {
        if (Status s = r.reset(); !s) return s.error();
        double gpuBefore = r.gpuMilliseconds();
        auto start = std::chrono::steady_clock::now();
        if (Status s = r.render(spp); !s) return s.error();
        wall.push_back(
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        gpu.push_back(r.gpuMilliseconds() - gpuBefore);
        auto traced = r.raysTraced();
        rays.push_back(traced ? double(*traced) : 0.0);
    }
    Measurement m;
    m.seconds = median(wall);
    m.gpuMs = median(gpu);
    double paths = double(settings.width) * settings.height * spp;
    m.pathsPerSecond = paths / m.seconds;
    m.raysPerSecond = median(rays) / m.seconds;
    m.bvhSeconds = r.bvh().buildSeconds;
    m.sahCost = r.bvh().sahCost;
    m.triangles = scene.geometry.triangles.size();
    return m;
}

std::string millions(double v) { return fmt::format("{:.2f} M", v * 1e-6); }

}  // namespace

int runBenchmarks(const BenchOptions& o) {
    // The network's CPU costs need neither examples, data nor a Vulkan device.
    if (o.only == "ltc") return runLtcBench(o.quick);
    if (o.only == "network") return runNetworkEncodeBench(o.quick);
    if (o.examplesDir.empty()) {
        logError("bench: the project's examples/ folder was not found beside or above previs");
        return 2;
    }
    if (o.only != "service" && o.only != "shot" && o.dataDir.empty()) {
        logError(
            "bench: no shared data found (meshes, environment maps): pass --data DIR or set "
            "PREVIS_DATA_DIR");
        return 2;
    }
    // Before any Vulkan device or thread exists: the service bench forks a child per run.
    if (o.only == "service") {
        ServiceBenchOptions service;
        service.examplesDir = o.examplesDir;
        service.quick = o.quick;
        service.csvPath = o.csvPath;
        return runServiceBench(service);
    }
    if (o.only == "recorder")
        return runRecorderBench(
            {.examplesDir = o.examplesDir, .dataDir = o.dataDir, .quick = o.quick});
    if (o.only == "shot")
        return runShotBench({.examplesDir = o.examplesDir,
                             .quick = o.quick,
                             .csvPath = o.csvPath,
                             .referenceCache = o.referenceCache,
                             .variant = o.variant});
    if (o.only == "trade")
        return runTradeBench({.dataDir = o.dataDir,
                              .outDir = o.outDir,
                              .plotter = o.plotter,
                              .quick = o.quick,
                              .repetitions = o.repetitions});
    // Also before any Vulkan device: each resolution runs in a forked child (peak RSS per run).
    if (o.only == "memory")
        return runMemoryBench({.dataDir = o.dataDir, .spp = o.quick ? 1 : o.spp});
    if (o.only == "preview") {
        PreviewBenchOptions preview;
        preview.dataDir = o.dataDir;
        preview.quick = o.quick;
        preview.rounds = o.repetitions;
        preview.csvPath = o.csvPath;
        return runPreviewBench(preview);
    }
    auto ctx = GpuContext::create({});
    if (!ctx) {
        logError("{}", ctx.message());
        return 1;
    }
    // Only by name: its reference render runs for minutes.
    if (o.only == "denoise")
        return runDenoiseBench(
            **ctx, {.dataDir = o.dataDir, .quick = o.quick, .repetitions = o.repetitions});
    const int reps = o.quick ? 1 : o.repetitions;
    const uint32_t spp = o.quick ? 1 : o.spp;
    const std::string env = o.dataDir + "/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr";
    auto want = [&](const char* section) { return o.only.empty() || o.only == section; };
    std::printf("Device: %s. Timings are medians of %d run(s); paths = pixels × spp.\n\n",
                (*ctx)->deviceName().c_str(), reps);

    auto fail = [](const Error& e) {
        logError("{}", e.message);
        return 1;
    };

    std::vector<std::pair<std::string, Scene>> scenes;
    auto loadMesh = [&](const std::string& name) { return readPly(o.dataDir + "/meshes/" + name); };

    if (want("throughput")) {
        std::printf("## Throughput, 640×480, %u spp, environment map, max depth 8\n\n", spp);
        std::printf(
            "| scene | triangles | BVH build | SAH cost | ms / spp | paths/s | rays/s | "
            "peak RSS |\n|---|---|---|---|---|---|---|---|\n");
        auto bunny = bunnyScene(o.dataDir, env);
        if (!bunny) return fail(bunny.error());
        auto dragon = loadMesh("dragon_vrip_res2.ply");
        if (!dragon) return fail(dragon.error());
        Scene bigDragon = meshOnPlaneScene(subdivide(*dragon), env, 0.3f);
        std::pair<const char*, const Scene*> list[] = {{"bunny on a plane", &bunny.value()},
                                                       {"dragon ×4 subdivided", &bigDragon}};
        for (auto [name, scene] : list) {
            RenderSettings rs = renderSettings(640, 480, 8);
            benchProgress("throughput {}", name);
            auto m = measure(**ctx, *scene, rs, spp, reps);
            if (!m) return fail(m.error());
            std::printf("| %s | %zu | %.3f s | %.1f | %.1f | %s | %s | %.0f MiB |\n", name,
                        m->triangles, m->bvhSeconds, m->sahCost, m->seconds * 1e3 / spp,
                        millions(m->pathsPerSecond).c_str(), millions(m->raysPerSecond).c_str(),
                        peakRssMiB());
            std::fflush(stdout);
        }
        std::printf("\n");
    }

    if (want("resolution")) {
        auto mesh = loadMesh("dragon_vrip_res3.ply");
        if (!mesh) return fail(mesh.error());
        Scene scene = meshOnPlaneScene(*mesh, env, 0.3f);
        std::printf(
            "## Rendering time against resolution (paper's figure 4): %zu triangles, "
            "1 spp, max depth 4\n\n| resolution | ms / frame | GPU ms | paths/s |\n"
            "|---|---|---|---|\n",
            scene.geometry.triangles.size());
        for (auto [w, h] :
             {std::pair{320u, 240u}, {640u, 480u}, {800u, 600u}, {1280u, 720u}, {1920u, 1080u}}) {
            RenderSettings rs = renderSettings(w, h, 4);
            benchProgress("resolution {}x{}", w, h);
            auto m = measure(**ctx, scene, rs, 1, reps);
            if (!m) return fail(m.error());
            std::printf("| %u×%u | %.1f | %.1f | %s |\n", w, h, m->seconds * 1e3, m->gpuMs,
                        millions(m->pathsPerSecond).c_str());
            std::fflush(stdout);
        }
        std::printf("\n");
    }

    if (want("triangles")) {
        std::printf(
            "## Rendering time against triangle count: 640×480, %u spp, max depth 4\n\n"
            "| mesh | triangles | BVH build | ms / spp | paths/s | rays/s |\n"
            "|---|---|---|---|---|---|\n",
            spp);
        for (const char* name :
             {"teapot_newell.ply", "dragon_vrip_res4.ply", "dragon_vrip_res3.ply",
              "stanford_bunny.ply", "dragon_vrip_res2.ply", "dragon ×4"}) {
            bool subdivided = std::string(name) == "dragon ×4";
            auto mesh = loadMesh(subdivided ? "dragon_vrip_res2.ply" : name);
            if (!mesh) return fail(mesh.error());
            Scene scene = meshOnPlaneScene(subdivided ? subdivide(*mesh) : *mesh, env, 0.3f);
            RenderSettings rs = renderSettings(640, 480, 4);
            benchProgress("triangles {}", name);
            auto m = measure(**ctx, scene, rs, spp, reps);
            if (!m) return fail(m.error());
            std::printf("| %s | %zu | %.3f s | %.1f | %s | %s |\n", name, m->triangles,
                        m->bvhSeconds, m->seconds * 1e3 / spp, millions(m->pathsPerSecond).c_str(),
                        millions(m->raysPerSecond).c_str());
            std::fflush(stdout);
        }
        std::printf("\n");
    }

    if (want("specialisation")) {
        auto bunny = bunnyScene(o.dataDir, env);
        if (!bunny) return fail(bunny.error());
        std::printf(
            "## Specialised against general pipeline: the Lambertian bunny scene, "
            "640×480, %u spp, max depth 8\n\n| pipeline | ms / spp | paths/s |\n"
            "|---|---|---|\n",
            spp);
        double times[2] = {};
        for (int general = 0; general < 2; ++general) {
            RenderSettings rs = renderSettings(640, 480, 8);
            benchProgress("{} pipeline", general ? "general" : "specialised");
            auto m = measure(**ctx, *bunny, rs, spp, reps, {.generalPipeline = general == 1});
            if (!m) return fail(m.error());
            times[general] = m->seconds;
            std::printf(
                "| %s | %.1f | %s |\n",
                general ? "general (every feature compiled in)" : "specialised (environment only)",
                m->seconds * 1e3 / spp, millions(m->pathsPerSecond).c_str());
        }
        std::printf("\nGeneral / specialised time: %.2f×\n\n", times[1] / times[0]);
    }
    if (want("differential")) {
        std::printf(
            "## Differential pass against a plain path trace of the mixed scene: "
            "640×480, %u spp, max depth 8. Rays: closest-hit and shadow rays traced, "
            "a measure of work that the machine's load does not change.\n\n"
            "| scene | plain ms / spp | differential ms / spp | time ratio | rays ratio |\n"
            "|---|---|---|---|---|\n",
            spp);
        auto bunny = bunnyScene(o.dataDir, env);
        if (!bunny) return fail(bunny.error());
        // Bunny box: the floor is the real set, the bunny virtual.
        Scene bunnyBox = *bunny;
        for (size_t t = 0; t < 2; ++t) bunnyBox.geometry.triangleIsReal[t] = 1;
        auto cubes = loadGltf(o.examplesDir + "/cubes_spheres/scene.gltf");
        if (!cubes) return fail(cubes.error());
        std::pair<const char*, const Scene*> list[] = {
            {"bunny on a real floor", &bunnyBox},
            {"cubes (real) and spheres (virtual)", &cubes.value()}};
        for (auto [name, scene] : list) {
            double t[2] = {}, rays[2] = {};
            for (int differential = 0; differential < 2; ++differential) {
                RenderSettings rs = renderSettings(640, 480, 8);
                rs.differential = differential == 1;
                benchProgress("{} {}", name, differential ? "differential" : "plain");
                auto m = measure(**ctx, *scene, rs, spp, reps);
                if (!m) return fail(m.error());
                t[differential] = m->seconds;
                rays[differential] = m->raysPerSecond * m->seconds;
            }
            std::printf("| %s | %.1f | %.1f | %.2f× | %.2f× |\n", name, t[0] * 1e3 / spp,
                        t[1] * 1e3 / spp, t[1] / t[0], rays[1] / rays[0]);
            std::fflush(stdout);
        }
        std::printf("\n");
    }
    if (want("pose")) {
        if (int rc = runPoseSweep(**ctx, {.quick = o.quick}); rc != 0) return rc;
    }
    if (o.only == "reach") {
        if (int rc = runReachSweep(**ctx, o.quick); rc != 0) return rc;
    }
    if (o.only == "filter") {
        if (int rc = runPoseFilterBench(**ctx, o.dataDir, o.examplesDir, o.quick); rc != 0)
            return rc;
    }
    std::printf("Peak resident memory of the whole run: %.0f MiB\n", peakRssMiB());
    return 0;
}

}  // namespace previs::bench
