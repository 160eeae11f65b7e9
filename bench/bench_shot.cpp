#include "bench/bench_shot.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <variant>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/image_compare.h"
#include "daemon/pipeline_renderer.h"
#include "daemon/replay.h"
#include "daemon/service_config.h"
#include "image/image.h"
#include "render/renderer.h"

namespace previs::bench {

namespace {

using Clock = std::chrono::steady_clock;

// The demo take's timeline (bench/make_demo_session.cpp): a pan, frames 20–44 one still view
// under one lighting, another pan.
constexpr size_t kStillFirst = 20;
constexpr size_t kStillLast = 44;
// Flicker is measured over the hold's last frames, where every variant has settled.
constexpr size_t kFlickerFrames = 8;

struct ShotVariant {
    std::string name;
    ServiceConfig config;
};

struct FrameRow {
    size_t frame = 0;
    double sqrtRelMse = 0.0;  // of (composite − plate) against the reference's; NaN in the pan
    double ms = 0.0;          // lock step: tracking, lighting, render, composite
    ImageF added;             // composite − plate (kept for the hold's flicker)
};

// What the renderer adds to the plate: composite − plate (the plate cancels, noise and all).
Result<ImageF> addedToPlate(PipelineRenderer& renderer, ImageF composite) {
    const ImageF* plate = renderer.renderer().plate();
    if (!plate || plate->pixels.size() != composite.pixels.size())
        return makeError("bench shot: the composite and the plate differ in size");
    for (size_t i = 0; i < composite.pixels.size(); ++i) composite.pixels[i] -= plate->pixels[i];
    return composite;
}

// Frames of the pan with a reference of their own (the hold shares frame kStillFirst's).
constexpr size_t kPanFrames[] = {5, 10, 15, 19, 48, 52};

struct References {
    std::map<size_t, ImageF> added;  // frame → the reference's composite − plate
    const ImageF* at(size_t frame) const {
        if (frame >= kStillFirst && frame <= kStillLast) frame = kStillFirst;
        auto it = added.find(frame);
        return it == added.end() ? nullptr : &it->second;
    }
};

// The reference of `frame` at `spp` in `cacheDir` ("" = no cache), named by a hash of the
// config's text too: another config is another reference. A change to the renderer is not seen:
// empty the folder then (bench/bench_shot.h).
std::string cachedReferencePath(const std::string& cacheDir, const std::string& configText,
                                size_t frame, uint32_t spp) {
    if (cacheDir.empty()) return {};
    return fmt::format("{}/shot_reference_{:016x}_frame{}_{}spp.exr", cacheDir,
                       std::hash<std::string>{}(configText), frame, spp);
}

// The file's text ("" when unreadable: loadServiceConfig has read it already).
std::string configText(const std::string& path) {
    std::ifstream in(path);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

// Each reference frame refined without the denoiser: the hold's view to `spp`, the pan's to a
// quarter of it (their error is measured frame by frame, and only compared between variants).
// With a cache folder, a reference found there is read instead of rendered, and one rendered is
// written there.
Result<References> references(const ServiceConfig& shipped, const std::string& session,
                              uint32_t spp, size_t lastFrame, const std::string& cacheDir,
                              const std::string& configText) {
    ServiceConfig config = shipped;
    config.render.denoise = "off";
    config.render.previewFps = 0.0;
    auto opened = SessionReplay::open(session, config, Mode::Preview);
    if (auto* e = std::get_if<SessionReplay::OpenError>(&opened)) return e->error;
    SessionReplay& replay = *std::get<std::unique_ptr<SessionReplay>>(opened);
    References refs;
    for (size_t i = 0; i <= lastFrame; ++i) {
        Result<std::optional<SessionReplay::Step>> step = replay.next();
        if (!step) return step.error();
        if (!*step) break;
        const bool pan =
            std::find(std::begin(kPanFrames), std::end(kPanFrames), i) != std::end(kPanFrames);
        if (i != kStillFirst && !pan) continue;
        if (!(*step)->shot.shown) return makeError("bench shot: frame {} was not tracked", i);
        const uint32_t total = pan ? std::max<uint32_t>(1, spp / 4) : spp;
        const std::string cached = cachedReferencePath(cacheDir, configText, i, total);
        if (!cached.empty() && std::filesystem::exists(cached)) {
            Result<ImageF> image = readImage(cached);
            if (!image) return image.error();
            refs.added.emplace(i, std::move(*image));
            continue;
        }
        PipelineRenderer& r = replay.renderer();
        if (Status s = r.beginRefine(*(*step)->shot.shown, replay.lighting()); !s) return s.error();
        for (uint32_t done = 0; done < total;) {
            const uint32_t n = std::min<uint32_t>(64, total - done);
            if (Status s = r.refineStep(n); !s) return s.error();
            done += n;
            benchProgress("reference frame {}: {}/{} spp", i, done, total);
        }
        Result<ImageF> image = r.composite();
        if (!image) return image.error();
        Result<ImageF> added = addedToPlate(r, std::move(*image));
        if (!added) return added.error();
        if (!cached.empty())
            if (Status s = writeExr(cached, *added); !s) return s.error();
        refs.added.emplace(i, std::move(*added));
    }
    if (!refs.at(kStillFirst)) return makeError("bench shot: the demo take has no still view");
    return refs;
}

// `dialPoint`: what the dial chose on this machine, where the variant runs it.
Result<std::vector<FrameRow>> run(const ShotVariant& v, const std::string& session,
                                  const References& refs, size_t lastFrame,
                                  std::string& dialPoint) {
    auto opened = SessionReplay::open(session, v.config, Mode::Preview);
    if (auto* e = std::get_if<SessionReplay::OpenError>(&opened)) return e->error;
    SessionReplay& replay = *std::get<std::unique_ptr<SessionReplay>>(opened);
    const PipelineRenderer& r = replay.renderer();
    if (r.dialChoice()) dialPoint = r.dialMeasurements()[*r.dialChoice()].point.describe();
    std::vector<FrameRow> rows;
    for (size_t i = 0; i <= lastFrame; ++i) {
        const Clock::time_point t = Clock::now();
        Result<std::optional<SessionReplay::Step>> step = replay.next();
        if (!step) return step.error();
        if (!*step) break;
        Result<ImageF> image = replay.renderer().composite((*step)->shot.noiseEstimate);
        if (!image) return image.error();
        FrameRow row;
        row.frame = i;
        row.ms = std::chrono::duration<double, std::milli>(Clock::now() - t).count();
        Result<ImageF> added = addedToPlate(replay.renderer(), std::move(*image));
        if (!added) return added.error();
        row.sqrtRelMse = std::nan("");
        if (const ImageF* ref = refs.at(i)) {
            Result<ImageDifference> d = compareImages(*added, *ref);
            if (!d) return d.error();
            row.sqrtRelMse = std::sqrt(d->relMse);
        }
        if (i >= kStillFirst && i <= kStillLast) row.added = std::move(*added);
        benchProgress("{}: frame {}, {:.0f} ms", v.name, i, row.ms);
        rows.push_back(std::move(row));
    }
    return rows;
}

// RMS over pixels of the temporal standard deviation of the last frames' added signal, relative
// to the RMS of the reference's added signal.
double flicker(const std::vector<FrameRow>& rows, const ImageF& ref) {
    std::vector<const ImageF*> held;
    for (auto it = rows.rbegin(); it != rows.rend() && held.size() < kFlickerFrames; ++it)
        if (!it->added.pixels.empty()) held.push_back(&it->added);
    if (held.size() < 2) return std::nan("");
    double variance = 0.0, signal = 0.0;
    const size_t n = ref.pixels.size();
    for (size_t i = 0; i < n; ++i) {
        double mean = 0.0, sq = 0.0;
        for (const ImageF* f : held) mean += f->pixels[i];
        mean /= double(held.size());
        for (const ImageF* f : held) sq += (f->pixels[i] - mean) * (f->pixels[i] - mean);
        variance += sq / double(held.size() - 1);
        signal += double(ref.pixels[i]) * ref.pixels[i];
    }
    return signal > 0.0 ? std::sqrt(variance / signal) : std::nan("");
}

double upperMedian(std::vector<double> v) {
    if (v.empty()) return std::nan("");
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

}  // namespace

int runShotBench(const ShotBenchOptions& o) {
    const std::string session = o.examplesDir + "/demo/session";
    const std::string configPath = o.examplesDir + "/demo/previsd.toml";
    Result<ServiceConfig> shipped = loadServiceConfig(configPath);
    if (!shipped) {
        logError("{}", shipped.message());
        return 2;
    }
    std::vector<ShotVariant> variants;
    variants.push_back({"as shipped", *shipped});
    // The dial times this machine, so its point differs between runs on a loaded one: the same
    // preview at its usual point, fixed, is comparable from run to run.
    ShotVariant fixedPoint{"shipped, fixed at 1/3, 4 spp, depth 2, 2 levels", *shipped};
    fixedPoint.config.render.previewFps = 0.0;
    fixedPoint.config.render.resolutionScale = 1.0f / 3.0f;
    fixedPoint.config.render.samplesPerFrame = 4;
    fixedPoint.config.render.maxDepth = 2;
    fixedPoint.config.render.denoise = "on";
    fixedPoint.config.render.denoiseLevels = 2;
    variants.push_back(fixedPoint);
    ShotVariant noDial{"shipped, dial off", *shipped};
    noDial.config.render.previewFps = 0.0;
    variants.push_back(noDial);
    ShotVariant paper{"fixed sequence (the paper), no denoiser", *shipped};
    paper.config.render.previewFps = 0.0;
    paper.config.render.previewAccumulate = false;
    paper.config.render.denoise = "off";
    variants.push_back(paper);

    // A cache makes the deep reference free after the first run, quick or not.
    const uint32_t spp = o.quick && o.referenceCache.empty() ? 64 : o.referenceSpp;
    const size_t last = o.quick ? kStillFirst + 8 : kStillLast + 8;
    Result<References> refs =
        references(*shipped, session, spp, last, o.referenceCache, configText(configPath));
    if (!refs) {
        logError("{}", refs.message());
        return 1;
    }
    const ImageF& still = *refs->at(kStillFirst);
    std::ofstream csv;
    if (!o.csvPath.empty()) {
        csv.open(o.csvPath, std::ios::trunc);
        csv << "variant,frame,frames_held,sqrt_rel_mse,ms\n";
    }
    std::printf(
        "Demo take (examples/demo), %ux%u, as `previs replay --mode preview` steps it; reference: "
        "the still view (frame %zu) refined to %u spp without the denoiser. Error: DESIGN.md §4's "
        "√relMSE of composite − plate against the reference's; the pan's frames against their own "
        "references (a quarter of the samples). Flicker: temporal std of the last "
        "%zu held frames' composite − plate, RMS over pixels, over the reference's RMS.\n\n",
        still.width, still.height, kStillFirst, spp, kFlickerFrames);
    std::printf(
        "| preview | pan 5 | pan 10 | pan 15 | pan 19 | held 0 | held 1 | held 2 | held 4 | held 8 "
        "| held 16 | held 24 | pan 48 | pan 52 | flicker | ms/frame (median) |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    std::vector<std::string> dialPoints;
    for (const ShotVariant& v : variants) {
        std::string dialPoint;
        Result<std::vector<FrameRow>> rows = run(v, session, *refs, last, dialPoint);
        if (!dialPoint.empty()) dialPoints.push_back(v.name + ": " + dialPoint);
        if (!rows) {
            logError("{}", rows.message());
            return 1;
        }
        std::vector<double> ms;
        std::printf("| %s |", v.name.c_str());
        for (size_t i : {size_t(5), size_t(10), size_t(15), size_t(19), kStillFirst,
                         kStillFirst + 1, kStillFirst + 2, kStillFirst + 4, kStillFirst + 8,
                         kStillFirst + 16, kStillFirst + 24, size_t(48), size_t(52)}) {
            if (i < rows->size())
                std::printf(" %.3f |", (*rows)[i].sqrtRelMse);
            else
                std::printf(" – |");
        }
        for (const FrameRow& r : *rows) {
            if (r.frame > 0) ms.push_back(r.ms);  // frame 0 compiles the pipelines
            if (csv.is_open())
                csv << v.name << "," << r.frame << ","
                    << (r.frame >= kStillFirst ? long(r.frame - kStillFirst) : -1L) << ","
                    << r.sqrtRelMse << "," << r.ms << "\n";
        }
        std::printf(" %.3f | %.0f |\n", flicker(*rows, still), upperMedian(ms));
        std::fflush(stdout);
    }
    for (const std::string& d : dialPoints) std::printf("\nThe dial chose, %s.\n", d.c_str());
    return 0;
}

}  // namespace previs::bench
