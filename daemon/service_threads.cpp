// The bodies of the service's threads (Service::Threads, daemon/service_threads.h): tracking,
// lighting, render and the stop.

#include "daemon/service_threads.h"

#include <algorithm>
#include <utility>

#include "base/log.h"
#include "base/monotonic_clock.h"

namespace previs {

namespace {

// How long the render thread waits for a frame before it checks the mode (and ends its step).
constexpr auto kRenderPoll = std::chrono::milliseconds(100);

// Without camera frames for this long, the display says so instead of holding the last picture.
constexpr auto kNoCameraAfter = std::chrono::seconds(2);

}  // namespace

void Service::Threads::runTracking(const ModeMachine& modes) {
    nameThread("pv-tracking");
    TrackingPace pace;
    while (!stopping.load()) {
        std::shared_ptr<const Frame> frame =
            sceneCamera->frames().waitTakeFor(std::chrono::milliseconds(100));
        if (!frame) continue;
        StageStep busy(&trackingStage);
        if (recordedEvents) {
            std::vector<SessionEvent> due = recordedEvents->due(frame->deviceSequence);
            // Each pass of a looping take starts in preview, as the recording did: its presses
            // are toggles, and an odd number of them would invert every other pass.
            if (recordedEvents->restarted()) applyEvent({0, "session", "restart"});
            for (const SessionEvent& e : due) applyEvent(e);
        }
        if (!pace.due(modes.mode(), frame->timestampNs)) continue;
        auto tracked = std::make_shared<TrackedFrame>(tracking->process(std::move(frame)));
        if (tracked->lostReason != LostReason::None)
            lostFrames[size_t(tracked->lostReason)].fetch_add(1);
        tracked->timecode = frameTimecode(*tracked->frame);
        // On the network first: a tracker's consumers want the pose as early as it exists.
        if (trackingOut) trackingOut->send(*tracked, tracked->timecode, recorder->recording());
        recorder->addPose(*tracked);
        // Replaced before the render thread took it: the renderer is the slow stage.
        if (trackedFrames.publish(std::move(tracked))) droppedRender.fetch_add(1);
    }
}

Status Service::Threads::openTimecode(const ServiceConfig& config) {
    const TimecodeConfig& c = config.network.timecode;
    TimecodeSourceConfig source;
    source.kind = c.ltc ? TimecodeSourceKind::Ltc : TimecodeSourceKind::Clock;
    // The rate the take's labels count at (one rule with the recorder and the export); a camera
    // without an fps has its rate measured on its frames (issue 54), not a guessed 30.
    Result<LabelRateRule> rule = labelRateRule(config, config.sceneCamera);
    if (!rule) return rule.error();
    source.rate = *rule;
    source.ltcRate = rule->configured;
    source.sampleRate = c.sampleRate;
    Result<std::unique_ptr<TimecodeSource>> made = TimecodeSource::create(source);
    if (!made) return made.error();
    timecode = std::move(*made);
    if (!c.ltc) return {};
    AlsaCaptureConfig audio;
    audio.device = c.device;
    audio.channel = c.channel;
    audio.sampleRate = c.sampleRate;
    // A missing audio input is the set's to fix, not a reason to stop previewing: the clock
    // stands in, and the status says so.
    Result<std::unique_ptr<AlsaCapture>> input = AlsaCapture::create(audio, timecode->audioSink());
    if (!input)
        logError("timecode: {}; frames carry the time of day until previsd restarts",
                 input.message());
    else
        ltcInput = std::move(*input);
    return {};
}

Status Service::Threads::openWeb(const WebConfig& c, Service* service) {
    if (c.listen.empty()) return {};
    Result<std::string> token = readWebToken(c, service->config_.path);
    if (!token) return token.error();
    WebMonitorSettings settings;
    settings.listen = c.listen;
    UniqueFD passed = passedSockets.take("web");
    settings.listenFd = passed.release();
    settings.token = *token;
    settings.streamFps = c.streamFps;
    settings.streamWidth = c.streamWidth;
    settings.jpegQuality = c.jpegQuality;
    settings.maxStreams = c.maxViewers;
    settings.hostNames = c.hostNames;
    WebMonitorHooks hooks;
    hooks.statusJson = [service] { return statusJson(service->status()); };
    hooks.command = [service](const std::string& command) {
        return service->handleCommand(command);
    };
    Result<std::unique_ptr<WebMonitor>> made = WebMonitor::create(settings, std::move(hooks));
    if (!made) return made.error();  // each names the [web] key it is about
    web = std::move(*made);
    return {};
}

std::optional<Timecode> Service::Threads::frameTimecode(const Frame& frame) const {
    // A recording's timestamps are not this machine's CLOCK_MONOTONIC: its recorded wall clock
    // gives the time of day it was filmed at.
    return timecode->frameTimecode(int64_t(frame.timestampNs), frame.wallClockNs, frame.sequence)
        .timecode;
}

void Service::Threads::restoreLighting() {
    std::error_code ec;
    if (savedLighting.empty() || !std::filesystem::is_regular_file(savedLighting, ec)) return;
    Result<std::shared_ptr<const LiveLighting>> restored = lighting->restore(savedLighting);
    if (!restored) {
        logWarning("lighting: the saved lighting is not used: {}", restored.message());
        return;
    }
    logInfo("lighting: lit by the saved lighting '{}' until the fisheye's first snapshot",
            savedLighting);
    lightingSnapshots.publish(*restored);
}

void Service::Threads::keepLighting(const LiveLighting& lit, Clock::time_point& lastSaved) {
    const Clock::time_point now = Clock::now();
    if (savedLighting.empty() || (lastSaved != Clock::time_point{} && now - lastSaved < kSaveEvery))
        return;
    if (Status s = saveLighting(lit, savedLighting); !s && lastSaved == Clock::time_point{})
        logWarning("lighting: {} (the next start lights with the studio environment)", s.message());
    lastSaved = now;
}

void Service::Threads::noteBrackets(const LiveLighting* snapshot) {
    const BracketCounts* counts = lighting->bracketCounts();
    if (!counts) return;
    std::lock_guard lock(statusMutex);
    if ((brackets ? brackets->dropped() : 0) == 0 && counts->dropped() > 0)
        logWarning("lighting: a fisheye bracket was dropped: {} (further drops are counted)",
                   lighting->lastBracketDrop());
    brackets = *counts;
    lastBracketDrop = lighting->lastBracketDrop();
    if (snapshot) clippedSolidAngleFraction = snapshot->clippedSolidAngleFraction;
}

void Service::Threads::runLighting() {
    nameThread("pv-lighting");
    restoreLighting();
    uint64_t failures = 0;
    Clock::time_point lastSaved{};
    while (!stopping.load()) {
        std::shared_ptr<const Frame> frame =
            fisheyeCamera->frames().waitTakeFor(std::chrono::milliseconds(100));
        if (!frame || !lighting->due(*frame)) continue;
        StageStep busy(&lightingStage);
        Result<std::shared_ptr<const LiveLighting>> lit = lighting->process(*frame);
        if (!lit) {
            if (failures++ == 0)
                logWarning("lighting: fisheye frame {}: {} (further failures are counted)",
                           frame->sequence, lit.message());
            continue;
        }
        noteBrackets(lit->get());
        if (!*lit) continue;  // a bracket in progress, or dropped (counted)
        lightingMs.store((*lit)->computeMs);
        recorder->addLighting(*lit);
        lightingSnapshots.publish(*lit);
        lightingUpdates.fetch_add(1);
        keepLighting(**lit, lastSaved);
    }
}

void Service::Threads::publish(PipelineRenderer& r, const TrackedFrame& frame, Mode mode,
                               Clock::time_point renderStart, double fps,
                               std::optional<double> noiseEstimate,
                               std::optional<double> etaSeconds) {
    Result<DisplayImage> image = r.display(noiseEstimate);
    if (!image) {
        logError("render: {}", image.message());
        return;
    }
    auto out = std::make_shared<DisplayFrame>();
    out->width = image->width;
    out->height = image->height;
    out->rgb = std::move(image->rgb);
    const double renderMs =
        std::chrono::duration<double, std::milli>(Clock::now() - renderStart).count();
    // The display thread's clock is CLOCK_MONOTONIC, as a live camera's timestamps.
    out->captureTimestampNs = captureInstantNs(frame, monotonicNowNs());
    ServiceStatus s;
    {
        std::lock_guard lock(statusMutex);
        renderStatus.mode = mode;
        renderStatus.samples = r.samples();
        renderStatus.noiseEstimate = noiseEstimate;
        renderStatus.etaSeconds = etaSeconds;
        renderStatus.renderMs = renderMs;
        renderStatus.fps = fps;
        renderStatus.worldFromCamera = frame.worldFromCamera;
        renderStatus.tags = frame.tags;
        renderStatus.trackingLost = frame.lost;
        renderStatus.trackMs = frame.trackMs;
        renderStatus.timecode = frame.timecode;
        renderStatus.deviceBytes = r.deviceBytes();
        // What the shown frame used: a preview frame's budget and radius, not refinement's.
        renderStatus.photonsPerIteration = r.lastPhotonCount();
        renderStatus.photonRadiusM = r.lastPhotonRadius();
        renderStatus.lightingPending = r.lightingPending();
        renderStatus.previewHistoryFrames = mode == Mode::Preview ? r.previewHistoryFrames() : 0;
        renderStatus.heldViewFrames = mode == Mode::Preview ? r.heldViewFrames() : 0;
        out->index = renderStatus.framesRendered++;
        s = renderStatus;
    }
    out->status = statusLine(s);
    if (web) web->submitFrame(webFrameOf(std::shared_ptr<const DisplayFrame>(out)));
    display->submit(std::move(out));
}

void Service::Threads::publishNoCamera(const PipelineRenderer& r) {
    auto out = std::make_shared<DisplayFrame>();
    out->width = r.width();
    out->height = r.height();
    out->rgb.assign(size_t(out->width) * out->height * 3, 0);
    const CaptureStats camera = sceneCamera->stats();
    out->status = fmt::format("NO CAMERA: {} is {}{}", sceneCamera->name(), toString(camera.state),
                              camera.problem.empty() ? "" : ": " + camera.problem);
    {
        std::lock_guard lock(statusMutex);
        out->index = renderStatus.framesRendered++;
    }
    display->submit(std::move(out));
}

void Service::Threads::runRender(ModeMachine& modes) {
    nameThread("pv-render");
    PipelineRenderer& r = *renderer;
    const SteadyShotClock clock;
    ShotController shot(r, modes, clock, live.refine);
    Clock::time_point lastPublished = Clock::now();
    while (!stopping.load()) {
        // One step a pass: its waits are bounded (kRenderPoll); a compile extends it
        // (GpuContext::setStage).
        StageStep pass(&renderStage);
        {
            std::lock_guard lock(settingsMutex);
            if (std::exchange(liveReloaded, false)) shot.setConfig(live);
        }
        std::shared_ptr<const TrackedFrame> frame =
            shot.wantsFrame() ? trackedFrames.waitTakeFor(kRenderPoll) : trackedFrames.take();
        Result<ShotStep> step = shot.step(std::move(frame), lightingSnapshots.latest());
        if (!step) {
            if (stopping.load()) return;  // the stop interrupted the GPU pass
            logError("render: {}", step.message());
            pipelineFailed.store(true);
            return;
        }
        {
            std::lock_guard lock(statusMutex);
            renderStatus.refineRestarts = shot.restarts();
            if (step->plateConsistency) renderStatus.plateConsistency = step->plateConsistency;
            if (step->lightingFit) renderStatus.lightingFit = step->lightingFit;
        }
        if (step->plateConsistency) recorder->addPlateConsistency(*step->plateConsistency);
        switch (step->kind) {
            case ShotStep::Kind::NoFrame:
                // A camera that delivers nothing (unplugged, never opened) must not leave the
                // monitor frozen on an old picture: say so on a black frame, once a second.
                if (step->mode == Mode::Preview && Clock::now() - lastPublished > kNoCameraAfter) {
                    publishNoCamera(r);
                    lastPublished = Clock::now();
                }
                break;
            case ShotStep::Kind::Held:
                // Converged (or nothing to refine): idle until the mode changes.
                std::this_thread::sleep_for(kRenderPoll);
                break;
            case ShotStep::Kind::Previewed:
            case ShotStep::Kind::Refined:
                lastPublished = Clock::now();
                publish(r, *step->shown, step->mode, step->start, step->fps, step->noiseEstimate,
                        step->etaSeconds);
                if (step->kind == ShotStep::Kind::Previewed)
                    shot.previewShown(
                        std::chrono::duration<double>(Clock::now() - step->start).count());
                break;
        }
    }
}

void Service::Threads::stopAll() {
    control.reset();
    web.reset();                   // its hooks call into the service
    if (freedIn) freedIn->stop();  // it writes into the take
    button.reset();
    // A take ends complete and durable before anything else stops (SIGTERM mid-take).
    if (recorder && recorder->recording()) {
        Result<std::string> take = recorder->stop();
        if (!take) logError("recording: {}", take.message());
    }
    stopping.store(true);
    trackedFrames.wakeAll();
    // Each thread finishes the step it is in (a frame's samples, a tag detection, a lighting
    // estimate); one that holds the stop up is named, so a slow stop says where it waited.
    const std::pair<std::thread*, const char*> workers[] = {
        {&renderThread, "render"}, {&trackingThread, "tracking"}, {&lightingThread, "lighting"}};
    for (auto [thread, name] : workers) {
        if (!thread->joinable()) continue;
        const Clock::time_point start = Clock::now();
        thread->join();
        const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
        if (seconds > 1.0)
            logInfo("stop: the {} thread took {:.1f} s to finish its step", name, seconds);
    }
    if (sceneCamera) sceneCamera->stop();
    if (fisheyeCamera) fisheyeCamera->stop();
    if (display) display->stop();
    if (led) led->set(false);
}

}  // namespace previs
