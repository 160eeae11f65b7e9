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
#include <tuple>

#include "base/guarded_thread.h"
#include "base/latest_value_slot.h"
#include "base/log.h"
#include "base/monotonic_clock.h"
#include "base/unique_fd.h"
#include "daemon/camera_sources.h"
#include "daemon/control_server.h"
#include "daemon/memory_budget.h"
#include "daemon/service_threads.h"
#include "display/display_thread.h"
#include "display/frame_output.h"
#include "gpu/context.h"
#include "io/gpio_button.h"
#include "io/status_led.h"
#include "scene/scene_description.h"
#include "shot/pipeline_renderer.h"
#include "shot/pipeline_stages.h"
#include "shot/refine_watch.h"
#include "shot/shot_controller.h"
#include "systemd/listen_fds.h"
#include "systemd/notify.h"
#include "take/recorded_events.h"

namespace previs {

namespace {

using Clock = std::chrono::steady_clock;

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

}  // namespace

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

Service::Service(ServiceConfig config)
    : config_(std::move(config)), threads_(std::make_unique<Threads>()), started_(Clock::now()) {}

Service::~Service() {
    if (threads_) threads_->stopAll();
}

Result<std::unique_ptr<Service>> Service::open(const ServiceConfig& config) {
    // The control socket and the port are the config's (exit 2): checked before any slow work,
    // so a second previsd on them is refused at once.
    std::unique_ptr<Service> service(new Service(config));
    Threads& t = *service->threads_;
    Service* self = service.get();
    service->stopFd_ = t.stopEvent.get();
    // Under systemd with the network units the sockets come made (docs/systemd.md).
    t.passedSockets = systemd::ListenFds::fromEnvironment();
    Result<std::unique_ptr<ControlServer>> control = ControlServer::create(
        controlSocketPath(config.control),
        [self](const std::string& command) { return self->handleCommand(command); });
    if (!control) return withKind(control.error(), Error::Kind::Config);
    t.control = std::move(*control);
    if (Status st = t.openWeb(config.network.web, self); !st)
        return withKind(st.error(), Error::Kind::Config);
    logInfo("serving {} (control socket {}); starting", config.path, t.control->path());
    return service;
}

Result<std::unique_ptr<Service>> Service::create(const ServiceConfig& config) {
    Result<std::unique_ptr<Service>> service = open(config);
    if (!service) return service;
    if (Status s = (*service)->start(); !s) return s.error();
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
    // A stage that counts its steps (the pipelines, the dial's settings) says how far it is.
    if (steps > 0) stage = fmt::format("{}: {}/{}", stage, done, steps);
    const double seconds = std::chrono::duration<double>(Clock::now() - since).count();
    if (seconds >= 2.0) return fmt::format("{}, {:.0f} s so far", stage, seconds);
    return stage;
}

Status Service::start() {
    // Most failures here are the config's (a scene, a connector, a GPIO line): exit 2, which
    // systemd does not restart. The GPU is the device's; the renderer and the cameras' threads
    // are runtime's.
    const ServiceConfig& config = config_;
    const Error stopped = makeError("stopped while starting");
    Threads& t = *threads_;
    t.live = static_cast<const LiveConfig&>(config);

    if (!beginStartStage("loading the scene " + config.scenePath)) return stopped;
    Result<Scene> scene = loadScene(config.scenePath);
    if (!scene) return withKind(scene.error(), Error::Kind::Config);
    // What would cross MemoryMax= is refused now, not found by the OOM killer mid-take.
    if (Status s = checkMemoryBudget(*scene, config, cgroupMemoryLimit()); !s)
        return withKind(s.error(), Error::Kind::Config);
    if (!beginStartStage("opening the GPU")) return stopped;
    Result<std::unique_ptr<GpuContext>> gpu = GpuContext::create({});
    if (!gpu) return withKind(gpu.error(), Error::Kind::Device);
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
        PipelineRenderer::create(*t.gpu, std::move(*scene), config, hooks);
    if (t.stopping.load()) return stopped;
    if (!renderer) return renderer.error();
    t.renderer = std::move(*renderer);
    // With [render] preview_fps the dial chose the preview's samples (PipelineRenderer).
    logInfo("render: {}x{} on {}, {} spp per preview frame", t.renderer->width(),
            t.renderer->height(), t.gpu->deviceName(), t.renderer->previewSamples());
    // What the stages open (tracking, network, display, button) the config names.
    if (Status s = startStages(); !s) return withKind(s.error(), Error::Kind::Config);
    if (Status s = startThreads(); !s) return s;
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

Status Service::startStages() {
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

Status Service::startThreads() {
    const ServiceConfig& config = config_;
    Threads& t = *threads_;
    if (!beginStartStage("opening the cameras")) return makeError("stopped while starting");
    // Cameras: once they stream, frames flow into the stages (and into a take while one rolls).
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
        threads_->live = static_cast<const LiveConfig&>(n);
        threads_->liveReloaded = true;
    }
    // What the running pipeline cannot take without a restart.
    const std::vector<std::string> restart = restartNeeded(config_, n);
    // The running dial, if any, keeps choosing preview's samples (ShotController::setConfig).
    const bool dialRuns = config_.render.previewFps > 0.0;
    std::string applied = fmt::format(
        "{}: applied [refine]{}{}", config_.path,
        dialRuns ? std::string(" (render.preview_fps keeps the dial's samples per frame)")
                 : fmt::format(" and render.samples_per_frame = {}", n.liveRender.samplesPerFrame),
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
    std::thread starter([&] {
        nameThread("pv-start");
        runGuarded(
            "start", [&] { result = start(); },
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
        return exitCodeOf(result.error());
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