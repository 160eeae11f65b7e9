#include "bench/bench_shot.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <map>
#include <variant>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "config/service_config.h"
#include "image/image.h"
#include "image/image_compare.h"
#include "render/renderer.h"
#include "shot/pipeline_renderer.h"
#include "take/replay.h"

namespace previs::bench {

namespace {

using Clock = std::chrono::steady_clock;

// The demo take's timeline (bench/make_demo_session.cpp): a pan, frames 20–44 one still view
// under one lighting, another pan.
constexpr size_t kStillFirst = 20;
constexpr size_t kStillLast = 44;
// Flicker is measured over the hold's last frames, where every variant has settled.
constexpr size_t kFlickerFrames = 8;
// The longest hold measured (the "after 64 still frames"): past the take's 25 frames.
constexpr size_t kLongHold = 64;

struct ShotVariant {
    std::string name;
    ServiceConfig config;
};

struct FrameRow {
    size_t frame = 0;
    double sqrtRelMse = 0.0;  // of (composite − plate) against the reference's; NaN in the pan
    double sqrtRelMseTrimmed = 0.0;  // the same, its worst thousandth of pixels left out
    // Against the truth, the references' own noise taken out (image/image_compare.h's
    // compareWithPairedReference with the frame's twin reference), whole and trimmed.
    double sqrtNetRelMse = 0.0;
    double sqrtNetRelMseTrimmed = 0.0;
    double ms = 0.0;         // lock step: tracking, lighting, render, composite
    ImageF added;            // composite − plate (kept for the hold's flicker)
    bool extraHold = false;  // beyond the take's hold (holdLonger): frame is kStillFirst + held
};

// What the renderer adds to the plate: composite − plate (the plate cancels, noise and all).
Result<ImageF> addedToPlate(PipelineRenderer& renderer, ImageF composite) {
    const ImageF* plate = renderer.plate();
    if (!plate || plate->pixels.size() != composite.pixels.size())
        return makeError("bench shot: the composite and the plate differ in size");
    for (size_t i = 0; i < composite.pixels.size(); ++i) composite.pixels[i] -= plate->pixels[i];
    return composite;
}

// Frames of the pan with a reference of their own. The hold's frames share one of two: the map
// turns until frame 19 and the fisheye's bracket lands a few frames after it is taken, so the
// hold's first frames are lit by a bracket of the pan (frame kStillFirst's reference), the rest
// by brackets of the still room (frame kStillLast's: what the crew holding on it would refine).
// Those brackets all see the same room; what their capture noise changes counts as the
// preview's error.
constexpr size_t kPanFrames[] = {5, 10, 15, 19, 48, 52};

struct References {
    std::map<size_t, ImageF> added;  // frame → the reference's composite − plate
    // The same frames again with another random sequence: the references' own noise, which
    // the net error takes out (and what refinement at the reference's samples scores against
    // it, on the metric's terms).
    std::map<size_t, ImageF> twins;
    uint64_t firstStillLighting = 0;  // the lighting snapshot frame kStillFirst is rendered with
    // The reference (or its twin) of `frame`, rendered with the lighting snapshot `lighting`.
    const ImageF* at(size_t frame, uint64_t lighting, bool twin = false) const {
        if (frame >= kStillFirst && frame <= kStillLast)
            frame = lighting == firstStillLighting ? kStillFirst : kStillLast;
        const auto& images = twin ? twins : added;
        auto it = images.find(frame);
        return it == images.end() ? nullptr : &it->second;
    }
};

// The sequence of the lighting snapshot `replay` renders with now (0: none).
uint64_t lightingSequence(const SessionReplay& replay) {
    return replay.lighting() ? replay.lighting()->sequence : 0;
}

// The twin reference's sequence: config.render.seed with these bits flipped (the references
// before it refine on from the last preview frame's). Its cache file's name does not say it:
// empty the folder after changing it.
constexpr uint32_t kTwinSeed = 0x5bd1e995u;

// The reference of `frame` at `spp` in `cacheDir` ("" = no cache), named by a hash of the
// config's text too: another config is another reference. A change to the renderer is not seen:
// empty the folder then (bench/bench_shot.h).
std::string cachedReferencePath(const std::string& cacheDir, const std::string& configText,
                                size_t frame, uint32_t spp, bool twin = false) {
    if (cacheDir.empty()) return {};
    return fmt::format("{}/shot_reference_{:016x}_frame{}_{}spp{}.exr", cacheDir,
                       std::hash<std::string>{}(configText), frame, spp, twin ? "_twin" : "");
}

// Frame `shown` refined to `spp` (read from `cached` where it is there, written there after),
// what it adds to the plate.
Result<ImageF> reference(PipelineRenderer& r, const TrackedFrame& shown,
                         const std::shared_ptr<const LiveLighting>& lighting, uint32_t spp,
                         const std::string& cached) {
    if (!cached.empty() && std::filesystem::exists(cached)) return readImage(cached);
    if (Status s = r.beginRefine(shown, lighting); !s) return s.error();
    for (uint32_t done = 0; done < spp;) {
        const uint32_t n = std::min<uint32_t>(64, spp - done);
        if (Status s = r.refineStep(n); !s) return s.error();
        done += n;
        benchProgress("reference frame {}: {}/{} spp", shown.frame->sequence, done, spp);
    }
    Result<ImageF> image = r.composite();
    if (!image) return image.error();
    Result<ImageF> added = addedToPlate(r, std::move(*image));
    if (!added) return added.error();
    if (!cached.empty())
        if (Status s = writeExr(cached, *added); !s) return s.error();
    return added;
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
        if (i == kStillFirst) refs.firstStillLighting = lightingSequence(replay);
        if (i != kStillFirst && i != kStillLast && !pan) continue;
        if (!(*step)->shot.shown) return makeError("bench shot: frame {} was not tracked", i);
        const uint32_t total = pan ? std::max<uint32_t>(1, spp / 4) : spp;
        PipelineRenderer& r = replay.renderer();
        const TrackedFrame& shown = *(*step)->shot.shown;
        Result<ImageF> added = reference(r, shown, replay.lighting(), total,
                                         cachedReferencePath(cacheDir, configText, i, total));
        if (!added) return added.error();
        refs.added.emplace(i, std::move(*added));
        // The next preview frame sets its own seed (Renderer::previewFrameSeed).
        r.setSeed(config.render.seed ^ kTwinSeed);
        Result<ImageF> twin = reference(r, shown, replay.lighting(), total,
                                        cachedReferencePath(cacheDir, configText, i, total, true));
        if (!twin) return twin.error();
        refs.twins.emplace(i, std::move(*twin));
    }
    if (!refs.added.count(kStillFirst) || !refs.added.count(kStillLast))
        return makeError("bench shot: the demo take has no still view");
    return refs;
}

// The row's errors against the reference of `frame` and its twin (NaN without them).
Status measureRow(FrameRow& row, const ImageF& added, const References& refs, size_t frame,
                  uint64_t lighting) {
    row.sqrtRelMse = row.sqrtRelMseTrimmed = std::nan("");
    row.sqrtNetRelMse = row.sqrtNetRelMseTrimmed = std::nan("");
    const ImageF* ref = refs.at(frame, lighting);
    const ImageF* twin = refs.at(frame, lighting, true);
    if (!ref || !twin) return {};
    Result<ImageDifference> d = compareImages(added, *ref);
    if (!d) return d.error();
    row.sqrtRelMse = std::sqrt(d->relMse);
    row.sqrtRelMseTrimmed = std::sqrt(d->relMseTrimmed);
    Result<PairedDifference> net = compareWithPairedReference(added, *ref, *twin);
    if (!net) return net.error();
    row.sqrtNetRelMse = std::sqrt(net->netRelMse);
    row.sqrtNetRelMseTrimmed = std::sqrt(net->netRelMseTrimmed);
    return {};
}

// The take holds its still view for kStillLast − kStillFirst + 1 frames; a crew may hold longer.
// The last still frame is previewed again until `holdTo` frames have held (the pose, plate and
// lighting of that frame: what a camera that stays put sends), each a row after it.
Status holdLonger(SessionReplay& replay, const TrackedFrame& still, const References& refs,
                  size_t holdTo, std::vector<FrameRow>& rows) {
    PipelineRenderer& r = replay.renderer();
    for (size_t held = kStillLast - kStillFirst + 1; held <= holdTo; ++held) {
        const Clock::time_point t = Clock::now();
        if (Status s = r.renderPreview(still, replay.lighting()); !s) return s;
        Result<ImageF> image = r.composite();
        if (!image) return image.error();
        FrameRow row;
        row.frame = kStillFirst + held;
        row.ms = std::chrono::duration<double, std::milli>(Clock::now() - t).count();
        Result<ImageF> added = addedToPlate(r, std::move(*image));
        if (!added) return added.error();
        if (Status s = measureRow(row, *added, refs, kStillLast, lightingSequence(replay)); !s)
            return s;
        row.extraHold = true;
        if (held == holdTo) row.added = std::move(*added);  // for printErrorBreakdown
        benchProgress("held {}: {:.0f} ms", held, row.ms);
        rows.push_back(std::move(row));
    }
    return {};
}

// `dialPoint`: what the dial chose on this machine, where the variant runs it. `holdTo` > 0
// extends the hold (holdLonger).
Result<std::vector<FrameRow>> run(const ShotVariant& v, const std::string& session,
                                  const References& refs, size_t lastFrame, size_t holdTo,
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
        if (Status s = measureRow(row, *added, refs, i, lightingSequence(replay)); !s)
            return s.error();
        if (i >= kStillFirst && i <= kStillLast) row.added = std::move(*added);
        benchProgress("{}: frame {}, {:.0f} ms", v.name, i, row.ms);
        rows.push_back(std::move(row));
        if (i == kStillLast && holdTo > 0)
            if (Status s = holdLonger(replay, *(*step)->shot.shown, refs, holdTo, rows); !s)
                return s.error();
    }
    return rows;
}

// RMS over pixels of the temporal standard deviation of the last frames' added signal, relative
// to the RMS of the reference's added signal.
double flicker(const std::vector<FrameRow>& rows, const ImageF& ref) {
    std::vector<const ImageF*> held;
    for (auto it = rows.rbegin(); it != rows.rend() && held.size() < kFlickerFrames; ++it)
        if (!it->extraHold && !it->added.pixels.empty()) held.push_back(&it->added);
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

// Where a held frame's error lies: its pixels by what the references add to the plate around
// them (their 5×5 mean), each class's share of the pixels and of the error against the truth
// (compareWithPairedReference's terms: the references' noise taken out), and the frame's mean
// over the references' there (below 1: too dark, e.g. light clamped away).
Status printErrorBreakdown(const std::string& name, const ImageF& added, const ImageF& ref,
                           const ImageF& twin) {
    Result<std::vector<PairedPixel>> errors = pairedPixelErrors(added, ref, twin);
    if (!errors) return errors.error();
    struct Class {
        const char* label;
        double below;  // the references' local mean under this
        double pixels = 0.0, error = 0.0, frame = 0.0, truth = 0.0;
    };
    std::array<Class, 5> classes{{{"darkens it (below −0.01)", -0.01},
                                  {"about nothing (±0.01)", 0.01},
                                  {"adds 0.01–0.1", 0.1},
                                  {"adds 0.1–1", 1.0},
                                  {"adds over 1", std::numeric_limits<double>::infinity()}}};
    double total = 0.0;
    for (size_t i = 0; i < errors->size(); ++i) {
        const PairedPixel& p = (*errors)[i];
        Class& c = *std::find_if(classes.begin(), classes.end(),
                                 [&](const Class& k) { return p.localMean < k.below; });
        c.pixels += 1.0;
        c.error += p.error;
        total += p.error;
        for (uint32_t k = 0; k < ref.channels; ++k) {
            const size_t v = i * ref.channels + k;
            c.frame += added.pixels[v];
            c.truth += 0.5 * (double(ref.pixels[v]) + double(twin.pixels[v]));
        }
    }
    std::printf(
        "\nWhere %s's held %zu error lies, by what the references add to the plate "
        "around a pixel:\n\n| pixels where the references | share of pixels | share of "
        "the error | frame / references |\n|---|---|---|---|\n",
        name.c_str(), kLongHold);
    for (const Class& c : classes)
        std::printf("| %s | %.1f %% | %.1f %% | %.2f |\n", c.label,
                    100.0 * c.pixels / double(errors->size()),
                    total > 0.0 ? 100.0 * c.error / total : 0.0,
                    c.truth != 0.0 ? c.frame / c.truth : std::nan(""));
    return {};
}

double upperMedian(std::vector<double> v) {
    if (v.empty()) return std::nan("");
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

struct VariantResult {
    std::string name;
    std::string dialPoint;  // what the dial chose on this machine, where the variant runs it
    std::vector<FrameRow> rows;
    double flicker = 0.0;
    double msMedian = 0.0;
};

// The row of the take's frame `frame` (the hold's frames past the take's: kStillFirst + held).
const FrameRow* rowOf(const std::vector<FrameRow>& rows, size_t frame, bool extraHold) {
    for (const FrameRow& r : rows)
        if (r.frame == frame && r.extraHold == extraHold) return &r;
    return nullptr;
}

// One markdown table of every variant: the rows' `error`, under `title`.
void printTable(const std::vector<VariantResult>& results, const char* title,
                double FrameRow::*error) {
    struct Column {
        const char* name;
        size_t frame;
        bool extraHold;
    };
    const Column columns[] = {{"pan 5", 5, false},
                              {"pan 10", 10, false},
                              {"pan 15", 15, false},
                              {"pan 19", 19, false},
                              {"held 0", kStillFirst, false},
                              {"held 1", kStillFirst + 1, false},
                              {"held 2", kStillFirst + 2, false},
                              {"held 4", kStillFirst + 4, false},
                              {"held 8", kStillFirst + 8, false},
                              {"held 16", kStillFirst + 16, false},
                              {"held 24", kStillFirst + 24, false},
                              {"held 64", kStillFirst + kLongHold, true},
                              {"pan 48", 48, false},
                              {"pan 52", 52, false}};
    std::printf("\n%s\n\n| preview |", title);
    for (const Column& c : columns) std::printf(" %s |", c.name);
    std::printf(" flicker | ms/frame (median) |\n|---|");
    for (size_t i = 0; i < std::size(columns) + 2; ++i) std::printf("---|");
    std::printf("\n");
    for (const VariantResult& v : results) {
        std::printf("| %s |", v.name.c_str());
        for (const Column& c : columns) {
            const FrameRow* r = rowOf(v.rows, c.frame, c.extraHold);
            if (r)
                std::printf(" %.3f |", r->*error);
            else
                std::printf(" – |");
        }
        std::printf(" %.3f | %.0f |\n", v.flicker, v.msMedian);
    }
    std::fflush(stdout);
}

// `base` with one change: a row of the ablation.
ShotVariant changed(std::string name, const ServiceConfig& base,
                    const std::function<void(ServiceConfig&)>& change) {
    ShotVariant v{std::move(name), base};
    change(v.config);
    return v;
}

// The rows: as shipped, the same preview at a fixed point, and that point with one part of the
// preview off or changed at a time.
std::vector<ShotVariant> shotVariants(const ServiceConfig& shipped) {
    // The dial times this machine, so its point differs between runs on a loaded one: the same
    // preview at its usual point, fixed, is comparable from run to run.
    const ShotVariant fixed =
        changed("shipped, fixed at 1/3, 4 spp, depth 2, 2 levels", shipped, [](ServiceConfig& c) {
            c.render.previewFps = 0.0;
            c.render.resolutionScale = 1.0f / 3.0f;
            c.liveRender.samplesPerFrame = 4;
            c.render.previewMaxDepth = 2;
            c.render.denoise = "on";
            c.render.denoiseLevels = 2;
        });
    // The lighting as estimated lights over a residual map ([lighting] mode = "lights"), where
    // one light sample picks a light uniformly.
    const ShotVariant lights =
        changed("fixed, estimated lights", fixed.config,
                [](ServiceConfig& c) { c.lighting.mode = LightingMode::Lights; });
    const ShotVariant noClamp =
        changed("fixed, samples not clamped", fixed.config,
                [](ServiceConfig& c) { c.render.previewSampleClamp = 0.0; });
    const auto noObjectSamples = [](ServiceConfig& c) { c.render.previewObjectSamples = 0.0; };
    const auto resampled = [](ServiceConfig& c) { c.render.previewResampling = true; };
    return {
        ShotVariant{"as shipped", shipped},
        fixed,
        changed("fixed, the hold at depth 2", fixed.config,
                [](ServiceConfig& c) { c.render.previewHoldDepth = false; }),
        changed("fixed, the held view not following the camera", fixed.config,
                [](ServiceConfig& c) { c.render.previewFollow = false; }),
        changed("fixed, held samples at random places (no phase schedule)", fixed.config,
                [](ServiceConfig& c) { c.render.previewPhases = false; }),
        changed("fixed, no test of the estimate's outline", fixed.config,
                [](ServiceConfig& c) { c.render.previewOutlineTest = false; }),
        changed("fixed, the distant light resampled (ReSTIR)", fixed.config, resampled),
        lights,
        changed("fixed, estimated lights, resampled", lights.config, resampled),
        noClamp,
        changed("fixed, no samples added at the objects", fixed.config, noObjectSamples),
        changed("fixed, neither", noClamp.config, noObjectSamples),
        // Before polished metal and the environment's lamps carried caustics by photons, the
        // demo ran none: the chrome ball's caustic of the softbox was the path tracer's.
        changed("fixed, photons off", fixed.config,
                [](ServiceConfig& c) { c.render.photons.mode = PhotonMode::Off; }),
        changed("shipped, dial off", shipped, [](ServiceConfig& c) { c.render.previewFps = 0.0; }),
        changed("fixed sequence (the paper), no denoiser", shipped,
                [](ServiceConfig& c) {
                    c.render.previewFps = 0.0;
                    c.render.previewAccumulate = false;
                    c.render.denoise = "off";
                }),
    };
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
    const std::vector<ShotVariant> variants = shotVariants(*shipped);

    // A cache makes the deep reference free after the first run, quick or not.
    const uint32_t spp = o.quick && o.referenceCache.empty() ? 64 : o.referenceSpp;
    // Quick: the hold and no more (the later pan's references are not rendered).
    const size_t last = o.quick ? kStillLast : kStillLast + 8;
    const size_t holdTo = kLongHold;
    Result<References> refs =
        references(*shipped, session, spp, last, o.referenceCache, configText(configPath));
    if (!refs) {
        logError("{}", refs.message());
        return 1;
    }
    const ImageF& still = refs->added.at(kStillLast);
    std::ofstream csv;
    if (!o.csvPath.empty()) {
        csv.open(o.csvPath, std::ios::trunc);
        csv << "variant,frame,frames_held,sqrt_rel_mse,sqrt_rel_mse_trimmed,sqrt_net_rel_mse,"
               "sqrt_net_rel_mse_trimmed,ms\n";
    }
    std::printf(
        "Demo take (examples/demo), %ux%u, as `previs replay --mode preview` steps it; reference: "
        "the still view refined to %u spp without the denoiser (frame %zu, lit by a bracket of the "
        "pan, for the hold's first frames; frame %zu, lit by the still room's, for the rest). "
        "Error: √relMSE of composite − plate against the truth, estimated with each reference "
        "and its twin (the same frame refined again with another random sequence) so that their "
        "own noise is not counted (image/image_compare.h, compareWithPairedReference), the %.1f %% "
        "of pixels where the two disagree most left out "
        "(the first table) and none (the second); then DESIGN.md §4's √relMSE against the "
        "reference alone, as earlier sessions measured it, its worst pixels left out (the third) "
        "and none (the fourth). The pan's frames against their own references (a quarter of the "
        "samples); held %zu previews the last still frame again after the take's hold ends. "
        "Flicker: temporal std of the last %zu of the take's held frames' composite − plate, RMS "
        "over pixels, over the reference's RMS.\n\n",
        still.width, still.height, spp, kStillFirst, kStillLast, kTrimmedFraction * 100.0,
        kLongHold, kFlickerFrames);
    std::vector<VariantResult> results;
    for (const ShotVariant& v : variants) {
        if (v.name.find(o.variant) == std::string::npos) continue;
        VariantResult result;
        result.name = v.name;
        Result<std::vector<FrameRow>> rows = run(v, session, *refs, last, holdTo, result.dialPoint);
        if (!rows) {
            logError("{}", rows.message());
            return 1;
        }
        std::vector<double> ms;
        for (const FrameRow& r : *rows) {
            if (r.frame > 0 && !r.extraHold) ms.push_back(r.ms);  // frame 0 compiles the pipelines
            if (csv.is_open())
                csv << v.name << "," << r.frame << ","
                    << (r.frame >= kStillFirst && (r.extraHold || r.frame <= kStillLast)
                            ? long(r.frame - kStillFirst)
                            : -1L)
                    << "," << r.sqrtRelMse << "," << r.sqrtRelMseTrimmed << "," << r.sqrtNetRelMse
                    << "," << r.sqrtNetRelMseTrimmed << "," << r.ms << "\n";
        }
        result.flicker = flicker(*rows, still);
        result.msMedian = upperMedian(ms);
        result.rows = std::move(*rows);
        results.push_back(std::move(result));
    }
    printTable(results,
               "√relMSE against the truth, the references' noise taken out (their twins'), the "
               "0.1 % of pixels where the two disagree most left out:",
               &FrameRow::sqrtNetRelMseTrimmed);
    printTable(results, "The same, every pixel:", &FrameRow::sqrtNetRelMse);
    printTable(results, "√relMSE against the reference, the worst 0.1 % of pixels left out:",
               &FrameRow::sqrtRelMseTrimmed);
    printTable(results, "√relMSE against the reference, every pixel:", &FrameRow::sqrtRelMse);
    if (Result<ImageDifference> d = compareImages(refs->twins.at(kStillLast), still))
        std::printf(
            "\nThe reference's own noise: the still view refined again to the same samples with "
            "another random sequence scores √relMSE %.3f (the worst %.1f %% left out), "
            "%.3f (every pixel) against it.\n",
            std::sqrt(d->relMseTrimmed), kTrimmedFraction * 100.0, std::sqrt(d->relMse));
    for (const VariantResult& r : results)
        if (const FrameRow* longest = rowOf(r.rows, kStillFirst + kLongHold, true);
            longest && !longest->added.pixels.empty())
            if (Status s =
                    printErrorBreakdown(r.name, longest->added, still, refs->twins.at(kStillLast));
                !s)
                logError("{}", s.message());
    for (const VariantResult& r : results)
        if (!r.dialPoint.empty())
            std::printf("\nThe dial chose, %s: %s.\n", r.name.c_str(), r.dialPoint.c_str());
    return 0;
}

}  // namespace previs::bench
