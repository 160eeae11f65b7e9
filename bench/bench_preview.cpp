#include "bench/bench_preview.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <opencv2/core.hpp>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/bench_scenes.h"
#include "bench/bench_stats.h"
#include "display/compose.h"
#include "gpu/context.h"
#include "image/image_compare.h"
#include "render/renderer.h"
#include "render/tonemap.h"
#include "vision/inverse_tone_map.h"

namespace previs::bench {

namespace {

// One preview frame's stages, in the order the service's render thread runs them
// (shot/pipeline_renderer.cpp, daemon/service.cpp's publish) and the display's compose. The
// service's frame is the device's (kDisplay: composite and tone map on the device, one 8-bit
// readback); the host's float composite and tone map (kComposite, kToneMap: what `previs render`
// and the error columns use, and what the service ran before) are timed beside it, not in the
// total.
enum Stage {
    kPlate,
    kSetPlate,
    kRender,
    kDisplay,
    kComposite,
    kToneMap,
    kCompose,
    kTotal,
    kStageCount
};
constexpr const char* kStageNames[kStageCount] = {"plate_inverse_tonemap_ms",
                                                  "set_plate_ms",
                                                  "render_ms",
                                                  "display_ms",
                                                  "composite_ms",
                                                  "tonemap_ms",
                                                  "compose_ms",
                                                  "total_ms"};

struct ScaleRun {
    float scale = 1.0f;
    std::unique_ptr<Renderer> renderer;
    std::vector<double> ms[kStageCount];
    ImageF lastComposite;
};

// Error over the pixels where `mask` is set (all when empty).
struct Error {
    double rmse = 0.0, relMse = 0.0;
    size_t pixels = 0;
};

Error errorOver(const ImageF& a, const ImageF& ref, const std::vector<uint8_t>& mask) {
    Error e;
    double se = 0.0, rel = 0.0;
    size_t values = 0;
    for (size_t i = 0; i < size_t(ref.width) * ref.height; ++i) {
        if (!mask.empty() && !mask[i]) continue;
        ++e.pixels;
        for (int c = 0; c < 3; ++c) {
            const double d = double(a.pixels[i * 3 + c]) - ref.pixels[i * 3 + c];
            se += d * d;
            rel += d * d / (double(ref.pixels[i * 3 + c]) * ref.pixels[i * 3 + c] + 0.01);
            ++values;
        }
    }
    if (values > 0) {
        e.rmse = std::sqrt(se / double(values));
        e.relMse = rel / double(values);
    }
    return e;
}

std::string scaleName(float s) {
    const float inverse = 1.0f / s;
    if (std::abs(inverse - std::round(inverse)) < 1e-3f)
        return std::round(inverse) == 1.0f ? "1" : fmt::format("1/{:.0f}", inverse);
    return fmt::format("{:.3f}", s);
}

}  // namespace

int runPreviewBench(const PreviewBenchOptions& o) {
    const int rounds = o.quick ? 1 : o.rounds;
    const int framesPerRound = o.quick ? 3 : o.framesPerRound;
    const uint32_t referenceSpp = o.quick ? 16 : o.referenceSpp;
    constexpr uint32_t kWidth = 640, kHeight = 480;

    auto ctx = GpuContext::create({});
    if (!ctx) {
        logError("{}", ctx.message());
        return 1;
    }
    const std::string env = o.dataDir + "/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr";
    auto bunny = bunnyScene(o.dataDir, env);
    if (!bunny) {
        logError("{}", bunny.message());
        return 1;
    }
    // The floor (the first two triangles) is the real set, the bunny virtual.
    Scene scene = std::move(*bunny);
    for (size_t t = 0; t < 2; ++t) scene.geometry.triangleIsReal[t] = 1;

    RenderSettings base;
    base.width = kWidth;
    base.height = kHeight;
    base.maxDepth = o.maxDepth;
    base.differential = true;
    base.samplesPerDispatch = 64;  // as the service (the renderer lowers it on a CPU device)

    // The reference: full resolution, long. Its real-only solution, through an 8-bit sRGB camera,
    // is the plate every frame starts from (as a scene-camera frame would).
    benchProgress("reference: {}x{}, {} spp, max depth {}", kWidth, kHeight, referenceSpp,
                  o.maxDepth);
    auto reference = Renderer::create(**ctx, scene, base);
    if (!reference) {
        logError("{}", reference.message());
        return 1;
    }
    const Clock::time_point refStart = Clock::now();
    if (Status s = (*reference)->render(referenceSpp); !s) {
        logError("{}", s.message());
        return 1;
    }
    const double referenceSeconds = msSince(refStart) / 1e3;
    auto real = (*reference)->image(Aov::Real);
    if (!real) {
        logError("{}", real.message());
        return 1;
    }
    const ToneMapSettings camera;  // sRGB, exposure 0 (and its inverse below)
    const InverseToneMapSettings inverse;
    std::vector<uint8_t> frame8 = toneMapToSrgb8(*real, camera);
    const cv::Mat frame(int(kHeight), int(kWidth), CV_8UC3, frame8.data());
    auto plateOf = [&] {
        const cv::Mat linear = inverseToneMapRgb8(frame, inverse);
        ImageF plate;
        plate.width = kWidth;
        plate.height = kHeight;
        plate.channels = 3;
        plate.pixels.assign(linear.ptr<float>(0),
                            linear.ptr<float>(0) + size_t(kWidth) * kHeight * 3);
        return plate;
    };
    const ImageF plate = plateOf();
    if (Status s = (*reference)->film().setPlate(plate, "bench plate"); !s) {
        logError("{}", s.message());
        return 1;
    }
    auto refComposite = (*reference)->image(Aov::Composite);
    if (!refComposite) {
        logError("{}", refComposite.message());
        return 1;
    }
    // The pixels the virtual bunny changes (shadow, reflections, the bunny itself).
    std::vector<uint8_t> affected(size_t(kWidth) * kHeight, 0);
    size_t affectedCount = 0;
    for (size_t i = 0; i < affected.size(); ++i) {
        for (int c = 0; c < 3; ++c)
            if (refComposite->pixels[i * 3 + c] != plate.pixels[i * 3 + c]) affected[i] = 1;
        affectedCount += affected[i];
    }

    std::vector<ScaleRun> runs;
    for (float s : o.scales) {
        RenderSettings rs = base;
        rs.resolutionScale = s;
        benchProgress("scale {}: pipeline and warm-up frame", scaleName(s));
        auto r = Renderer::create(**ctx, scene, rs);
        if (!r) {
            logError("{}", r.message());
            return 1;
        }
        if (Status st = (*r)->film().setPlate(plate, "bench plate"); !st) {
            logError("{}", st.message());
            return 1;
        }
        if (Status st = (*r)->renderPreviewFrame(1); !st) {
            logError("{}", st.message());
            return 1;
        }
        runs.push_back({s, std::move(*r), {}, {}});
    }

    std::vector<uint32_t> screen(1920 * 1080);
    for (int round = 0; round < rounds; ++round)
        for (ScaleRun& run : runs) {
            benchProgress("round {}/{}: scale {}", round + 1, rounds, scaleName(run.scale));
            for (int f = 0; f < framesPerRound; ++f) {
                const Clock::time_point start = Clock::now();
                Clock::time_point t = start;
                ImageF p = plateOf();
                run.ms[kPlate].push_back(msSince(t));
                t = Clock::now();
                if (Status s = run.renderer->film().setPlate(std::move(p), "bench plate"); !s) {
                    logError("{}", s.message());
                    return 1;
                }
                run.ms[kSetPlate].push_back(msSince(t));
                t = Clock::now();
                if (Status s = run.renderer->renderPreviewFrame(1); !s) {
                    logError("{}", s.message());
                    return 1;
                }
                run.ms[kRender].push_back(msSince(t));
                const double untilRendered = msSince(start);
                t = Clock::now();
                Result<DisplayImage> shown = run.renderer->display(false, {camera, {1, 1, 1}});
                if (!shown) {
                    logError("{}", shown.message());
                    return 1;
                }
                run.ms[kDisplay].push_back(msSince(t));
                t = Clock::now();
                auto composite = run.renderer->image(Aov::Composite);
                if (!composite) {
                    logError("{}", composite.message());
                    return 1;
                }
                run.ms[kComposite].push_back(msSince(t));
                t = Clock::now();
                DisplayFrame out;
                out.width = kWidth;
                out.height = kHeight;
                out.rgb = toneMapToSrgb8(*composite, camera);
                run.ms[kToneMap].push_back(msSince(t));
                t = Clock::now();
                out.rgb = std::move(shown->rgb);
                out.status = "PREVIEW 1 spp";
                composeFrame(out, 1920, 1080, screen.data(), 1920 * 4);
                run.ms[kCompose].push_back(msSince(t));
                run.ms[kTotal].push_back(untilRendered + run.ms[kDisplay].back() +
                                         run.ms[kCompose].back());
                run.lastComposite = std::move(*composite);
            }
        }

    // The per-pixel tone map as it was before the threshold table (render/tonemap.cpp).
    std::vector<double> perPixelToneMap;
    for (int k = 0; k < 5; ++k) {
        const Clock::time_point t = Clock::now();
        std::vector<uint8_t> out(size_t(kWidth) * kHeight * 3);
        for (size_t i = 0; i < size_t(kWidth) * kHeight; ++i) {
            const std::array<float, 3> e =
                toneMapRgb({refComposite->pixels[i * 3], refComposite->pixels[i * 3 + 1],
                            refComposite->pixels[i * 3 + 2]},
                           camera);
            for (int c = 0; c < 3; ++c) out[i * 3 + c] = uint8_t(std::lround(e[c] * 255.0f));
        }
        perPixelToneMap.push_back(msSince(t));
    }

    std::printf(
        "## Preview speed and the error of the resolution scale: bunny on a real floor, "
        "environment map, %u×%u output, 1 spp, max depth %u\n\n"
        "Device: %s. Lock step, one frame after another (ms, median of %d frames per scale: "
        "%d round(s) of %d, scales alternating). Error against a %u-spp full-resolution "
        "reference (%.0f s); \"affected\" = the %zu pixels (%.0f %%) where the reference "
        "composite differs from the plate.\n\n"
        "| scale | traced | plate inverse tone map | setPlate | render 1 spp | display on the "
        "device (upsample, composite, tone map, 8-bit readback) | host: readback + upsample + "
        "composite | host: tone map | compose 1920×1080 | total | fps | RMSE | relMSE "
        "| RMSE affected | relMSE affected |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        kWidth, kHeight, o.maxDepth, (*ctx)->deviceName().c_str(), rounds * framesPerRound, rounds,
        framesPerRound, referenceSpp, referenceSeconds, affectedCount,
        100.0 * double(affectedCount) / double(affected.size()));
    std::ofstream csv;
    if (!o.csvPath.empty()) {
        csv.open(o.csvPath, std::ios::trunc);
        csv << "scale,metric,value\n";
    }
    for (const ScaleRun& run : runs) {
        double m[kStageCount];
        for (int k = 0; k < kStageCount; ++k) m[k] = median(run.ms[k]);
        const Error all = errorOver(run.lastComposite, *refComposite, {});
        const Error part = errorOver(run.lastComposite, *refComposite, affected);
        std::printf(
            "| %s | %u×%u | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.4f | "
            "%.4f | %.4f | %.4f |\n",
            scaleName(run.scale).c_str(), run.renderer->traceWidth(), run.renderer->traceHeight(),
            m[kPlate], m[kSetPlate], m[kRender], m[kDisplay], m[kComposite], m[kToneMap],
            m[kCompose], m[kTotal], 1000.0 / m[kTotal], all.rmse, all.relMse, part.rmse,
            part.relMse);
        if (csv.is_open()) {
            for (int k = 0; k < kStageCount; ++k)
                csv << run.scale << "," << kStageNames[k] << "," << m[k] << "\n";
            csv << run.scale << ",fps," << 1000.0 / m[kTotal] << "\n";
            csv << run.scale << ",rmse," << all.rmse << "\n";
            csv << run.scale << ",relmse," << all.relMse << "\n";
            csv << run.scale << ",rmse_affected," << part.rmse << "\n";
            csv << run.scale << ",relmse_affected," << part.relMse << "\n";
        }
    }
    std::printf(
        "\nTone map of the same 640×480 composite, per pixel through toneMapRgb (the "
        "code before the threshold table): %.1f ms (median of 5).\n\n",
        median(perPixelToneMap));
    if (csv.is_open() && !csv) {
        logError("--csv {}: cannot write the file", o.csvPath);
        return 1;
    }
    return 0;
}

}  // namespace previs::bench
