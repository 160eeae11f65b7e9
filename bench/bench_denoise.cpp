#include "bench/bench_denoise.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/bench_scenes.h"
#include "bench/image_compare.h"
#include "render/renderer.h"

namespace previs::bench {

namespace {

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double mean(const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return s / double(v.size());
}

// A grey plate of radiance 0.5: the composite's plate term is then the same in every image, and
// the errors are those of the rendered signal the composite adds to it.
ImageF greyPlate(uint32_t w, uint32_t h) {
    ImageF p;
    p.width = w;
    p.height = h;
    p.channels = 3;
    p.pixels.assign(size_t(w) * h * 3, 0.5f);
    return p;
}

Result<std::unique_ptr<Renderer>> makeRenderer(GpuContext& ctx, const Scene& scene, uint32_t w,
                                               uint32_t h) {
    RenderSettings rs;
    rs.width = w;
    rs.height = h;
    rs.maxDepth = 8;
    rs.differential = true;
    rs.denoise = true;
    auto r = Renderer::create(ctx, scene, rs);
    if (!r) return r;
    if (Status s = (*r)->setPlate(greyPlate(w, h), "grey plate"); !s) return s.error();
    return r;
}

// Wall and GPU time of one denoised image() beyond the undenoised one (readback included).
struct DenoiseTime {
    double wallMs = 0.0;
    double gpuMs = 0.0;
};

Result<DenoiseTime> timeDenoise(Renderer& r, int reps) {
    std::vector<double> wall, gpu;
    using Clock = std::chrono::steady_clock;
    auto ms = [](Clock::time_point t) {
        return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
    };
    for (int i = 0; i < reps; ++i) {
        auto t0 = Clock::now();
        auto plain = r.image(Aov::Composite);
        const double plainMs = ms(t0);
        if (!plain) return plain.error();
        auto t1 = Clock::now();
        auto den = r.image(Aov::Composite, true);
        const double denMs = ms(t1);
        if (!den) return den.error();
        wall.push_back(denMs - plainMs);
        gpu.push_back(r.denoiseMilliseconds());
    }
    return DenoiseTime{median(wall), median(gpu)};
}

}  // namespace

int runDenoiseBench(GpuContext& ctx, const DenoiseBenchOptions& o) {
    auto fail = [](const Error& e) {
        logError("{}", e.message);
        return 1;
    };
    const std::string env = o.dataDir + "/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr";
    auto bunny = bunnyScene(o.dataDir, env);
    if (!bunny) return fail(bunny.error());
    // As the differential section: the floor is the real set, the bunny virtual.
    Scene scene = std::move(bunny.value());
    for (size_t t = 0; t < 2; ++t) scene.geometry.triangleIsReal[t] = 1;
    const int reps = o.quick ? 1 : o.repetitions;

    // Time at 640×480 (the filter's cost does not depend on the samples).
    {
        benchProgress("denoise time 640x480");
        auto r = makeRenderer(ctx, scene, 640, 480);
        if (!r) return fail(r.error());
        if (Status s = (*r)->render(1); !s) return fail(s.error());
        auto t = timeDenoise(**r, std::max(reps, 3));
        if (!t) return fail(t.error());
        std::printf(
            "## Denoiser (issue 10): bunny on a real floor, differential, environment light, "
            "max depth 8\n\nDenoise time at 640×480 (5 à-trous iterations, medians of %d): "
            "**%.1f ms GPU** (the filter's dispatches), %.1f ms wall (with the guides' and "
            "accumulation's readback and upload beyond an undenoised image()).\n\n",
            std::max(reps, 3), t->gpuMs, t->wallMs);
        std::fflush(stdout);
    }

    // Error curves at a lower resolution: the reference must be long.
    const uint32_t w = o.quick ? 160 : 320, h = o.quick ? 120 : 240;
    const uint32_t refSpp = o.quick ? 64 : 1024;
    auto r = makeRenderer(ctx, scene, w, h);
    if (!r) return fail(r.error());
    Renderer& renderer = **r;
    benchProgress("denoise reference {}x{} {} spp", w, h, refSpp);
    renderer.setSeed(1000);
    if (Status s = renderer.render(refSpp); !s) return fail(s.error());
    auto reference = renderer.image(Aov::Composite);
    if (!reference) return fail(reference.error());
    auto refTime = timeDenoise(renderer, std::max(reps, 3));
    if (!refTime) return fail(refTime.error());

    const std::vector<uint32_t> checkpoints =
        o.quick ? std::vector<uint32_t>{1, 4} : std::vector<uint32_t>{1, 4, 16, 64};
    struct Row {
        std::vector<double> rmse[2], relMse[2];
    };
    std::vector<Row> rows(checkpoints.size());
    for (int seed = 0; seed < reps; ++seed) {
        if (Status s = renderer.reset(); !s) return fail(s.error());
        renderer.setSeed(uint32_t(seed));
        for (size_t k = 0; k < checkpoints.size(); ++k) {
            benchProgress("denoise {}x{} seed {} {} spp", w, h, seed, checkpoints[k]);
            if (Status s = renderer.render(checkpoints[k] - uint32_t(renderer.samplesPerPixel()));
                !s)
                return fail(s.error());
            for (int denoised = 0; denoised < 2; ++denoised) {
                auto img = renderer.image(Aov::Composite, denoised == 1);
                if (!img) return fail(img.error());
                auto d = compareImages(*img, *reference);
                if (!d) return fail(d.error());
                rows[k].rmse[denoised].push_back(d->rmse);
                rows[k].relMse[denoised].push_back(d->relMse);
            }
        }
    }
    std::printf(
        "Error of the composite (grey plate 0.5) at %u×%u against a %u-spp reference, mean "
        "of %d seed(s); denoise time at this size %.1f ms GPU, %.1f ms wall. \"RMSE drop per "
        "ms\" = (RMSE without − RMSE with) / the GPU ms of denoising.\n\n"
        "| spp | RMSE | RMSE denoised | RMSE ratio | relMSE | relMSE denoised | RMSE drop per ms "
        "|\n|---|---|---|---|---|---|---|\n",
        w, h, refSpp, reps, refTime->gpuMs, refTime->wallMs);
    for (size_t k = 0; k < checkpoints.size(); ++k) {
        const double before = mean(rows[k].rmse[0]), after = mean(rows[k].rmse[1]);
        std::printf("| %u | %.5f | %.5f | %.2f× | %.5f | %.5f | %.2e |\n", checkpoints[k], before,
                    after, before / after, mean(rows[k].relMse[0]), mean(rows[k].relMse[1]),
                    (before - after) / std::max(refTime->gpuMs, 1e-9));
        std::fflush(stdout);
    }
    std::printf("\n");
    return 0;
}

}  // namespace previs::bench
