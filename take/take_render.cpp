#include "take/take_render.h"

#include <signal.h>

#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>
#include <set>

#include "base/atomic_file.h"
#include "base/log.h"
#include "base/progress.h"
#include "capture/recorded_source.h"
#include "gpu/context.h"
#include "image/image.h"
#include "render/convergence.h"
#include "scene/scene_description.h"
#include "shot/pipeline_renderer.h"
#include "shot/pipeline_stages.h"
#include "take/take_files.h"
#include "take/take_track.h"
#include "timecode/frame_rate.h"

namespace previs {

namespace fs = std::filesystem;

namespace {

bool parseIndex(std::string_view s, size_t& out) {
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return !s.empty() && ec == std::errc() && end == s.data() + s.size();
}

Result<std::vector<size_t>> parsePostList(const std::string& text, size_t count) {
    std::set<size_t> frames;
    size_t start = 0;
    while (start <= text.size()) {
        const size_t comma = std::min(text.find(',', start), text.size());
        const std::string item = text.substr(start, comma - start);
        start = comma + 1;
        // "A", "A-B" or "A-BxS".
        size_t a = 0, b = 0, step = 1;
        const size_t dash = item.find('-');
        const size_t x = item.find('x');
        bool ok;
        if (dash == std::string::npos) {
            ok = x == std::string::npos && parseIndex(item, a);
            b = a;
        } else {
            ok = parseIndex(item.substr(0, dash), a) &&
                 parseIndex(item.substr(dash + 1, x == std::string::npos ? x : x - dash - 1), b) &&
                 (x == std::string::npos || parseIndex(item.substr(x + 1), step)) && step > 0 &&
                 b >= a;
        }
        if (!ok)
            return makeError(
                "frame range '{}': cannot read '{}' (use A:B, or a list like 1-100, 1-100x2, "
                "1,5,7-9)",
                text, item);
        if (b >= count)
            return makeError("frame range '{}': frame {} is past the take's last frame ({})", text,
                             b, count == 0 ? 0 : count - 1);
        for (size_t f = a; f <= b; f += step) frames.insert(f);
    }
    return std::vector<size_t>(frames.begin(), frames.end());
}

}  // namespace

Result<std::vector<size_t>> parseFrameRange(const std::string& text, size_t count) {
    if (text.empty()) {
        std::vector<size_t> all(count);
        for (size_t i = 0; i < count; ++i) all[i] = i;
        return all;
    }
    const size_t colon = text.find(':');
    if (colon == std::string::npos) return parsePostList(text, count);
    size_t a = 0, b = count;
    const std::string first = text.substr(0, colon), second = text.substr(colon + 1);
    if ((!first.empty() && !parseIndex(first, a)) || (!second.empty() && !parseIndex(second, b)))
        return makeError("frame range '{}': use A:B (A inclusive, B exclusive)", text);
    if (b > count)
        return makeError("frame range '{}': the take has {} frames (0:{})", text, count, count);
    std::vector<size_t> frames;
    for (size_t i = a; i < b; ++i) frames.push_back(i);
    return frames;
}

std::vector<std::string> planFrameRanges(const std::vector<size_t>& frames, size_t parts) {
    std::vector<std::string> plan;
    if (parts == 0) return plan;
    // More parts than frames: the surplus get an empty slice at the end, so task i always finds
    // line i, and renders nothing.
    const size_t used = std::min(parts, frames.size());
    const size_t past = frames.empty() ? 0 : frames.back() + 1;
    for (size_t p = used; p < parts; ++p) plan.push_back(fmt::format("{}:{}", past, past));
    parts = used;
    std::vector<std::string> ranges;
    for (size_t p = 0; p < parts; ++p) {
        const size_t begin = frames.size() * p / parts, end = frames.size() * (p + 1) / parts;
        if (frames[end - 1] - frames[begin] == end - begin - 1) {
            ranges.push_back(fmt::format("{}:{}", frames[begin], frames[end - 1] + 1));
            continue;
        }
        std::string list;
        for (size_t i = begin; i < end;) {
            size_t j = i;
            while (j + 1 < end && frames[j + 1] == frames[j] + 1) ++j;
            if (!list.empty()) list += ',';
            list +=
                j == i ? fmt::format("{}", frames[i]) : fmt::format("{}-{}", frames[i], frames[j]);
            i = j + 1;
        }
        ranges.push_back(list);
    }
    ranges.insert(ranges.end(), plan.begin(), plan.end());
    return ranges;
}

namespace {

// Imath's layout of a transform given for column vectors: its transpose, row-major.
std::array<float, 16> imathLayout(const cv::Matx44d& columnForm) {
    std::array<float, 16> m{};
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) m[size_t(r * 4 + c)] = float(columnForm(c, r));
    return m;
}

}  // namespace

std::array<float, 16> exrWorldToCamera(const cv::Matx44d& worldFromCamera) {
    const cv::Matx44d yUp = cv::Matx44d::diag({1.0, -1.0, 1.0, 1.0});
    return imathLayout(yUp * worldFromCamera.inv());
}

std::array<float, 16> exrWorldToNDC(const cv::Matx44d& worldFromCamera, const cv::Matx33d& k,
                                    cv::Size size) {
    const double w = size.width, h = size.height;
    // Pixels (u, v) with centres at integers, as OpenCV projects; NDC = ((u + ½)/W, (v + ½)/H).
    const cv::Matx44d projection(k(0, 0) / w, k(0, 1) / w, (k(0, 2) + 0.5) / w, 0.0,  //
                                 0.0, k(1, 1) / h, (k(1, 2) + 0.5) / h, 0.0,          //
                                 0.0, 0.0, 0.0, 1.0,                                  //
                                 0.0, 0.0, 1.0, 0.0);
    return imathLayout(projection * worldFromCamera.inv());
}

std::pair<int, int> exrFramesPerSecond(double fps) {
    if (!(fps > 0.0)) return {0, 0};
    const FrameRate rate = snapFrameRate(fps);
    return {int(rate.num), int(rate.den)};
}

uint32_t takeFrameSeed(uint32_t seed, uint64_t index) {
    uint64_t z = (uint64_t(seed) << 32 ^ index) + 0x9e3779b97f4a7c15ull;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return uint32_t((z ^ (z >> 31)) >> 32);
}

namespace {

std::atomic<bool> gStop{false};
std::atomic<int> gSignal{0};

void onSignal(int sig) {
    gSignal.store(sig);
    gStop.store(true);
}

// The take's lighting snapshots in time order: those the service recorded (v3 lighting/), else
// made from its fisheye frames by the lighting stage, as the service made them.
Result<std::vector<std::shared_ptr<const LiveLighting>>> takeLighting(const SessionInfo& session,
                                                                      const ServiceConfig& config) {
    std::vector<std::shared_ptr<const LiveLighting>> out;
    if (!config.fisheyeCamera) return out;
    Result<LightingStage> stage = LightingStage::create(config);
    if (!stage) return stage.error();
    Result<std::vector<LightingRecord>> recorded = loadLighting(session.dir);
    if (!recorded) return recorded.error();
    const int mapWidth = config.lighting.fisheye.width;
    for (const LightingRecord& r : *recorded) {
        // The map's header first: a small file may declare a size that costs gigabytes.
        Result<ImageSize> size = imageFileSize(r.mapFile);
        if (!size) return size.error();
        if (size->width > uint32_t(mapWidth) || size->height > uint32_t(mapWidth / 2))
            return makeError(
                "{}: a {}x{} map, larger than the take's config makes ({}x{}); not decoded",
                r.mapFile, size->width, size->height, mapWidth, mapWidth / 2);
        Result<std::shared_ptr<const LiveLighting>> lit = stage->restore(r.mapFile);
        if (!lit) return lit.error();
        auto snapshot = std::make_shared<LiveLighting>(**lit);
        snapshot->timestampNs = r.timestampNs;
        snapshot->restored = false;  // captured on set, not the box's stand-in
        out.push_back(std::move(snapshot));
    }
    if (!out.empty() || !session.cameraWithRole("fisheye")) return out;
    Result<std::vector<RecordedFrameEntry>> fisheye =
        loadCameraIndex(session.cameraWithRole("fisheye")->dir);
    if (!fisheye) return fisheye.error();
    for (const RecordedFrameEntry& e : *fisheye) {
        Result<Frame> frame = readRecordedFrame(e);
        if (!frame) continue;
        frame->sequence = e.sequence;  // a bracket's frames are consecutive by their sequence
        if (!stage->due(*frame)) continue;
        Result<std::shared_ptr<const LiveLighting>> lit = stage->process(*frame);
        if (lit && *lit) out.push_back(*lit);  // null: a bracket in progress or dropped
    }
    return out;
}

// The snapshot in effect at `timestampNs`: the newest before it, else the first.
std::shared_ptr<const LiveLighting> lightingAt(
    const std::vector<std::shared_ptr<const LiveLighting>>& snapshots, uint64_t timestampNs) {
    std::shared_ptr<const LiveLighting> in;
    for (const auto& s : snapshots)
        if (!in || s->timestampNs <= timestampNs) in = s;
    return in;
}

std::string framePath(const std::string& dir, size_t index, const char* ext) {
    return (fs::path(dir) / fmt::format("frame_{:06d}.{}", index, ext)).string();
}

bool frameDone(const std::string& dir, size_t index) {
    std::error_code ec;
    return fs::is_regular_file(framePath(dir, index, "png"), ec) &&
           isCompleteExr(framePath(dir, index, "exr"));
}

class FrameRenderer {
public:
    FrameRenderer(PipelineRenderer& r, const TakeRenderOptions& o, uint32_t spp, double target,
                  uint32_t seed)
        : r_(r), o_(o), spp_(spp), target_(target), seed_(seed) {}

    // Renders and writes frame `index`; an error names what failed.
    Status render(size_t index, const TakeFrame& f, const cv::Matx44d& pose,
                  const std::shared_ptr<const LiveLighting>& lighting,
                  const ExrFrameAttributes& attributes) {
        Result<Frame> plate = readRecordedFrame(f.entry);
        if (!plate) return plate.error();
        TrackedFrame tracked;
        tracked.frame = std::make_shared<const Frame>(std::move(*plate));
        tracked.worldFromCamera = pose;
        tracked.lost = false;
        // The first refinement of a process differs from later ones in the last bits of a float
        // (the renderer's first pass settles state a later one finds settled; not yet pinned
        // down), so frame k would depend on whether it came first: one discarded sample first.
        if (!warmed_) {
            warmed_ = true;
            if (Status s = r_.beginRefine(tracked, lighting); !s) return s;
            if (Status s = r_.refineStep(1); !s) return s;
        }
        r_.resetLightingCorrection();  // each frame fits on its own: frames render alike anywhere
        std::optional<double> noise;
        uint32_t done = 0;
        if (Status s = accumulate(index, tracked, lighting, noise, done); !s) return s;
        // [lighting] fit_to_plate, as the service fits: the finished accumulation is metered, and
        // when the fit changes the lighting the frame renders again with it. Nothing more is
        // rendered when the lighting already explains the plate.
        // A fit that changed the lighting is checked by short renders and fitted again while the
        // fit asks (it leaves interreflections to the next), then the frame renders in full.
        bool refitted = false;
        for (int pass = 0; pass < kMaxFitPasses; ++pass) {
            Result<bool> refit = fitLighting(index, tracked);
            if (!refit) return refit.error();
            if (!*refit) break;
            refitted = true;
            if (Status s = accumulate(index, tracked, lighting, noise, done, kFitSamples); !s)
                return s;
        }
        if (refitted)
            if (Status s = accumulate(index, tracked, lighting, noise, done); !s) return s;
        if (gStop.load()) return makeError("interrupted");
        lastSamples_ = done;
        lastNoise_ = noise;
        return write(index, noise, attributes);
    }

    // The last frame's samples per pixel and the meter's estimate (none when not measured).
    uint32_t lastSamples() const { return lastSamples_; }
    std::optional<double> lastNoise() const { return lastNoise_; }

private:
    // The frame from a fresh accumulation with its own seed, up to spp_ or target_.
    Status accumulate(size_t index, const TrackedFrame& tracked,
                      const std::shared_ptr<const LiveLighting>& lighting,
                      std::optional<double>& noise, uint32_t& done, uint32_t most = 0) {
        if (Status s = r_.beginRefine(tracked, lighting); !s) return s;
        r_.setSeed(takeFrameSeed(seed_, index));
        constexpr uint32_t kStep = 16;  // samples a step at most, between checks for a stop
        // The shot's stopping rule (render/convergence.h): the target, on a look, or the samples.
        StoppingRule rule(target_, most > 0 ? std::min(most, spp_) : spp_);
        done = 0;
        while (!rule.done(done) && !gStop.load()) {
            const uint32_t n = uint32_t(std::min<uint64_t>(kStep, rule.nextStop(done) - done));
            if (Status s = r_.refineStep(n); !s) return s;
            done += n;
            // Without a target nothing is measured: the frame renders its samples, and the
            // composite has no estimate to denoise by.
            if (rule.targetNoise() > 0.0 && !rule.done(done))
                if (Status s = rule.lookIfDue(done, [this] { return r_.measureNoise(); }); !s)
                    return s;
        }
        noise = rule.measured();
        return {};
    }

    // Meters the frame and fits its lighting to the plate (PipelineRenderer::fitLighting);
    // whether the lighting changed.
    Result<bool> fitLighting(size_t index, const TrackedFrame& tracked) {
        if (!r_.fitsLighting() || gStop.load()) return false;
        Result<std::optional<PlateConsistency>> reading = r_.measurePlateConsistency();
        if (!reading) return reading.error();
        if (!*reading) return false;
        const LightingFitReport fit = r_.fitLighting(tracked, **reading);
        if (fit.state == LightingFitReport::State::Failed)
            logWarning(
                "render-session: frame {}: the fit to the plate failed ({}); rendered with "
                "the lighting as captured",
                index, fit.why);
        return fit.changed;
    }

    // The fit's own renders: enough samples for the meter's cells (kPlateMeterCellSamples), and
    // how many times it may fit a frame.
    static constexpr uint32_t kFitSamples = 32;
    static constexpr int kMaxFitPasses = 3;

    Status write(size_t index, std::optional<double> noise, const ExrFrameAttributes& attributes) {
        Result<ImageF> composite = r_.composite(noise);
        if (!composite) return composite.error();
        ImageF rgba;
        rgba.width = composite->width;
        rgba.height = composite->height;
        rgba.channels = 4;
        rgba.pixels.reserve(size_t(rgba.width) * rgba.height * 4);
        for (size_t i = 0; i < composite->pixels.size(); i += 3)
            rgba.pixels.insert(rgba.pixels.end(), {composite->pixels[i], composite->pixels[i + 1],
                                                   composite->pixels[i + 2], 1.0f});
        std::vector<ImageF> layers;
        std::vector<std::string> names;
        for (const std::string& name : o_.aovs) {
            Result<ImageF> layer = aov(name);
            if (!layer) return layer.error();
            layers.push_back(std::move(*layer));
            names.push_back(name);
        }
        std::vector<ExrLayer> layersOut{{"", &rgba}};
        for (size_t i = 0; i < layers.size(); ++i) layersOut.push_back({names[i], &layers[i]});
        const std::string exrPath = framePath(o_.outDir, index, "exr");
        const std::string pngPath = framePath(o_.outDir, index, "png");
        const DisplayImage shown = r_.toDisplay(std::move(*composite));
        Result<std::vector<uint8_t>> png = encodePng(shown.width, shown.height, shown.rgb, pngPath);
        if (!png) return png.error();
        // The EXR marks a frame done (a resubmission renders what lacks one): the PNG is renamed
        // into place first. Not synced, as before: a frame lost to a power cut renders again.
        Result<AtomicFile> exr = AtomicFile::create(exrPath, {.durable = false});
        if (!exr) return exr.error();
        if (Status s = writeExrLayers(exr->fd(), exrPath, layersOut, attributes); !s) return s;
        if (Status s = writeFileAtomic(pngPath, *png, {.durable = false}); !s) return s;
        return exr->commit();
    }

    Result<ImageF> aov(const std::string& name) {
        if (name == "differential") {
            Result<ImageF> mixed = r_.image(Aov::Mixed);
            if (!mixed) return mixed.error();
            Result<ImageF> real = r_.image(Aov::Real);
            if (!real) return real.error();
            for (size_t i = 0; i < mixed->pixels.size(); ++i) mixed->pixels[i] -= real->pixels[i];
            return mixed;
        }
        static const std::map<std::string, Aov> kAovs = {
            {"mixed", Aov::Mixed},   {"real", Aov::Real},     {"mask", Aov::Mask},
            {"albedo", Aov::Albedo}, {"normal", Aov::Normal}, {"depth", Aov::Depth}};
        return r_.image(kAovs.at(name));
    }

    PipelineRenderer& r_;
    const TakeRenderOptions& o_;
    uint32_t spp_;
    double target_;
    uint32_t seed_;
    bool warmed_ = false;
    uint32_t lastSamples_ = 0;
    std::optional<double> lastNoise_;
};

// The take's frame rate: the camera's configured fps, else its frames' median interval.
double takeFrameRate(const TakeTrack& track, const ServiceConfig& config) {
    if (config.sceneCamera.fps > 0.0) return config.sceneCamera.fps;
    std::vector<uint64_t> intervals;
    for (size_t i = 1; i < track.frames.size(); ++i)
        intervals.push_back(track.frames[i].entry.timestampNs -
                            track.frames[i - 1].entry.timestampNs);
    if (intervals.empty()) return 0.0;
    std::nth_element(intervals.begin(), intervals.begin() + ptrdiff_t(intervals.size() / 2),
                     intervals.end());
    const uint64_t median = intervals[intervals.size() / 2];
    return median > 0 ? 1e9 / double(median) : 0.0;
}

// A frame's standard attributes for post (docs/takes.md, "EXR attributes"): the take's
// timecode label, its rate, the camera it was rendered with, when it was captured, the take.
ExrFrameAttributes postAttributes(const TakeFrame& f, const cv::Matx44d& pose,
                                  const CameraCalibration& calibration, std::pair<int, int> fps,
                                  const std::string& take) {
    ExrFrameAttributes a;
    a.timeCode = f.entry.timecode;
    a.fpsNum = fps.first;
    a.fpsDen = fps.second;
    a.worldToCamera = exrWorldToCamera(pose);
    a.worldToNDC = exrWorldToNDC(pose, calibration.cameraMatrix(), calibration.imageSize());
    if (f.entry.wallClockNs) {
        const time_t seconds = time_t(*f.entry.wallClockNs / 1000000000u);
        std::tm local{};
        if (::localtime_r(&seconds, &local)) {
            char text[32];
            std::strftime(text, sizeof text, "%Y:%m:%d %H:%M:%S", &local);
            a.capDate = text;
            a.utcOffset = float(-local.tm_gmtoff);
        }
    }
    a.strings.emplace_back("take", take);
    return a;
}

struct Prepared {
    SessionInfo session;
    ServiceConfig config;
    TakeTrack track;
    std::vector<size_t> frames;
};

Result<Prepared> prepare(const TakeRenderOptions& o) {
    Prepared p;
    Result<SessionInfo> session = openSession(o.takeDir);
    if (!session) return session.error();
    p.session = std::move(*session);
    Result<ServiceConfig> config = loadSessionConfig(p.session);
    if (!config) return config.error();
    p.config = std::move(*config);
    if ((o.width == 0) != (o.height == 0))
        return makeError("give --width and --height together (or neither)");
    if (o.width > 0) {
        p.config.render.width = o.width;
        p.config.render.height = o.height;
    }
    p.config.render.previewFps = 0.0;  // no dial: a final render never previews
    static const std::set<std::string> kKnown = {"mixed",  "real",   "mask", "differential",
                                                 "albedo", "normal", "depth"};
    for (const std::string& a : o.aovs)
        if (!kKnown.count(a))
            return makeError(
                "--aov '{}': use mixed, real, mask, differential, albedo, normal or depth", a);
    // Frames are counted from the index alone, so --plan needs no tracking.
    const SessionCamera* scene = p.session.cameraWithRole("scene");
    if (!scene) return makeError("{}: the take has no scene camera", o.takeDir);
    Result<std::vector<size_t>> frames = parseFrameRange(o.frames, scene->frames);
    if (!frames) return frames.error();
    p.frames = std::move(*frames);
    return p;
}

// A stage as it begins, one line on stderr unless --quiet.
void stageLine(const std::string& what, bool quiet) {
    if (!quiet) logInfo("render-session: {} ...", what);
}

// The take tracked frame by frame (trackTake), its progress on stderr as ProgressLine shows it.
Result<TakeTrack> trackWithProgress(const SessionInfo& session, const ServiceConfig& config,
                                    bool quiet) {
    ProgressLine line("previs: render-session", quiet);
    line.update("tracking the take ...");
    Result<TakeTrack> track = trackTake(session, config, [&line](size_t done, size_t total) {
        line.update(fmt::format("tracking the take: frame {}/{}", done, total));
    });
    if (track) {
        const size_t tracked =
            size_t(std::count_if(track->frames.begin(), track->frames.end(),
                                 [](const TakeFrame& f) { return f.tracked.has_value(); }));
        line.update(fmt::format("tracked the take: {} of {} frames have a pose", tracked,
                                track->frames.size()));
    }
    return track;
}

// The frames of the range not yet in the output folder (a resubmitted job renders only what is
// missing), the folder made first.
Result<std::vector<size_t>> framesToRender(const TakeRenderOptions& o,
                                           const std::vector<size_t>& frames) {
    std::error_code ec;
    fs::create_directories(o.outDir, ec);
    if (ec) return makeError("cannot create {}: {}", o.outDir, ec.message());
    std::vector<size_t> todo;
    for (size_t f : frames)
        if (!frameDone(o.outDir, f)) todo.push_back(f);
    if (todo.size() < frames.size())
        logInfo("render-session: {} of the {} frames are already in {}",
                frames.size() - todo.size(), frames.size(), o.outDir);
    return todo;
}

// The scene on the GPU, ready to render the take's frames (`gpu` made here, to outlive it).
// The GPU's failure is the device's (exit 1); the scene's and the renderer's are the take's
// config's (exit 2).
Result<std::unique_ptr<PipelineRenderer>> openRenderer(const TakeRenderOptions& o,
                                                       const ServiceConfig& config,
                                                       std::unique_ptr<GpuContext>& gpu) {
    stageLine("loading the scene " + config.scenePath, o.quiet);
    Result<Scene> scene = loadScene(config.scenePath);
    if (!scene) return withKind(scene.error(), Error::Kind::Config);
    stageLine("opening the GPU", o.quiet);
    Result<std::unique_ptr<GpuContext>> context = GpuContext::create({});
    if (!context) return withKind(context.error(), Error::Kind::Device);
    gpu = std::move(*context);
    PipelineStartHooks hooks;
    hooks.stage = [&o](const std::string& what, size_t) { stageLine(what, o.quiet); };
    Result<std::unique_ptr<PipelineRenderer>> renderer =
        PipelineRenderer::create(*gpu, std::move(*scene), config, hooks);
    if (!renderer) return withKind(renderer.error(), Error::Kind::Config);
    return renderer;
}

// SIGTERM and SIGINT stop the render between frames, or the frame's dispatches mid-frame.
void stopOnSignals(PipelineRenderer& renderer) {
    gStop.store(false);
    struct sigaction action {};
    action.sa_handler = onSignal;
    sigaction(SIGTERM, &action, nullptr);
    sigaction(SIGINT, &action, nullptr);
    renderer.setInterrupt(&gStop);
}

// --spp N renders exactly N; otherwise the take's [refine] target, up to its max_samples
// (kUncappedSpp when it has none: a final render must end).
FrameRenderer makeFrameRenderer(PipelineRenderer& renderer, const TakeRenderOptions& o,
                                const ServiceConfig& config) {
    constexpr uint32_t kUncappedSpp = 4096;
    const uint32_t spp = o.spp > 0                      ? o.spp
                         : config.refine.maxSamples > 0 ? uint32_t(config.refine.maxSamples)
                                                        : kUncappedSpp;
    const double target = o.spp > 0              ? 0.0
                          : o.targetNoise >= 0.0 ? o.targetNoise
                                                 : config.refine.targetNoise;
    return FrameRenderer(renderer, o, spp, target, config.render.seed);
}

struct FrameCounts {
    size_t rendered = 0;
    size_t failed = 0;
};

// Renders `todo` until done or a signal; a frame that cannot be rendered is one line and
// skipped.
FrameCounts renderFrames(FrameRenderer& frames, const std::vector<size_t>& todo,
                         const TakeTrack& track,
                         const std::vector<std::shared_ptr<const LiveLighting>>& lighting,
                         const Prepared& p, const TakeRenderOptions& o) {
    const std::pair<int, int> fps = exrFramesPerSecond(takeFrameRate(track, p.config));
    fs::path takeDir = fs::absolute(p.session.dir).lexically_normal();
    if (takeDir.filename().empty()) takeDir = takeDir.parent_path();  // "TAKE/"
    const std::string take = takeDir.filename().string();
    FrameCounts counts{.rendered = 0, .failed = track.skippedLines.size()};
    for (size_t index : todo) {
        if (gStop.load()) break;
        if (index >= track.frames.size()) continue;
        const TakeFrame& f = track.frames[index];
        const std::optional<cv::Matx44d>& pose = o.rawPoses ? f.tracked : f.smoothed;
        Status s =
            !f.problem.empty() ? Status(makeError("{}", f.problem))
            : !pose            ? Status(makeError("no camera pose (tracking lost, not bridged)"))
                               : frames.render(
                                     index, f, *pose, lightingAt(lighting, f.entry.timestampNs),
                                     postAttributes(f, *pose, *p.config.sceneCamera.calibration, fps, take));
        if (gStop.load()) break;
        if (!s) {
            logError("render-session: frame {} ({}): {}; skipped", index, f.entry.file,
                     s.message());
            ++counts.failed;
            continue;
        }
        ++counts.rendered;
        if (!o.quiet)
            logInfo("render-session: frame {} ({} of {}): {} spp{}", index, counts.rendered,
                    todo.size(), frames.lastSamples(),
                    frames.lastNoise() ? fmt::format(", noise {:.2f} %", *frames.lastNoise() * 100)
                                       : std::string());
    }
    return counts;
}

}  // namespace

int runTakeRender(const TakeRenderOptions& o) {
    Result<Prepared> prepared = prepare(o);
    if (!prepared) {
        logError("render-session: {}", prepared.message());
        return 2;
    }
    Prepared& p = *prepared;
    if (o.plan > 0) {
        for (const std::string& range : planFrameRanges(p.frames, o.plan))
            std::printf("%s\n", range.c_str());
        return 0;
    }
    Result<std::vector<size_t>> todo = framesToRender(o, p.frames);
    if (!todo) {
        logError("render-session: {}", todo.message());
        return 2;
    }
    if (todo->empty()) return 0;

    // Every stage before the first frame says what it does (DESIGN.md §3): tracking a long take
    // alone takes minutes. The time a frame reported at the end includes them.
    const auto start = std::chrono::steady_clock::now();
    Result<TakeTrack> track = trackWithProgress(p.session, p.config, o.quiet);
    if (!track) {
        logError("render-session: {}", track.message());
        return 2;
    }
    for (const std::string& line : track->skippedLines) logError("render-session: {}", line);
    stageLine("reading the take's lighting", o.quiet);
    Result<std::vector<std::shared_ptr<const LiveLighting>>> lighting =
        takeLighting(p.session, p.config);
    if (!lighting) {
        logError("render-session: {}", lighting.message());
        return 2;
    }
    std::unique_ptr<GpuContext> gpu;
    Result<std::unique_ptr<PipelineRenderer>> renderer = openRenderer(o, p.config, gpu);
    if (!renderer) {
        logError("render-session: {}", renderer.message());
        return renderer.error().kind == Error::Kind::Config ? 2 : 1;
    }
    stopOnSignals(**renderer);
    FrameRenderer frames = makeFrameRenderer(**renderer, o, p.config);
    const double setupSeconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const FrameCounts counts = renderFrames(frames, *todo, *track, *lighting, p, o);
    if (gStop.load()) {
        logInfo("render-session: stopped by signal {} after {} frame(s); no partial frame left",
                gSignal.load(), counts.rendered);
        return 128 + gSignal.load();
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    logInfo(
        "render-session: {} frame(s) in {:.1f} s ({:.2f} s a frame, the take's tracking and the "
        "setup's {:.1f} s included){}",
        counts.rendered, seconds, counts.rendered ? seconds / double(counts.rendered) : 0.0,
        setupSeconds,
        counts.failed ? fmt::format("; {} could not be rendered (see above)", counts.failed) : "");
    return counts.failed ? 1 : 0;
}

}  // namespace previs
