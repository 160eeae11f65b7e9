#include "daemon/replay.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "base/log.h"
#include "base/progress.h"
#include "capture/recorded_source.h"
#include "daemon/pipeline_renderer.h"
#include "daemon/pipeline_stages.h"
#include "daemon/recorded_events.h"
#include "daemon/service_config.h"
#include "daemon/shot_controller.h"
#include "gpu/context.h"
#include "image/image.h"
#include "io/session.h"
#include "scene/scene_description.h"

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

int runReplay(const ReplayOptions& o) {
    Result<SessionInfo> session = openSession(o.sessionDir);
    if (!session) {
        logError("{}", session.message());
        return 2;
    }
    Result<ServiceConfig> config = o.configPath.empty()
                                       ? loadServiceConfig(session->configPath, session->configDir)
                                       : loadServiceConfig(o.configPath);
    if (!config) {
        logError("{}", config.message());
        return 2;
    }
    size_t unknownEvents = 0;
    std::vector<SessionEvent> events;
    if (fs::exists(fs::path(o.sessionDir) / "events.csv")) {
        Result<std::vector<SessionEvent>> loaded = loadEvents(o.sessionDir, &unknownEvents);
        if (!loaded) {
            logError("{}", loaded.message());
            return 2;
        }
        events = std::move(*loaded);
    }

    Result<std::unique_ptr<RecordedReader>> sceneReader = openCamera(*session, "scene");
    if (!sceneReader) {
        logError("{}", sceneReader.message());
        return 2;
    }
    if (!*sceneReader) {
        logError(
            "{}: the session has no scene camera (cameras/scene or a camera with role "
            "\"scene\" in session.toml)",
            o.sessionDir);
        return 2;
    }
    Result<std::unique_ptr<RecordedReader>> fisheyeReader = openCamera(*session, "fisheye");
    if (!fisheyeReader) {
        logError("{}", fisheyeReader.message());
        return 2;
    }
    if (*fisheyeReader && !config->fisheyeCamera)
        logWarning(
            "{}: the session has fisheye frames but the config has no [cameras.fisheye]: "
            "the scene's own lighting is used",
            config->path);

    Result<Scene> scene = loadScene(config->scenePath);
    if (!scene) {
        logError("{}", scene.message());
        return 2;
    }
    Result<std::unique_ptr<GpuContext>> gpu = GpuContext::create({});
    if (!gpu) {
        logError("{}", gpu.message());
        return 1;
    }
    Result<std::unique_ptr<PipelineRenderer>> renderer =
        PipelineRenderer::create(**gpu, *scene, *config);
    if (!renderer) {
        logError("{}", renderer.message());
        return 2;
    }
    Result<TrackingStage> tracking = TrackingStage::create(*config);
    if (!tracking) {
        logError("{}", tracking.message());
        return 2;
    }
    std::optional<LightingStage> lighting;
    if (*fisheyeReader && config->fisheyeCamera) {
        Result<LightingStage> stage = LightingStage::create(*config);
        if (!stage) {
            logError("{}", stage.message());
            return 2;
        }
        lighting.emplace(std::move(*stage));
    }

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
    csv << "frame,timestamp_ns,mode,samples,render_ms,tracking,tags,restarts,noise_estimate";
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) csv << ",m" << r << c;
    csv << "\n";

    ModeMachine modes(o.mode.value_or(Mode::Preview));
    size_t nextEvent = 0;
    uint64_t sceneSequence = 0, fisheyeSequence = 0;
    std::shared_ptr<Frame> pendingFisheye;
    if (*fisheyeReader) {
        Result<std::shared_ptr<Frame>> f = nextFrame(**fisheyeReader, fisheyeSequence);
        if (!f) {
            logError("{}", f.message());
            return 1;
        }
        pendingFisheye = *f;
    }
    std::shared_ptr<const LiveLighting> currentLighting;
    // The service's own shot rules, on the session's clock: rendering takes no recorded time, so
    // nothing is sized by this machine's speed and the same session gives the same frames.
    ManualShotClock clock;
    ShotController shot(**renderer, modes, clock, config->refine);
    TrackingPace pace;
    uint64_t written = 0;
    const Clock::time_point start = Clock::now();
    ProgressLine progress("replay", o.quiet);

    for (;;) {
        Result<std::shared_ptr<Frame>> next = nextFrame(**sceneReader, sceneSequence);
        if (!next) {
            logError("{}", next.message());
            return 1;
        }
        if (!*next) break;
        const std::shared_ptr<Frame> frame = *next;
        clock.setNs(frame->timestampNs);

        // Lighting: every fisheye frame recorded up to this scene frame, in order.
        while (pendingFisheye && pendingFisheye->timestampNs <= frame->timestampNs) {
            if (lighting && lighting->due(*pendingFisheye)) {
                Result<std::shared_ptr<const LiveLighting>> lit =
                    lighting->process(*pendingFisheye);
                if (lit)
                    currentLighting = *lit;
                else
                    logWarning("replay: fisheye frame {}: {}", pendingFisheye->sequence,
                               lit.message());
            }
            Result<std::shared_ptr<Frame>> f = nextFrame(**fisheyeReader, fisheyeSequence);
            if (!f) {
                logError("{}", f.message());
                return 1;
            }
            pendingFisheye = *f;
        }
        // Button and ctl events up to this frame drive the mode, as they did live.
        for (; nextEvent < events.size() && events[nextEvent].timestampNs <= frame->timestampNs;
             ++nextEvent) {
            if (!o.mode) applySessionEvent(modes, events[nextEvent]);
        }

        // Tracking at the service's pace: every frame in preview, a few a second refining.
        std::shared_ptr<const TrackedFrame> tracked;
        if (pace.due(modes.mode(), frame->timestampNs))
            tracked = std::make_shared<TrackedFrame>(tracking->process(frame));
        const Clock::time_point renderStart = Clock::now();
        Result<ShotStep> step = shot.step(tracked, currentLighting);
        if (!step) {
            logError("replay: frame {}: {}", frame->sequence, step.message());
            return 1;
        }
        const Mode mode = step->mode;
        Result<ImageF> image = (*renderer)->composite(step->noiseEstimate);
        if (!image) {
            logError("replay: frame {}: {}", frame->sequence, image.message());
            return 1;
        }
        const double renderMs =
            std::chrono::duration<double, std::milli>(Clock::now() - renderStart).count();
        const std::string stem =
            (fs::path(o.outDir) / fmt::format("frame_{:06d}", written)).string();
        if (o.exr) {
            if (Status s = writeExr(stem + ".exr", *image); !s) {
                logError("{}", s.message());
                return 1;
            }
        }
        const uint32_t width = image->width, height = image->height;
        if (Status s =
                writePng(stem + ".png", width, height, (*renderer)->toDisplay(std::move(*image)));
            !s) {
            logError("{}", s.message());
            return 1;
        }
        // The frame shown: refinement's frozen one, else this one.
        static const TrackedFrame kNothingShown;
        const TrackedFrame& used = step->shown ? *step->shown : kNothingShown;
        csv << written << "," << frame->timestampNs << "," << toString(mode) << ","
            << (*renderer)->samples() << "," << fmt::format("{:.1f}", renderMs) << ","
            << (!used.worldFromCamera ? "none"
                : used.lost           ? "held"
                                      : "tracked")
            << "," << used.tags << "," << shot.restarts() << ",";
        if (mode == Mode::Refine && shot.measuredNoise())
            csv << fmt::format("{:.6g}", *shot.measuredNoise());
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) {
                csv << ",";
                if (used.worldFromCamera)
                    csv << fmt::format("{:.9g}", (*used.worldFromCamera)(r, c));
            }
        csv << "\n";
        ++written;
        progress.update(fmt::format("frame {}, {}, {} spp, {:.0f} ms", written - 1, toString(mode),
                                    (*renderer)->samples(), renderMs));
    }
    csv.flush();
    if (!csv) {
        logError("replay: writing {} failed (disk full?)", csvPath);
        return 1;
    }
    progress.finish();
    if (unknownEvents > 0)
        logInfo("replay: {} event(s) of sources this previs does not know were skipped",
                unknownEvents);
    if (written == 0) {
        logError("{}: the scene camera has no frames", o.sessionDir);
        return 2;
    }
    logInfo("replay: wrote {} frames to {} in {:.1f} s", written, o.outDir,
            std::chrono::duration<double>(Clock::now() - start).count());
    return 0;
}

}  // namespace previs
