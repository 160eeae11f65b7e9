#include "take/replay.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "base/log.h"
#include "base/progress.h"
#include "capture/recorded_source.h"
#include "config/service_config.h"
#include "gpu/context.h"
#include "image/image.h"
#include "io/session.h"
#include "scene/scene_description.h"
#include "shot/pipeline_renderer.h"
#include "shot/pipeline_stages.h"
#include "shot/shot_controller.h"
#include "take/recorded_events.h"
#include "take/take_files.h"

namespace previs {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// The next frame of a recorded camera, or nullptr at its end.
Result<std::shared_ptr<Frame>> nextFrame(RecordedReader& reader, uint64_t& sequence) {
    while (!reader.finished()) {
        auto frame = std::make_shared<Frame>();
        Result<bool> got = reader.read(1000, *frame);
        if (!got) return got.error();
        if (*got) {
            frame->sequence = sequence++;
            return frame;
        }
    }
    return std::shared_ptr<Frame>();
}

Result<std::unique_ptr<RecordedReader>> openCamera(const SessionInfo& session,
                                                   const std::string& role) {
    const SessionCamera* camera = session.cameraWithRole(role);
    if (!camera) return std::unique_ptr<RecordedReader>();
    Result<std::unique_ptr<RecordedReader>> reader =
        RecordedReader::create(camera->dir, ReplayTiming::AsFastAsPossible);
    if (!reader) return reader.error();
    if (Status s = (*reader)->start(); !s) return s.error();
    return reader;
}

}  // namespace

SessionReplay::~SessionReplay() = default;

std::variant<std::unique_ptr<SessionReplay>, SessionReplay::OpenError> SessionReplay::open(
    const std::string& sessionDir, const ServiceConfig& config, std::optional<Mode> mode) {
    auto bad = [](const Error& e, int code = 2) { return OpenError{e, code}; };
    Result<SessionInfo> session = openSession(sessionDir);
    if (!session) return bad(session.error());
    std::unique_ptr<SessionReplay> r(new SessionReplay());
    r->fixedMode_ = mode;
    if (fs::exists(fs::path(sessionDir) / "events.csv")) {
        Result<std::vector<SessionEvent>> loaded = loadEvents(sessionDir, &r->unknownEvents_);
        if (!loaded) return bad(loaded.error());
        r->events_ = std::move(*loaded);
    }
    Result<std::unique_ptr<RecordedReader>> scene = openCamera(*session, "scene");
    if (!scene) return bad(scene.error());
    if (!*scene)
        return bad(
            makeError("{}: the session has no scene camera (cameras/scene or a camera with role "
                      "\"scene\" in session.toml)",
                      sessionDir));
    r->sceneReader_ = std::move(*scene);
    Result<std::unique_ptr<RecordedReader>> fisheye = openCamera(*session, "fisheye");
    if (!fisheye) return bad(fisheye.error());
    r->fisheyeReader_ = std::move(*fisheye);
    if (r->fisheyeReader_ && !config.fisheyeCamera)
        logWarning(
            "{}: the session has fisheye frames but the config has no [cameras.fisheye]: "
            "the scene's own lighting is used",
            config.path);

    Result<Scene> loaded = loadScene(config.scenePath);
    if (!loaded) return bad(loaded.error());
    Result<std::unique_ptr<GpuContext>> gpu = GpuContext::create({});
    if (!gpu) return bad(gpu.error(), 1);
    r->gpu_ = std::move(*gpu);
    Result<std::unique_ptr<PipelineRenderer>> renderer =
        PipelineRenderer::create(*r->gpu_, std::move(*loaded), config);
    if (!renderer) return bad(renderer.error());
    r->renderer_ = std::move(*renderer);
    Result<TrackingStage> tracking = TrackingStage::create(config);
    if (!tracking) return bad(tracking.error());
    r->tracking_ = std::make_unique<TrackingStage>(std::move(*tracking));
    if (r->fisheyeReader_ && config.fisheyeCamera) {
        Result<LightingStage> stage = LightingStage::create(config);
        if (!stage) return bad(stage.error());
        r->lighting_ = std::make_unique<LightingStage>(std::move(*stage));
        Result<std::shared_ptr<Frame>> f = nextFrame(*r->fisheyeReader_, r->fisheyeSequence_);
        if (!f) return bad(f.error(), 1);
        r->pendingFisheye_ = *f;
    }
    r->modes_ = std::make_unique<ModeMachine>(mode.value_or(Mode::Preview));
    // The service's own shot rules, on the session's clock: rendering takes no recorded time, so
    // nothing is sized by this machine's speed and the same session gives the same frames.
    r->shot_ =
        std::make_unique<ShotController>(*r->renderer_, *r->modes_, r->clock_, config.refine);
    return r;
}

// Every fisheye frame recorded up to `timestampNs`, in order, through the lighting stage's own
// pacing ([lighting] update_hz on the frames' timestamps).
Status SessionReplay::lightUpTo(uint64_t timestampNs) {
    while (pendingFisheye_ && pendingFisheye_->timestampNs <= timestampNs) {
        if (lighting_->due(*pendingFisheye_)) {
            Result<std::shared_ptr<const LiveLighting>> lit = lighting_->process(*pendingFisheye_);
            if (lit && *lit)
                currentLighting_ = *lit;
            else if (!lit)
                logWarning("replay: fisheye frame {}: {}", pendingFisheye_->sequence,
                           lit.message());
        }
        Result<std::shared_ptr<Frame>> f = nextFrame(*fisheyeReader_, fisheyeSequence_);
        if (!f) return f.error();
        pendingFisheye_ = *f;
    }
    return {};
}

Result<std::optional<SessionReplay::Step>> SessionReplay::next() {
    Result<std::shared_ptr<Frame>> next = nextFrame(*sceneReader_, sceneSequence_);
    if (!next) return next.error();
    if (!*next) return std::optional<Step>();
    Step out;
    out.frame = *next;
    const Frame& frame = *out.frame;
    clock_.setNs(frame.timestampNs);
    if (Status s = lightUpTo(frame.timestampNs); !s) return s.error();
    // Button and ctl events up to this frame drive the mode, as they did live.
    for (; nextEvent_ < events_.size() && events_[nextEvent_].timestampNs <= frame.timestampNs;
         ++nextEvent_) {
        if (!fixedMode_) applySessionEvent(*modes_, events_[nextEvent_]);
    }
    // Tracking at the service's pace: every frame in preview, a few a second refining.
    std::shared_ptr<const TrackedFrame> tracked;
    if (pace_.due(modes_->mode(), frame.timestampNs))
        tracked = std::make_shared<TrackedFrame>(tracking_->process(out.frame));
    Result<ShotStep> step = shot_->step(tracked, currentLighting_);
    if (!step) return makeError("replay: frame {}: {}", frame.sequence, step.message());
    out.shot = std::move(*step);
    return std::optional<Step>(std::move(out));
}

namespace {

// frames.csv: one row per written frame (docs/previsd.md, "previs replay").
void writeCsvHeader(std::ofstream& csv) {
    csv << "frame,timestamp_ns,mode,samples,render_ms,tracking,tags,restarts,noise_estimate";
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) csv << ",m" << r << c;
    csv << "\n";
}

void writeCsvRow(std::ofstream& csv, uint64_t index, const SessionReplay& replay,
                 const SessionReplay::Step& step, uint64_t samples, double renderMs) {
    // The frame shown: refinement's frozen one, else this one.
    static const TrackedFrame kNothingShown;
    const TrackedFrame& used = step.shot.shown ? *step.shot.shown : kNothingShown;
    const ShotController& shot = replay.shot();
    csv << index << "," << step.frame->timestampNs << "," << toString(step.shot.mode) << ","
        << samples << "," << fmt::format("{:.1f}", renderMs) << ","
        << (!used.worldFromCamera ? "none"
            : used.lost           ? "held"
                                  : "tracked")
        << "," << used.tags << "," << shot.restarts() << ",";
    if (step.shot.mode == Mode::Refine && shot.measuredNoise())
        csv << fmt::format("{:.6g}", *shot.measuredNoise());
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) {
            csv << ",";
            if (used.worldFromCamera) csv << fmt::format("{:.9g}", (*used.worldFromCamera)(r, c));
        }
    csv << "\n";
}

}  // namespace

int runReplay(const ReplayOptions& o) {
    Result<ServiceConfig> config = [&]() -> Result<ServiceConfig> {
        if (!o.configPath.empty()) return loadServiceConfig(o.configPath);
        Result<SessionInfo> session = openSession(o.sessionDir);
        if (!session) return session.error();
        return loadSessionConfig(*session);
    }();
    if (!config) {
        logError("{}", config.message());
        return 2;
    }
    // The dial chooses by this machine's timing; lock step gives the same pixels on any machine.
    if (config->render.previewFps > 0.0) {
        logInfo(
            "replay: the dial ([render] preview_fps = {:g}) is live only: preview renders "
            "samples_per_frame = {} at resolution_scale = {:g}",
            config->render.previewFps, config->liveRender.samplesPerFrame,
            config->render.resolutionScale);
        config->render.previewFps = 0.0;
    }
    auto opened = SessionReplay::open(o.sessionDir, *config, o.mode);
    if (auto* e = std::get_if<SessionReplay::OpenError>(&opened)) {
        logError("{}", e->error.message);
        return e->exitCode;
    }
    SessionReplay& replay = *std::get<std::unique_ptr<SessionReplay>>(opened);
    PipelineRenderer& renderer = replay.renderer();

    std::error_code ec;
    fs::create_directories(o.outDir, ec);
    if (ec) {
        logError("--out {}: cannot create the folder: {}", o.outDir, ec.message());
        return 2;
    }
    const std::string csvPath = (fs::path(o.outDir) / "frames.csv").string();
    std::ofstream csv(csvPath, std::ios::trunc);
    if (!csv) {
        logError("--out {}: cannot write {}", o.outDir, csvPath);
        return 2;
    }
    writeCsvHeader(csv);

    uint64_t written = 0;
    const Clock::time_point start = Clock::now();
    ProgressLine progress("replay", o.quiet);
    for (;;) {
        const Clock::time_point renderStart = Clock::now();
        Result<std::optional<SessionReplay::Step>> step = replay.next();
        if (!step) {
            logError("{}", step.message());
            return 1;
        }
        if (!*step) break;
        // With --exr the float composite, tone mapped on the host; else the monitor's frame as
        // the service makes it (on the device). Either is the frame's one composite: each adds
        // the frame to the preview's history.
        Result<DisplayImage> shown = DisplayImage{};
        std::optional<ImageF> image;
        if (o.exr) {
            Result<ImageF> composite = renderer.composite((*step)->shot.noiseEstimate);
            if (composite)
                image = std::move(*composite);
            else
                shown = composite.error();
        } else {
            shown = renderer.display((*step)->shot.noiseEstimate);
        }
        if (!shown) {
            logError("replay: frame {}: {}", (*step)->frame->sequence, shown.message());
            return 1;
        }
        const double renderMs =
            std::chrono::duration<double, std::milli>(Clock::now() - renderStart).count();
        const std::string stem =
            (fs::path(o.outDir) / fmt::format("frame_{:06d}", written)).string();
        if (image) {
            if (Status s = writeExr(stem + ".exr", *image); !s) {
                logError("{}", s.message());
                return 1;
            }
            shown = renderer.toDisplay(std::move(*image));
        }
        if (Status s = writePng(stem + ".png", shown->width, shown->height, shown->rgb); !s) {
            logError("{}", s.message());
            return 1;
        }
        writeCsvRow(csv, written, replay, **step, renderer.samples(), renderMs);
        ++written;
        progress.update(fmt::format("frame {}, {}, {} spp, {:.0f} ms", written - 1,
                                    toString((*step)->shot.mode), renderer.samples(), renderMs));
    }
    csv.flush();
    if (!csv) {
        logError("replay: writing {} failed (disk full?)", csvPath);
        return 1;
    }
    progress.finish();
    if (replay.unknownEvents() > 0)
        logInfo("replay: {} event(s) of sources this previs does not know were skipped",
                replay.unknownEvents());
    if (written == 0) {
        logError("{}: the scene camera has no frames", o.sessionDir);
        return 2;
    }
    logInfo("replay: wrote {} frames to {} in {:.1f} s", written, o.outDir,
            std::chrono::duration<double>(Clock::now() - start).count());
    return 0;
}

}  // namespace previs
