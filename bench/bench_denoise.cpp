#include "bench/bench_denoise.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <glm/gtc/matrix_transform.hpp>
#include <vector>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/bench_scenes.h"
#include "bench/bench_stats.h"
#include "image/image_compare.h"
#include "render/renderer.h"

namespace previs::bench {

namespace {

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
                                               uint32_t h, uint32_t maxDepth = 8,
                                               bool meter = true) {
    RenderSettings rs;
    rs.width = w;
    rs.height = h;
    rs.maxDepth = maxDepth;
    rs.convergenceMeter = meter;
    rs.differential = true;
    rs.denoise = true;
    auto r = Renderer::create(ctx, scene, rs);
    if (!r) return r;
    if (Status s = (*r)->film().setPlate(greyPlate(w, h), "grey plate"); !s) return s.error();
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

// The kernels compared (DenoiseSettings::kernelRadius) and their labels.
struct Variant {
    const char* label;
    uint32_t kernelRadius;
    uint32_t iterations;
};
constexpr Variant kVariants[] = {{"5×5, 5 levels", 2, 5}, {"3×3, 5 levels", 1, 5}};

Status setVariant(Renderer& r, uint32_t kernelRadius, uint32_t iterations) {
    DenoiseSettings d = r.film().denoiser()->settings();
    d.kernelRadius = kernelRadius;
    d.iterations = iterations;
    return r.film().denoiser()->setSettings(d);
}

// Mean and half the spread of a 2-seed (or more) set: the ± the bench quotes.
std::string meanSpread(const std::vector<double>& v) {
    const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
    return fmt::format("{:.5f} ± {:.5f}", mean(v), 0.5 * (*hi - *lo));
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

    // Time per kernel at the dial's preview size (213×160: 640×480 at scale 1/3), 320×240 and
    // 640×480 (the filter's cost does not depend on the samples).
    const uint32_t sizes[][2] = {{213, 160}, {320, 240}, {640, 480}};
    std::printf(
        "## Denoiser (issue 10): bunny on a real floor, differential, environment light\n\n"
        "GPU ms of the filter's dispatches (medians of %d; wall adds the guides' and "
        "accumulation's readback and upload):\n\n| kernel | 213×160 | 320×240 | 640×480 |\n"
        "|---|---|---|---|\n",
        std::max(reps, 3));
    std::vector<std::string> cells[std::size(kVariants)];
    for (const auto& size : sizes) {
        benchProgress("denoise time {}x{}", size[0], size[1]);
        auto r = makeRenderer(ctx, scene, size[0], size[1]);
        if (!r) return fail(r.error());
        if (Status s = (*r)->render(1); !s) return fail(s.error());
        for (size_t v = 0; v < std::size(kVariants); ++v) {
            if (Status s = setVariant(**r, kVariants[v].kernelRadius, kVariants[v].iterations); !s)
                return fail(s.error());
            auto t = timeDenoise(**r, std::max(reps, 3));
            if (!t) return fail(t.error());
            cells[v].push_back(fmt::format("{:.1f} ({:.1f} wall)", t->gpuMs, t->wallMs));
        }
    }
    for (size_t v = 0; v < std::size(kVariants); ++v)
        std::printf("| %s | %s | %s | %s |\n", kVariants[v].label, cells[v][0].c_str(),
                    cells[v][1].c_str(), cells[v][2].c_str());
    std::printf("\n");
    std::fflush(stdout);

    // Strength (DenoiseSettings::iterations, the dial's knob) at the dial's preview point:
    // 213×160, 4 spp, max depth 4, one sequence (no meter), as preview frames are traced.
    {
        const uint32_t pw = 213, ph = 160, depth = 4, spp = 4;
        const uint32_t refSpp = o.quick ? 64 : 1024;
        auto r = makeRenderer(ctx, scene, pw, ph, depth, false);
        if (!r) return fail(r.error());
        Renderer& renderer = **r;
        benchProgress("denoise strength reference {}x{} {} spp", pw, ph, refSpp);
        renderer.setSeed(1000);
        if (Status s = renderer.render(refSpp); !s) return fail(s.error());
        auto reference = renderer.image(Aov::Composite);
        if (!reference) return fail(reference.error());
        struct Cell {
            std::vector<double> rmse, ms;
        };
        std::vector<Cell> cellsK1(6), cellsK2(6);
        for (int seed = 0; seed < reps; ++seed) {
            benchProgress("denoise strength seed {}", seed);
            if (Status s = renderer.reset(); !s) return fail(s.error());
            renderer.setSeed(uint32_t(seed));
            if (Status s = renderer.render(spp); !s) return fail(s.error());
            for (uint32_t radius : {2u, 1u}) {
                auto& cellsK = radius == 2 ? cellsK2 : cellsK1;
                for (uint32_t it = 0; it <= 5; ++it) {
                    if (Status s = setVariant(renderer, radius, it); !s) return fail(s.error());
                    auto img = renderer.image(Aov::Composite, true);
                    if (!img) return fail(img.error());
                    auto d = compareImages(*img, *reference);
                    if (!d) return fail(d.error());
                    cellsK[it].rmse.push_back(d->rmse);
                    cellsK[it].ms.push_back(renderer.denoiseMilliseconds());
                }
            }
        }
        std::printf(
            "Strength at the dial's preview point (%u×%u, %u spp, max depth %u, one sequence): "
            "RMSE of the composite against a %u-spp reference (mean ± half the spread of %d "
            "seeds) and the filter's GPU ms (median), per à-trous iteration count (0 = off):\n\n"
            "| iterations | RMSE 5×5 | ms 5×5 | RMSE 3×3 | ms 3×3 |\n|---|---|---|---|---|\n",
            pw, ph, spp, depth, refSpp, reps);
        for (uint32_t it = 0; it <= 5; ++it)
            std::printf("| %u | %s | %.1f | %s | %.1f |\n", it,
                        meanSpread(cellsK2[it].rmse).c_str(), median(cellsK2[it].ms),
                        meanSpread(cellsK1[it].rmse).c_str(), median(cellsK1[it].ms));
        std::printf("\n");
        std::fflush(stdout);
    }

    // Error curves at a lower resolution: the reference must be long.
    const uint32_t w = o.quick ? 160 : 320, h = o.quick ? 120 : 240;
    const uint32_t refSpp = o.quick ? 64 : 1024;
    {
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
        // [0] undenoised, [1 + v] kVariants[v].
        constexpr size_t kColumns = 1 + std::size(kVariants);
        struct Row {
            std::vector<double> rmse[kColumns], relMse[kColumns];
        };
        std::vector<Row> rows(checkpoints.size());
        for (int seed = 0; seed < reps; ++seed) {
            if (Status s = renderer.reset(); !s) return fail(s.error());
            renderer.setSeed(uint32_t(seed));
            for (size_t k = 0; k < checkpoints.size(); ++k) {
                benchProgress("denoise {}x{} seed {} {} spp", w, h, seed, checkpoints[k]);
                if (Status s =
                        renderer.render(checkpoints[k] - uint32_t(renderer.samplesPerPixel()));
                    !s)
                    return fail(s.error());
                for (size_t c = 0; c < kColumns; ++c) {
                    if (c > 0) {
                        const Variant& v = kVariants[c - 1];
                        if (Status s = setVariant(renderer, v.kernelRadius, v.iterations); !s)
                            return fail(s.error());
                    }
                    auto img = renderer.image(Aov::Composite, c > 0);
                    if (!img) return fail(img.error());
                    auto d = compareImages(*img, *reference);
                    if (!d) return fail(d.error());
                    rows[k].rmse[c].push_back(d->rmse);
                    rows[k].relMse[c].push_back(d->relMse);
                }
            }
        }
        std::printf(
            "Error of the composite (grey plate 0.5) at %u×%u, max depth 8, against a %u-spp "
            "reference, mean ± half the spread of %d seed(s); the 5×5 filter's time at this size "
            "%.1f ms GPU. \"RMSE drop per ms\" = (RMSE without − RMSE with) / the GPU ms.\n\n"
            "| spp | RMSE | RMSE 5×5 | RMSE 3×3 | ratio 5×5 | ratio 3×3 | relMSE | relMSE 5×5 | "
            "relMSE 3×3 | RMSE drop per ms (5×5) |\n|---|---|---|---|---|---|---|---|---|---|\n",
            w, h, refSpp, reps, refTime->gpuMs);
        for (size_t k = 0; k < checkpoints.size(); ++k) {
            const Row& row = rows[k];
            const double before = mean(row.rmse[0]);
            std::printf("| %u | %s | %s | %s | %.2f× | %.2f× | %.5f | %.5f | %.5f | %.2e |\n",
                        checkpoints[k], meanSpread(row.rmse[0]).c_str(),
                        meanSpread(row.rmse[1]).c_str(), meanSpread(row.rmse[2]).c_str(),
                        before / mean(row.rmse[1]), before / mean(row.rmse[2]), mean(row.relMse[0]),
                        mean(row.relMse[1]), mean(row.relMse[2]),
                        (before - mean(row.rmse[1])) / std::max(refTime->gpuMs, 1e-9));
            std::fflush(stdout);
        }
        std::printf("\n");
    }

    // Temporal reprojection in preview: a pan (the camera turning 0.5° a frame about its own
    // vertical axis) at the dial's point, every frame traced afresh with the same sequence, each
    // compared with its own long reference.
    {
        const uint32_t pw = 213, ph = 160, depth = 4, spp = 4;
        const int frames = o.quick ? 4 : 16;
        const uint32_t panRefSpp = o.quick ? 32 : 256;
        constexpr float kDegreesPerFrame = 0.5f;
        auto pr = makeRenderer(ctx, scene, pw, ph, depth, false);
        if (!pr) return fail(pr.error());
        auto rr = makeRenderer(ctx, scene, pw, ph, depth, false);
        if (!rr) return fail(rr.error());
        Renderer& preview = **pr;
        Renderer& refRenderer = **rr;
        if (Status s = setVariant(preview, 2, 5); !s) return fail(s.error());
        const glm::dmat4 start = preview.denoiseCamera().worldFromCamera;
        std::vector<double> rmse[3], ms[2];
        for (int f = 0; f < frames; ++f) {
            benchProgress("denoise pan frame {} of {}", f + 1, frames);
            const glm::dmat4 pose = glm::rotate(start, glm::radians(double(kDegreesPerFrame) * f),
                                                glm::dvec3(0.0, 1.0, 0.0));
            refRenderer.setCameraPose(pose);
            if (Status s = refRenderer.reset(); !s) return fail(s.error());
            refRenderer.setSeed(5000 + uint32_t(f));
            if (Status s = refRenderer.render(panRefSpp); !s) return fail(s.error());
            auto reference = refRenderer.image(Aov::Composite);
            if (!reference) return fail(reference.error());
            preview.setCameraPose(pose);
            if (Status s = preview.reset(); !s) return fail(s.error());
            if (Status s = preview.render(spp); !s) return fail(s.error());
            for (int mode = 0; mode < 3; ++mode) {
                // 0: none, 1: spatial only, 2: temporal + spatial.
                preview.film().setTemporalDenoise(mode == 2);
                auto img = preview.image(Aov::Composite, mode > 0);
                if (!img) return fail(img.error());
                auto d = compareImages(*img, *reference);
                if (!d) return fail(d.error());
                rmse[mode].push_back(d->rmse);
                if (mode > 0) ms[mode - 1].push_back(preview.denoiseMilliseconds());
            }
        }
        std::printf(
            "Temporal reprojection: a pan of %d frames turning %.1f° a frame, %u×%u, %u spp "
            "(one sequence, the same every frame), max depth %u, 5×5 × 5 levels; RMSE of each "
            "frame's composite against its own %u-spp reference. Filter GPU ms (median): "
            "spatial %.1f, temporal + spatial %.1f.\n\n| frame | none | spatial | temporal + "
            "spatial |\n|---|---|---|---|\n",
            frames, kDegreesPerFrame, pw, ph, spp, depth, panRefSpp, median(ms[0]), median(ms[1]));
        for (int f = 0; f < frames; ++f)
            std::printf("| %d | %.5f | %.5f | %.5f |\n", f + 1, rmse[0][f], rmse[1][f], rmse[2][f]);
        auto tail = [&](const std::vector<double>& v) {
            return mean(std::vector<double>(v.begin() + std::min<int>(frames - 1, 4), v.end()));
        };
        std::printf("| mean of frames 5.. | %.5f | %.5f | %.5f |\n\n", tail(rmse[0]), tail(rmse[1]),
                    tail(rmse[2]));
        std::fflush(stdout);
    }
    return 0;
}

}  // namespace previs::bench
