#include "daemon/service.h"

#include <poll.h>
#include <pthread.h>
#include <signal.h>
#include <sys/eventfd.h>
#include <sys/resource.h>
#include <sys/signalfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "base/guarded_thread.h"
#include "base/latest_value_slot.h"
#include "base/log.h"
#include "base/monotonic_clock.h"
#include "base/unique_fd.h"
#include "daemon/camera_sources.h"
#include "daemon/control_server.h"
#include "daemon/memory_budget.h"
#include "daemon/pipeline_renderer.h"
#include "daemon/pipeline_stages.h"
#include "daemon/recorded_events.h"
#include "daemon/refine_watch.h"
#include "daemon/shot_controller.h"
#include "display/display_thread.h"
#include "display/frame_output.h"
#include "gpu/context.h"
#include "io/gpio_button.h"
#include "io/status_led.h"
#include "scene/scene_description.h"
#include "systemd/listen_fds.h"
#include "systemd/notify.h"

namespace previs {

namespace {

using Clock = std::chrono::steady_clock;

// How long the render thread waits for a frame before it checks the mode (and ends its step).
constexpr auto kRenderPoll = std::chrono::milliseconds(100);
// Without systemd's watchdog a thread this long in one step is logged as stuck.
constexpr int64_t kStuckWithoutWatchdogNs = 30'000'000'000;

// Logs each stage that became stuck (once, until it recovers) and says whether the watchdog may
// be fed: only when no stage is stuck.
bool reportStuckStages(const std::vector<StageWatch::Stuck>& stuck,
                       std::vector<std::string>& reported, bool underWatchdog) {
    std::vector<std::string> now;
    for (const StageWatch::Stuck& s : stuck) {
        now.push_back(s.name);
        if (std::find(reported.begin(), reported.end(), s.name) != reported.end()) continue;
        logError("watchdog: the {} thread has been in one step for {:.0f} s{}", s.name, s.seconds,
                 underWatchdog ? "; no longer feeding systemd's watchdog, which restarts previsd"
                               : " (no systemd watchdog: previsd goes on without it)");
    }
    for (const std::string& name : reported)
        if (std::find(now.begin(), now.end(), name) == now.end())
            logInfo("watchdog: the {} thread is going again", name);
    reported = std::move(now);
    return stuck.empty();
}

// Names show in top -H, perf and /proc/PID/task/*/comm (15 characters at most).
void nameThread(const char* name) { pthread_setname_np(pthread_self(), name); }

// Without camera frames for this long, the display says so instead of holding the last picture.
constexpr auto kNoCameraAfter = std::chrono::seconds(2);

OutputSettings outputSettings(const OutputConfig& c) {
    OutputSettings s;
    s.kind = toString(c.kind);
    s.folder = c.folder;
    s.card = c.card;
    s.connector = c.connector;
    s.mode = c.mode;
    s.files = {
        .keepFrames = c.keepFrames, .maxBytes = c.maxMb << 20, .minFreeBytes = c.minFreeMb << 20};
    return s;
}

// "12 s", "4.5 min", "2.1 h": an ETA at the precision it has.
std::string etaText(double seconds) {
    if (seconds < 59.5) return fmt::format("{:.0f} s", seconds);
    if (seconds < 3600.0) return fmt::format("{:.1f} min", seconds / 60.0);
    return fmt::format("{:.1f} h", seconds / 3600.0);
}

}  // namespace

std::string statusLine(const ServiceStatus& s) {
    if (s.state == "starting") return "STARTING: " + s.starting;
    std::string line =
        fmt::format("{} {} spp ", s.mode == Mode::Refine ? "REFINE" : "PREVIEW", s.samples);
    if (s.mode == Mode::Refine && s.noiseEstimate)
        line += fmt::format("noise {:.1f}% ", *s.noiseEstimate * 100.0);
    if (s.mode == Mode::Refine && s.etaSeconds) line += "ETA " + etaText(*s.etaSeconds) + " ";
    line += fmt::format("{:.1f} fps", s.fps);
    if (s.photonsPerIteration > 0)
        line += fmt::format("  {}K photons r {:.1f} mm", (s.photonsPerIteration + 512) / 1024,
                            s.photonRadiusM * 1e3f);
    if (s.mode == Mode::Preview && s.previewHistoryFrames > 1)
        line += fmt::format(" x{}", s.previewHistoryFrames);
    if (s.trackingLost) line += s.worldFromCamera ? "  TRACKING LOST (holding)" : "  NO TRACKING";
    if (s.lightingPending) line += "  LIGHTING PENDING";
    // The lighting does not explain the plate (DESIGN.md §4): render / plate per channel.
    if (s.plateConsistency && !s.plateConsistency->value.ok) {
        const auto& r = s.plateConsistency->value.ratio;
        line += fmt::format("  LIGHTING OFF x{:.2f} {:.2f} {:.2f}", r[0], r[1], r[2]);
    }
    if (!s.fisheyeCameraProblem.empty()) line += "  FISHEYE CAMERA LOST";
    if (s.button == "absent") line += "  NO BUTTON";
    if (s.led == "absent") line += "  NO LED";
    if (s.record.recording)
        line +=
            fmt::format("  REC {} {:.0f} MiB", s.record.frames, double(s.record.bytes) / (1 << 20));
    else if (!s.record.stoppedBecause.empty())
        line += "  REC STOPPED";
    return line;
}

namespace {

// The lighting fit's last report (docs/previsd.md, "lightingFit").
nlohmann::json lightingFitJson(const std::optional<LightingFitReport>& fit) {
    if (!fit) return nullptr;
    nlohmann::json j = {{"state", toString(fit->state)}, {"frame", fit->frame}};
    if (fit->state == LightingFitReport::State::Failed) j["why"] = fit->why;
    if (fit->state == LightingFitReport::State::Fitted) {
        j["clusterGains"] = fit->fit.clusterGains;
        j["globalGain"] = fit->fit.globalGain;
        j["residual"] = {fit->fit.residualBefore, fit->fit.residualAfter};
        j["samples"] = fit->fit.samples;
    }
    return j;
}

// The plate-consistency meter's last reading (docs/previsd.md, "plateConsistency").
nlohmann::json plateConsistencyJson(const std::optional<PlateConsistencyReading>& reading) {
    if (!reading) return nullptr;
    const PlateConsistency& v = reading->value;
    auto rounded = [](const std::array<double, 3>& a) {
        nlohmann::json j = nlohmann::json::array();
        for (double x : a) j.push_back(std::round(x * 1e4) / 1e4);
        return j;
    };
    return {{"ratio", rounded(v.ratio)},
            {"spread", rounded(v.spread)},
            {"pixels", v.pixels},
            {"resolution", {v.gridWidth, v.gridHeight}},
            {"ok", v.ok},
            {"range", {kPlateConsistencyLow, kPlateConsistencyHigh}},
            {"frame", reading->frame}};
}

// The last tracked frame's timecode and where it came from (docs/timecode.md).
nlohmann::json timecodeJson(const std::optional<Timecode>& value, const TimecodeStatus& t) {
    nlohmann::json j = {{"value", value ? nlohmann::json(value->toString()) : nullptr},
                        {"rate", value ? value->rate().toString() : t.rate.toString()},
                        {"source", toString(t.source)},
                        {"state", toString(t.state)}};
    if (t.source == TimecodeSourceKind::Ltc)
        j["ltc"] = {{"decoded", t.ltc.decoded},
                    {"rejected", t.ltc.rejected},
                    {"dropouts", t.dropouts},
                    {"jams", t.jams},
                    {"lastLtc", t.lastLtc ? nlohmann::json(t.lastLtc->toString()) : nullptr}};
    return j;
}

nlohmann::json trackingOutJson(const TrackingOutStats& s) {
    nlohmann::json j = {{"lostNotSent", s.lostNotSent},
                        {"dropped", s.dropped},
                        {"failed", s.failed},
                        {"delayMs",
                         {{"last", std::round(s.lastDelayMs * 100.0) / 100.0},
                          {"max", std::round(s.maxDelayMs * 100.0) / 100.0}}}};
    j["freed"] = s.freed ? nlohmann::json{{"packets", s.freedPackets},
                                          {"held", s.freedHeld},
                                          {"clamped", s.freedClamped}}
                         : nlohmann::json(nullptr);
    j["opentrackio"] = s.openTrackIo ? nlohmann::json{{"samples", s.openTrackIoSamples},
                                                      {"datagrams", s.openTrackIoDatagrams}}
                                     : nlohmann::json(nullptr);
    return j;
}

// FreeD in: packets accepted and refused by why (bad input is counted, never applied).
nlohmann::json freedInJson(const FreedInputStats& s) {
    nlohmann::json rejected = nlohmann::json::object();
    for (size_t i = 1; i < s.rejected.size(); ++i)
        rejected[freedErrorName(FreedError(i))] = s.rejected[i];
    return {{"packets", s.packets}, {"rejected", rejected}, {"calibrated", s.calibrated}};
}

}  // namespace

std::string statusJson(const ServiceStatus& s) {
    nlohmann::json j;
    j["state"] = s.state;
    j["starting"] = s.starting.empty() ? nlohmann::json(nullptr) : nlohmann::json(s.starting);
    j["mode"] = toString(s.mode);
    j["framesShown"] = s.framesShown;
    j["framesDropped"] = s.framesDropped;
    j["drops"] = {
        {"capture", s.droppedCapture}, {"render", s.droppedRender}, {"display", s.droppedDisplay}};
    j["samples"] = s.samples;
    auto number = [](std::optional<double> v, double scale) {
        return v ? nlohmann::json(std::round(*v * scale) / scale) : nlohmann::json(nullptr);
    };
    j["noiseEstimate"] = number(s.noiseEstimate, 1e6);
    j["etaSeconds"] = number(s.etaSeconds, 10.0);
    j["refineRestarts"] = s.refineRestarts;
    j["fps"] = std::round(s.fps * 100.0) / 100.0;
    j["recording"] = s.record.recording;
    if (s.record.recording || !s.record.stoppedBecause.empty()) {
        nlohmann::json r = {{"path", s.record.path},
                            {"frames", s.record.frames},
                            {"dropped", s.record.dropped},
                            {"bytes", s.record.bytes},
                            {"freeBytes", s.record.freeBytes},
                            {"seconds", std::round(s.record.seconds * 10.0) / 10.0}};
        r["freedDropped"] = s.record.freedDropped;  // FreeD packets left out (issue 52)
        if (!s.record.stoppedBecause.empty()) r["stoppedBecause"] = s.record.stoppedBecause;
        j["record"] = r;
    } else {
        j["record"] = nullptr;
    }
    j["display"] = s.display;
    if (s.worldFromCamera) {
        nlohmann::json m = nlohmann::json::array();
        for (int r = 0; r < 4; ++r)
            for (int c = 0; c < 4; ++c) m.push_back((*s.worldFromCamera)(r, c));
        j["pose"] = {{"worldFromCamera", m}, {"tags", s.tags}, {"lost", s.trackingLost}};
    } else {
        j["pose"] = nullptr;
    }
    j["uptimeSeconds"] = std::round(s.uptimeSeconds * 10.0) / 10.0;
    j["renderMs"] = std::round(s.renderMs * 10.0) / 10.0;
    j["trackMs"] = std::round(s.trackMs * 10.0) / 10.0;
    j["lightingMs"] = std::round(s.lightingMs * 10.0) / 10.0;
    j["latencyMs"] = std::round(s.latencyMs * 10.0) / 10.0;
    j["deviceBytes"] = s.deviceBytes;
    if (s.photonsPerIteration > 0)
        j["photons"] = {{"perIteration", s.photonsPerIteration}, {"radiusM", s.photonRadiusM}};
    else
        j["photons"] = nullptr;
    j["cameras"] = {{"scene", s.sceneCamera}, {"fisheye", s.fisheyeCamera}};
    // Why a camera is lost (absent, busy, a control that did not apply); empty while streaming.
    j["cameraProblems"] = {{"scene", s.sceneCameraProblem}, {"fisheye", s.fisheyeCameraProblem}};
    j["lightingUpdates"] = s.lightingUpdates;
    j["lightingPending"] = s.lightingPending;
    if (s.brackets) {
        const BracketCounts& b = *s.brackets;
        j["lightCapture"] = {{"bracketsMerged", b.merged},
                             {"bracketsDropped",
                              {{"unlabelled", b.droppedUnlabelled},
                               {"wrongExposure", b.droppedWrongExposure},
                               {"missing", b.droppedMissing},
                               {"mismatch", b.droppedMismatch}}},
                             {"pairsUnchecked", b.unchecked},
                             {"lastDrop", s.lastBracketDrop},
                             {"framesWithheld", s.bracketFramesWithheld},
                             {"clippedSolidAngleFraction", s.clippedSolidAngleFraction}};
    } else {
        j["lightCapture"] = nullptr;
    }
    j["previewHistoryFrames"] = s.previewHistoryFrames;
    j["heldViewFrames"] = s.heldViewFrames;
    // Frames that gave no trusted pose, counted by why (vision/board_pose.h LostReason).
    nlohmann::json lost = nlohmann::json::object();
    for (int i = 1; i < kLostReasonCount; ++i)
        lost[toString(LostReason(i))] = s.trackingLostFrames[size_t(i)];
    j["trackingLost"] = lost;
    j["button"] = s.button;
    j["led"] = s.led;
    j["timecode"] = timecodeJson(s.timecode, s.timecodeStatus);
    j["trackingOut"] = s.trackingOut ? trackingOutJson(*s.trackingOut) : nlohmann::json(nullptr);
    j["web"] = s.web ? toJson(*s.web) : nlohmann::json(nullptr);
    j["freedIn"] = s.freedIn ? freedInJson(*s.freedIn) : nlohmann::json(nullptr);
    j["plateConsistency"] = plateConsistencyJson(s.plateConsistency);
    j["lightingFit"] = lightingFitJson(s.lightingFit);
    // A camera's name may hold any bytes: invalid UTF-8 becomes U+FFFD, never a throw.
    return j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

uint64_t raiseOpenFileLimit() {
    rlimit limit{};
    if (::getrlimit(RLIMIT_NOFILE, &limit) != 0) return 0;
    if (limit.rlim_cur < limit.rlim_max) {
        rlimit raised = limit;
        raised.rlim_cur = limit.rlim_max;
        if (::setrlimit(RLIMIT_NOFILE, &raised) == 0) limit = raised;
    }
    if (limit.rlim_cur < kWantedOpenFiles)
        logWarning(
            "descriptors: previsd may open only {} files (hard limit {}); the web's clients could "
            "leave the cameras and a take without: raise it to {} (LimitNOFILE= in the unit, "
            "ulimit -Hn in a shell)",
            uint64_t(limit.rlim_cur), uint64_t(limit.rlim_max), kWantedOpenFiles);
    return limit.rlim_cur;
}

void blockServiceSignals() {
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGTERM);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGHUP);
    pthread_sigmask(SIG_BLOCK, &set, nullptr);
}

// Everything with a thread, in the order it is stopped (reverse of declaration is destruction).
struct Service::Threads {
    // Each thread's steps (base/stage_watch.h), read by run() before it feeds the watchdog; first,
    // so it outlives every thread that marks it.
    StageWatch watch;
    Stage& renderStage = watch.add("render");
    Stage& trackingStage = watch.add("tracking");
    Stage& lightingStage = watch.add("lighting");
    Stage& displayStage = watch.add("display");
    Stage& sceneCaptureStage = watch.add("scene camera");
    Stage& fisheyeCaptureStage = watch.add("fisheye camera");

    std::unique_ptr<GpuContext> gpu;
    std::unique_ptr<PipelineRenderer> renderer;
    std::optional<TrackingStage> tracking;
    std::optional<LightingStage> lighting;

    std::unique_ptr<CameraSource> sceneCamera;
    std::unique_ptr<CameraSource> fisheyeCamera;
    LatestValueSlot<TrackedFrame> trackedFrames;
    LatestValueSlot<LiveLighting> lightingSnapshots;
    std::unique_ptr<DisplayThread> display;
    std::unique_ptr<GpioButton> button;
    std::unique_ptr<StatusLed> led;  // thread-safe; made before any thread that switches it
    std::unique_ptr<ControlServer> control;
    std::unique_ptr<TakeRecorder> recorder;
    // The set's network (issue 39): every frame's timecode (and the LTC input feeding it), the
    // tracking packets, the browser monitor. The last two are null unless configured.
    systemd::ListenFds passedSockets;
    std::shared_ptr<FreedInput> freedIn;
    std::unique_ptr<TimecodeSource> timecode;
    std::unique_ptr<AlsaCapture> ltcInput;
    std::unique_ptr<TrackingOut> trackingOut;
    std::unique_ptr<WebMonitor> web;
    // A recorded scene camera's button and ctl events, fired as its frames arrive.
    std::optional<RecordedEvents> recordedEvents;
    std::function<void(const SessionEvent&)> applyEvent;

    UniqueFD stopEvent{::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK)};
    std::atomic<bool> stopping{false};
    std::atomic<uint64_t> droppedRender{0};
    // Frames tracking gave no trusted pose, by LostReason (status "trackingLost").
    std::array<std::atomic<uint64_t>, kLostReasonCount> lostFrames{};
    std::atomic<uint64_t> lightingUpdates{0};
    // The lighting thread's part of the status (under statusMutex).
    std::optional<BracketCounts> brackets;
    std::string lastBracketDrop;
    double clippedSolidAngleFraction = 0.0;
    void noteBrackets(const LiveLighting* snapshot);
    // Set by a stage thread that cannot go on (its reason logged); run() then exits 1 so that
    // systemd restarts the service.
    std::atomic<bool> pipelineFailed{false};
    void stageFailed(const std::string&) { pipelineFailed.store(true); }

    // Settings SIGHUP may change while running.
    std::mutex settingsMutex;
    RefineConfig refine;
    uint32_t previewSamples = 1;

    // The render thread's part of the status.
    mutable std::mutex statusMutex;
    ServiceStatus renderStatus;

    std::thread trackingThread, lightingThread, renderThread;

    void runTracking(const ModeMachine& modes);
    std::optional<Timecode> frameTimecode(const Frame& frame) const;
    Status openTimecode(const ServiceConfig& config);
    Status openWeb(const WebConfig& web, Service* service);
    void runLighting();
    // [lighting] saved (savedLightingPath; empty: off): read at start, so the virtual objects
    // are lit by the set as last seen until the first snapshot, and kept from the first snapshot
    // on, at most every kSaveEvery (a room's light changes slowly; a box's flash wears).
    std::string savedLighting;
    static constexpr std::chrono::seconds kSaveEvery{60};
    void restoreLighting();
    void keepLighting(const LiveLighting& lit, Clock::time_point& lastSaved);
    void runRender(ModeMachine& modes);
    std::atomic<double> lightingMs{0.0};
    // Sends the composite to the display; renderMs runs from `renderStart` to the tone-mapped
    // frame (render, readback, tone map).
    void publish(PipelineRenderer& r, const TrackedFrame& frame, Mode mode,
                 Clock::time_point renderStart, double fps,
                 std::optional<double> noiseEstimate = {}, std::optional<double> etaSeconds = {});
    void publishNoCamera(const PipelineRenderer& r);
    void stopAll();
};

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
    // A camera without an fps: its rate measured on its frames (issue 54), not a guessed 30.
    source.rate = config.sceneCamera.fps > 0.0
                      ? std::optional(TimecodeRate::fromFps(config.sceneCamera.fps))
                      : std::nullopt;
    if (!c.rate.empty()) {
        Result<TimecodeRate> rate = TimecodeRate::parse(c.rate);
        if (!rate) return makeError("[timecode] rate: {}", rate.message());
        source.rate = *rate;
        source.ltcRate = *rate;
    }
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
        renderStatus.deviceBytes = r.renderer().deviceBytes();
        const bool photons = r.renderer().photonsActive();
        // What the shown frame used: a preview frame's budget and radius, not refinement's.
        renderStatus.photonsPerIteration = photons ? r.renderer().lastPhotonCount() : 0;
        renderStatus.photonRadiusM = photons ? r.renderer().lastPhotonRadius() : 0.0f;
        renderStatus.lightingPending = r.lightingPending();
        renderStatus.previewHistoryFrames = mode == Mode::Preview ? r.previewHistoryFrames() : 0;
        renderStatus.heldViewFrames = mode == Mode::Preview ? r.renderer().heldViewFrames() : 0;
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
    ShotController shot(r, modes, clock, refine);
    Clock::time_point lastPublished = Clock::now();
    while (!stopping.load()) {
        // One step a pass: its waits are bounded (kRenderPoll); a compile extends it
        // (GpuContext::setStage).
        StageStep pass(&renderStage);
        {
            std::lock_guard lock(settingsMutex);
            shot.setConfig(refine, previewSamples);
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

Service::Service(ServiceConfig config)
    : config_(std::move(config)), threads_(std::make_unique<Threads>()), started_(Clock::now()) {}

Service::~Service() {
    if (threads_) threads_->stopAll();
}

Result<std::unique_ptr<Service>> Service::open(const ServiceConfig& config, bool* userError) {
    // The control socket and the port are the config's (exit 2): checked before any slow work,
    // so a second previsd on them is refused at once.
    if (userError) *userError = true;
    std::unique_ptr<Service> service(new Service(config));
    Threads& t = *service->threads_;
    Service* self = service.get();
    service->stopFd_ = t.stopEvent.get();
    // Under systemd with the network units the sockets come made (docs/systemd.md).
    t.passedSockets = systemd::ListenFds::fromEnvironment();
    Result<std::unique_ptr<ControlServer>> control = ControlServer::create(
        controlSocketPath(config.control),
        [self](const std::string& command) { return self->handleCommand(command); });
    if (!control) return control.error();
    t.control = std::move(*control);
    if (Status st = t.openWeb(config.network.web, self); !st) return st.error();
    if (userError) *userError = false;
    logInfo("serving {} (control socket {}); starting", config.path, t.control->path());
    return service;
}

Result<std::unique_ptr<Service>> Service::create(const ServiceConfig& config, bool* userError) {
    Result<std::unique_ptr<Service>> service = open(config, userError);
    if (!service) return service;
    if (Status s = (*service)->start(userError); !s) return s.error();
    return service;
}

bool Service::beginStartStage(const std::string& what, size_t steps) {
    if (threads_->stopping.load()) return false;
    {
        std::lock_guard lock(startMutex_);
        startStage_ = what;
        startStageSince_ = Clock::now();
        startStepsDone_ = 0;
        startSteps_ = steps;
    }
    logInfo("starting: {} ...", what);
    systemd::notifyStatus("starting: " + what);
    return true;
}

std::string Service::startingNow() const {
    std::string stage;
    Clock::time_point since;
    size_t done = 0;
    size_t steps = 0;
    {
        std::lock_guard lock(startMutex_);
        stage = startStage_;
        since = startStageSince_;
        done = startStepsDone_;
        steps = startSteps_;
    }
    // The GPU context counts its compiles on the render stage (base/stage_watch.h).
    if (stage == PipelineStartHooks::kCompilingStage)
        return fmt::format("{}: {} done", stage, threads_->renderStage.longerSteps());
    // A stage that counts its steps (the dial's settings) says how far it is.
    if (steps > 0) stage = fmt::format("{}: {}/{}", stage, done, steps);
    const double seconds = std::chrono::duration<double>(Clock::now() - since).count();
    if (seconds >= 2.0) return fmt::format("{}, {:.0f} s so far", stage, seconds);
    return stage;
}

Status Service::start(bool* userError) {
    // Most failures here are the config's (a scene, a connector, a GPIO line): exit 2, which
    // systemd does not restart. The GPU and the cameras' threads are runtime's.
    bool ignored = false;
    bool& configError = userError ? *userError : ignored;
    const ServiceConfig& config = config_;
    const Error stopped = makeError("stopped while starting");
    configError = true;
    Threads& t = *threads_;
    t.refine = config.refine;
    t.previewSamples = config.render.samplesPerFrame;

    if (!beginStartStage("loading the scene " + config.scenePath)) return stopped;
    Result<Scene> scene = loadScene(config.scenePath);
    if (!scene) return scene.error();
    // What would cross MemoryMax= is refused now, not found by the OOM killer mid-take.
    if (Status s = checkMemoryBudget(*scene, config, cgroupMemoryLimit()); !s) return s.error();
    configError = false;
    if (!beginStartStage("opening the GPU")) return stopped;
    Result<std::unique_ptr<GpuContext>> gpu = GpuContext::create({});
    if (!gpu) return gpu.error();
    t.gpu = std::move(*gpu);
    // From the first compile on: a compile extends the step (GpuContext::setStage), and the
    // start's status counts them.
    t.gpu->setStage(&t.renderStage);
    // A renderer that cannot be made (device memory, a driver's compile) may be made after a
    // restart: not exit 2. A stop must not wait for a whole frame on a slow device (lavapipe on
    // a slow CPU), nor for the dial's timings while starting.
    PipelineStartHooks hooks;
    hooks.stage = [this](const std::string& what, size_t steps) { beginStartStage(what, steps); };
    hooks.progress = [this](size_t done, size_t) {
        std::lock_guard lock(startMutex_);
        startStepsDone_ = std::min(done, startSteps_);
    };
    hooks.interrupt = &t.stopping;
    Result<std::unique_ptr<PipelineRenderer>> renderer =
        PipelineRenderer::create(*t.gpu, *scene, config, hooks);
    if (t.stopping.load()) return stopped;
    if (!renderer) return renderer.error();
    t.renderer = std::move(*renderer);
    configError = true;
    // With [render] preview_fps the dial chose the preview's samples (PipelineRenderer).
    t.previewSamples = t.renderer->previewSamples();
    logInfo("render: {}x{} on {}, {} spp per preview frame", t.renderer->width(),
            t.renderer->height(), t.gpu->deviceName(), t.previewSamples);
    if (Status s = startStages(configError); !s) return s;
    if (Status s = startThreads(configError); !s) return s;
    // Everything status() and the commands read exists from here on.
    running_.store(true, std::memory_order_release);
    logInfo("running: started in {:.1f} s",
            std::chrono::duration<double>(Clock::now() - started_).count());
    // [record] auto: a box that cannot record says so, and still previews.
    if (config.record.autoStart)
        if (Result<std::string> take = startRecording(""); !take)
            logError("recording: [record] auto: {}", take.message());
    return {};
}

Status Service::startStages(bool& configError) {
    const ServiceConfig& config = config_;
    Threads& t = *threads_;
    const Error stopped = makeError("stopped while starting");
    if (!beginStartStage("opening the tracking and the network")) return stopped;
    // FreeD in: received whenever [tracking] listen is set (a take records the packets, for
    // `previs freed-calibrate`); the pose with source = "freed".
    t.recorder = std::make_unique<TakeRecorder>(config);
    if (!config.tracking.freedListen.empty()) {
        TakeRecorder* recorder = t.recorder.get();
        Result<std::unique_ptr<FreedInput>> freed =
            FreedInput::listen(config.tracking, t.passedSockets.take("freed-in"),
                               [recorder](int64_t receivedNs, std::span<const uint8_t> datagram) {
                                   recorder->addFreedPacket(receivedNs, datagram);
                               });
        if (!freed) return freed.error();
        t.freedIn = std::move(*freed);
    }
    Result<TrackingStage> tracking = TrackingStage::create(config, t.freedIn);
    if (!tracking) return tracking.error();
    t.tracking.emplace(std::move(*tracking));
    if (config.fisheyeCamera) {
        if (!beginStartStage("preparing the lighting")) return stopped;
        Result<LightingStage> lighting = LightingStage::create(config);
        if (!lighting) return lighting.error();
        t.lighting.emplace(std::move(*lighting));
        t.savedLighting = savedLightingPath(config.lighting);
    }

    if (!beginStartStage(fmt::format("opening the display ({})", toString(config.output.kind))))
        return stopped;
    Result<std::unique_ptr<FrameOutput>> output = makeFrameOutput(outputSettings(config.output));
    if (!output) return output.error();
    t.display = std::make_unique<DisplayThread>(std::move(*output), &t.displayStage);

    if (config.button) {
        if (!beginStartStage("opening the button")) return stopped;
        if (Status s = openButton(*config.button); !s) return s;
    }

    if (config.sceneCamera.source == CameraSourceKind::Session && config.replaySessionEvents) {
        Result<std::optional<RecordedEvents>> events =
            RecordedEvents::load(config.sceneCamera.device);
        if (!events) return events.error();
        if (*events) {
            t.recordedEvents = std::move(**events);
            t.applyEvent = [this](const SessionEvent& e) { applyRecordedEvent(e); };
            logInfo("{} recorded button/ctl event(s) replay with the session",
                    t.recordedEvents->size());
        }
    }

    // The timecode and the tracking packets before the cameras: every frame has them.
    if (Status st = t.openTimecode(config); !st) return st.error();
    Result<std::unique_ptr<TrackingOut>> trackingOut =
        TrackingOut::create(config.network, config.sceneCamera, t.passedSockets);
    if (!trackingOut) return trackingOut.error();
    t.trackingOut = std::move(*trackingOut);
    configError = false;
    return {};
}

Status Service::openButton(const ButtonConfig& b) {
    Threads& t = *threads_;
    // The LED before the button: the button's thread switches it from its first press. Either
    // may be absent at start (a chip not probed yet, udev's rule not applied): they start
    // without it and keep looking (io/gpio_button.h); only a wrong line is exit 2.
    if (!b.ledLine.empty()) {
        Result<std::unique_ptr<StatusLed>> led =
            StatusLed::create(b.ledChip, b.ledLine, b.ledActiveLow);
        if (!led) return led.error();
        t.led = std::move(*led);
    }
    ButtonSettings settings;
    settings.chip = b.chip;
    settings.line = b.line;
    settings.activeLow = b.activeLow;
    settings.debounceMs = b.debounceMs;
    settings.longPressMs = b.longPressMs;
    Result<std::unique_ptr<GpioButton>> button =
        GpioButton::create(settings, [this](ButtonEvent e) {
            if (e == ButtonEvent::ShortPress) {
                recordEvent("mode-button", "short-press");
                modes_.toggle("button");
                updateLed();
                return;
            }
            recordEvent("mode-button", "long-press");
            const bool rolling = threads_->recorder->recording();
            Result<std::string> take = rolling ? stopRecording() : startRecording("");
            if (!take) logError("button: long press: {}", take.message());
        });
    if (!button) return button.error();
    t.button = std::move(*button);
    return {};
}

Status Service::startThreads(bool& configError) {
    const ServiceConfig& config = config_;
    Threads& t = *threads_;
    if (!beginStartStage("opening the cameras")) return makeError("stopped while starting");
    // Cameras: once they stream, frames flow into the stages (and into a take while one rolls).
    configError = false;
    t.recorder->setTimecodeSource(t.timecode.get());
    TakeRecorder* recorder = t.recorder.get();
    t.sceneCamera = makeCameraSource(
        config.sceneCamera, config.loopSession,
        [recorder](const std::shared_ptr<const Frame>& f) { recorder->addFrame("scene", f); },
        recorder->keepCapturedFlag(), &t.sceneCaptureStage);
    if (Status s = t.sceneCamera->start(); !s) return s.error();
    if (config.fisheyeCamera) {
        t.fisheyeCamera = makeCameraSource(
            *config.fisheyeCamera, config.loopSession,
            [recorder](const std::shared_ptr<const Frame>& f) { recorder->addFrame("fisheye", f); },
            recorder->keepCapturedFlag(), &t.fisheyeCaptureStage);
        if (Status s = t.fisheyeCamera->start(); !s) return s.error();
        t.lightingThread = std::thread([&t] {
            runGuarded(
                "lighting", [&t] { t.runLighting(); },
                [&t](const std::string& why) { t.stageFailed(why); });
        });
    }
    t.trackingThread = std::thread([&t, this] {
        runGuarded(
            "tracking", [&t, this] { t.runTracking(modes_); },
            [&t](const std::string& why) { t.stageFailed(why); });
    });
    t.renderThread = std::thread([&t, this] {
        runGuarded(
            "render", [&t, this] { t.runRender(modes_); },
            [&t](const std::string& why) { t.stageFailed(why); });
    });
    return {};
}

Result<std::string> Service::startRecording(const std::string& name) {
    Result<std::string> take =
        threads_->recorder->start(name, threads_->lightingSnapshots.latest());
    // The mode the take starts in: its presses toggle from there when it replays.
    if (take) recordEvent("take", "mode=" + std::string(toString(modes_.mode())));
    updateLed();
    return take;
}

Result<std::string> Service::stopRecording() {
    Result<std::string> take = threads_->recorder->stop();
    updateLed();
    return take;
}

void Service::recordEvent(const std::string& source, const std::string& event) {
    threads_->recorder->addEvent({0, source, event});
}

void Service::updateLed() {
    const bool refine = modes_.mode() == Mode::Refine;
    if (!threads_->recorder || !threads_->recorder->recording()) {
        setLed(refine);
        return;
    }
    const int64_t phaseMs = (monotonicNowNs() / 1'000'000) % 1000;
    setLed(phaseMs < (refine ? 800 : 200));
}

void Service::applyRecordedEvent(const SessionEvent& e) {
    applySessionEvent(modes_, e);
    updateLed();
}

void Service::setLed(bool on) {
    if (threads_->led) threads_->led->set(on);
}

void Service::requestStop() {
    const uint64_t one = 1;
    [[maybe_unused]] ssize_t n = ::write(stopFd_, &one, sizeof(one));
}

ServiceStatus Service::startingStatus() const {
    ServiceStatus s;
    s.state = "starting";
    s.starting = startingNow();
    s.mode = modes_.mode();
    s.display = toString(config_.output.kind);
    s.sceneCamera = toString(CaptureState::Stopped);
    s.fisheyeCamera = config_.fisheyeCamera ? toString(CaptureState::Stopped) : "none";
    s.uptimeSeconds = std::chrono::duration<double>(Clock::now() - started_).count();
    if (threads_->web) s.web = threads_->web->stats();
    return s;
}

ServiceStatus Service::status() const {
    if (!running_.load(std::memory_order_acquire)) return startingStatus();
    const Threads& t = *threads_;
    ServiceStatus s;
    {
        std::lock_guard lock(t.statusMutex);
        s = t.renderStatus;
    }
    // Just out of refinement, before the first preview frame: report preview's count.
    const Mode rendered = s.mode;
    s.mode = modes_.mode();
    if (s.mode == Mode::Preview && rendered == Mode::Refine) {
        std::lock_guard lock(threads_->settingsMutex);
        s.samples = threads_->previewSamples;
        s.noiseEstimate.reset();
        s.etaSeconds.reset();
    }
    const DisplayStats shown = t.display->stats();
    s.framesShown = shown.shown;
    s.droppedCapture = t.sceneCamera->frames().dropped();
    s.droppedRender = t.droppedRender.load();
    s.droppedDisplay = shown.dropped;
    // A "NO CAMERA" frame has no capture time.
    if (shown.shown > 0 && shown.lastCaptureTimestampNs > 0)
        s.latencyMs = double(shown.lastShownNs - shown.lastCaptureTimestampNs) * 1e-6;
    s.lightingMs = t.lightingMs.load();
    s.framesDropped = s.droppedCapture + s.droppedRender + s.droppedDisplay;
    s.display = shown.kind.empty() ? t.display->output().kind() : shown.kind;
    s.uptimeSeconds = std::chrono::duration<double>(Clock::now() - started_).count();
    const CaptureStats scene = t.sceneCamera->stats();
    s.sceneCamera = toString(scene.state);
    s.sceneCameraProblem = scene.problem;
    if (t.fisheyeCamera) {
        const CaptureStats fisheye = t.fisheyeCamera->stats();
        s.fisheyeCamera = toString(fisheye.state);
        s.fisheyeCameraProblem = fisheye.problem;
        s.bracketFramesWithheld = fisheye.withheld;
    } else {
        s.fisheyeCamera = "none";
    }
    s.lightingUpdates = t.lightingUpdates.load();
    {
        std::lock_guard lock(t.statusMutex);
        s.brackets = t.brackets;
        s.lastBracketDrop = t.lastBracketDrop;
        s.clippedSolidAngleFraction = t.clippedSolidAngleFraction;
    }
    s.record = t.recorder->status();
    for (int i = 1; i < kLostReasonCount; ++i)
        s.trackingLostFrames[size_t(i)] = t.lostFrames[size_t(i)].load();
    s.button = !t.button ? "none" : t.button->connected() ? "connected" : "absent";
    s.led = !t.led ? "none" : t.led->connected() ? "connected" : "absent";
    s.timecodeStatus = t.timecode->status();
    if (t.trackingOut) s.trackingOut = t.trackingOut->stats();
    if (t.web) s.web = t.web->stats();
    if (t.freedIn) s.freedIn = t.freedIn->stats();
    return s;
}

std::string Service::handleCommand(const std::string& command) {
    // A client's bytes may be anything (a Latin-1 terminal, a fuzzer): replaced, never thrown.
    auto error = [](const std::string& what) {
        return nlohmann::json{{"ok", false}, {"error", what}}.dump(
            -1, ' ', false, nlohmann::json::error_handler_t::replace);
    };
    if (command == "status") return statusJson(status());
    // Nothing but the status exists yet (no recorder, renderer or cameras).
    if (!running_.load(std::memory_order_acquire))
        return error("starting: " + startingNow() + "; try again when ready");
    if (command == "toggle") {
        recordEvent("ctl", "mode=toggle");
        const Mode m = modes_.toggle("ctl");
        updateLed();
        return nlohmann::json{{"ok", true}, {"mode", toString(m)}}.dump();
    }
    if (command.rfind("mode ", 0) == 0) {
        const std::optional<Mode> wanted = parseMode(command.substr(5));
        if (!wanted)
            return error("mode must be preview or refine, not '" + command.substr(5) + "'");
        recordEvent("ctl", "mode=" + std::string(toString(*wanted)));
        const Mode m = modes_.set(*wanted, "ctl");
        updateLed();
        return nlohmann::json{{"ok", true}, {"mode", toString(m)}}.dump();
    }
    if (command == "reload") {
        Result<std::string> applied = reload();
        if (!applied) return error(applied.message());
        return nlohmann::json{{"ok", true}, {"applied", *applied}}.dump(
            -1, ' ', false, nlohmann::json::error_handler_t::replace);
    }
    if (command == "record stop") {
        Result<std::string> take = stopRecording();
        if (!take) return error(take.message());
        return nlohmann::json{{"ok", true}, {"path", *take}}.dump();
    }
    if (command == "record start" || command.rfind("record start ", 0) == 0) {
        const std::string name = command.size() > 13 ? command.substr(13) : std::string();
        Result<std::string> take = startRecording(name);
        if (!take) return error(take.message());
        return nlohmann::json{{"ok", true}, {"path", *take}}.dump(
            -1, ' ', false, nlohmann::json::error_handler_t::replace);
    }
    return error("unknown command '" + command +
                 "'; use status, mode preview|refine, toggle, reload or record start [NAME]|stop");
}

Result<std::string> Service::reload() {
    std::lock_guard reloading(reloadMutex_);
    systemd::notifyReloading();
    Result<ServiceConfig> fresh = loadServiceConfig(config_.path);
    if (!fresh) {
        logError("reload: {}; keeping the running config", fresh.message());
        systemd::notifyReady();
        return makeError("{}; the running config is kept", fresh.message());
    }
    const ServiceConfig& n = *fresh;
    {
        std::lock_guard lock(threads_->settingsMutex);
        threads_->refine = n.refine;
        // The dial's choice stands while preview_fps is set.
        if (n.render.previewFps <= 0.0) threads_->previewSamples = n.render.samplesPerFrame;
    }
    // What the running pipeline cannot take without a restart.
    std::vector<std::string> restart;
    auto cameraKey = [](const CameraConfig& c) {
        return fmt::format("{}|{}|{}x{}|{}|{}|{}", toString(c.source), c.device, c.width, c.height,
                           c.pixelFormat, c.fps, c.calibrationPath);
    };
    if (n.scenePath != config_.scenePath) restart.push_back("scene");
    if (cameraKey(n.sceneCamera) != cameraKey(config_.sceneCamera))
        restart.push_back("cameras.scene");
    if (n.fisheyeCamera.has_value() != config_.fisheyeCamera.has_value() ||
        (n.fisheyeCamera && cameraKey(*n.fisheyeCamera) != cameraKey(*config_.fisheyeCamera)))
        restart.push_back("cameras.fisheye");
    if (n.tracking.boardPath != config_.tracking.boardPath) restart.push_back("tracking");
    if (n.lighting.mode != config_.lighting.mode) restart.push_back("lighting");
    if (n.render.width != config_.render.width || n.render.height != config_.render.height ||
        n.render.maxDepth != config_.render.maxDepth || n.render.seed != config_.render.seed ||
        !(n.render.photons == config_.render.photons) ||
        n.render.previewFps != config_.render.previewFps ||
        n.render.resolutionScale != config_.render.resolutionScale)
        restart.push_back("render (size, max_depth, seed, photons, preview_fps, resolution_scale)");
    if (n.output.kind != config_.output.kind || n.output.folder != config_.output.folder ||
        n.output.card != config_.output.card || n.output.connector != config_.output.connector ||
        n.output.mode != config_.output.mode)
        restart.push_back("output");
    if (n.button.has_value() != config_.button.has_value() ||
        (n.button &&
         (n.button->chip != config_.button->chip || n.button->line != config_.button->line)))
        restart.push_back("button");
    if (controlSocketPath(n.control) != controlSocketPath(config_.control))
        restart.push_back("control");
    std::string applied = fmt::format(
        "{}: applied [refine]{}{}", config_.path,
        n.render.previewFps <= 0.0
            ? fmt::format(" and render.samples_per_frame = {}", n.render.samplesPerFrame)
            : std::string(" (render.preview_fps keeps the dial's samples per frame)"),
        restart.empty()
            ? std::string()
            : fmt::format("; these need a restart to apply: {}", fmt::join(restart, ", ")));
    logInfo("reload: {}", applied);
    systemd::notifyReady();
    return applied;
}

std::optional<int> Service::startAnsweringSignals(int signalFd) {
    Threads& t = *threads_;
    UniqueFD started(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
    if (!started.isValid()) {
        logError("eventfd: {}", std::strerror(errno));
        return 1;
    }
    Status result;
    bool userError = false;
    std::thread starter([&] {
        nameThread("pv-start");
        runGuarded(
            "start", [&] { result = start(&userError); },
            [&](const std::string& why) { result = makeError("{}", why); });
        const uint64_t one = 1;
        [[maybe_unused]] ssize_t n = ::write(started.get(), &one, sizeof(one));
    });
    bool stopAsked = false;
    auto stop = [&](const std::string& why) {
        if (!stopAsked) logInfo("{}: stopping while starting ({})", why, startingNow());
        stopAsked = true;
        t.stopping.store(true);  // the start's next stage, or its GPU pass, ends it
    };
    uint64_t compiled = t.renderStage.longerSteps();
    for (;;) {
        pollfd fds[3] = {
            {signalFd, POLLIN, 0}, {t.stopEvent.get(), POLLIN, 0}, {started.get(), POLLIN, 0}};
        const int r = ::poll(fds, 3, 500);
        if (r < 0 && errno != EINTR) stop(fmt::format("poll: {}", std::strerror(errno)));
        if (fds[2].revents) break;
        if (fds[1].revents) stop("asked to stop");
        signalfd_siginfo info{};
        while (r > 0 && (fds[0].revents & POLLIN) &&
               ::read(signalFd, &info, sizeof(info)) == ssize_t(sizeof(info))) {
            if (info.ssi_signo == SIGHUP)
                logInfo(
                    "SIGHUP: still starting; the config read at start applies (reload once "
                    "running)");
            else
                stop(strsignal(int(info.ssi_signo)));
        }
        // The compiles' progress, at most every poll's timeout; other stages are logged as
        // they begin.
        const std::string now = startingNow();
        const uint64_t n = t.renderStage.longerSteps();
        if (n != compiled && !stopAsked && now.starts_with(PipelineStartHooks::kCompilingStage)) {
            logInfo("starting: {}", now);
            systemd::notifyStatus("starting: " + now);
            compiled = n;
        }
    }
    starter.join();
    if (stopAsked) {
        t.stopAll();
        logInfo("stopped while starting");
        return 0;
    }
    if (!result) {
        logError("{}", result.message());
        t.stopAll();
        return userError ? 2 : 1;
    }
    return std::nullopt;
}

int Service::run() {
    sigset_t set;
    sigemptyset(&set);
    sigaddset(&set, SIGTERM);
    sigaddset(&set, SIGINT);
    sigaddset(&set, SIGHUP);
    UniqueFD signals(::signalfd(-1, &set, SFD_CLOEXEC | SFD_NONBLOCK));
    if (!signals.isValid()) {
        logError("signalfd: {}", std::strerror(errno));
        return 1;
    }
    if (!running_.load(std::memory_order_acquire))
        if (std::optional<int> code = startAnsweringSignals(signals.get())) return *code;
    Threads& t = *threads_;
    systemd::notifyReady();
    const std::optional<std::chrono::microseconds> watchdog = systemd::watchdogInterval();
    // Ping at a quarter of the interval, and only while no thread is stuck in a step for half of
    // it (base/stage_watch.h): a hung camera, tracker, GPU or display stops the pings and
    // systemd restarts the service. Without a watchdog a stuck thread is still logged.
    const int pollMs =
        watchdog ? int(std::clamp<int64_t>(watchdog->count() / 4000, 50, 1000)) : 1000;
    const int64_t stuckNs =
        watchdog ? int64_t(watchdog->count()) * 1000 / 2 : kStuckWithoutWatchdogNs;
    std::vector<std::string> reportedStuck;
    int exitCode = 0;
    Clock::time_point lastStatus{}, finishedAt{};
    for (;;) {
        pollfd fds[2] = {{signals.get(), POLLIN, 0}, {t.stopEvent.get(), POLLIN, 0}};
        // A rolling take blinks the LED (updateLed): wake often enough to blink.
        const bool rolling = t.recorder->recording();
        const int r = ::poll(fds, 2, rolling ? std::min(pollMs, 100) : pollMs);
        if (r < 0 && errno != EINTR) {
            logError("poll: {}", std::strerror(errno));
            exitCode = 1;
            break;
        }
        if (fds[1].revents) break;
        if (r > 0 && (fds[0].revents & POLLIN)) {
            signalfd_siginfo info{};
            bool stop = false;
            while (::read(signals.get(), &info, sizeof(info)) == ssize_t(sizeof(info))) {
                if (info.ssi_signo == SIGHUP) {
                    logInfo("SIGHUP: reloading {}", config_.path);
                    (void)reload();  // logged either way
                } else {
                    logInfo("{}: stopping", strsignal(int(info.ssi_signo)));
                    stop = true;
                }
            }
            if (stop) break;
        }
        if (t.pipelineFailed.load()) {
            logError("a pipeline thread failed (see above); exiting so the service restarts");
            exitCode = 1;
            break;
        }
        // A session that does not loop ends the service once its last frame had time to be
        // rendered and shown.
        if (!config_.loopSession && t.sceneCamera->stats().state == CaptureState::Finished) {
            if (finishedAt == Clock::time_point{}) finishedAt = Clock::now();
            if (Clock::now() - finishedAt > std::chrono::seconds(3)) {
                logInfo("the recorded session ended");
                break;
            }
        }
        if (rolling || t.led) updateLed();
        if (reportStuckStages(t.watch.stuck(monotonicNowNs(), stuckNs), reportedStuck,
                              watchdog.has_value()))
            if (watchdog) systemd::notifyWatchdog();
        if (Clock::now() - lastStatus > std::chrono::seconds(1)) {
            systemd::notifyStatus(statusLine(status()));
            lastStatus = Clock::now();
        }
    }
    systemd::notifyStopping();
    t.stopAll();
    return exitCode;
}

}  // namespace previs
