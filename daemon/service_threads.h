#pragma once

// Internal to daemon/: the service's threads and what they share (Service::Threads), for
// service.cpp (start, run, reload), service_threads.cpp (the thread bodies) and status.cpp.

#include <pthread.h>
#include <sys/eventfd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "base/latest_value_slot.h"
#include "base/stage_watch.h"
#include "base/unique_fd.h"
#include "daemon/camera_sources.h"
#include "daemon/control_server.h"
#include "daemon/service.h"
#include "display/display_thread.h"
#include "gpu/context.h"
#include "io/gpio_button.h"
#include "io/status_led.h"
#include "shot/pipeline_renderer.h"
#include "shot/pipeline_stages.h"
#include "systemd/listen_fds.h"
#include "take/recorded_events.h"

namespace previs {

// Names show in top -H, perf and /proc/PID/task/*/comm (15 characters at most).
inline void nameThread(const char* name) { pthread_setname_np(pthread_self(), name); }

// Everything with a thread, in the order it is stopped (reverse of declaration is destruction).
struct Service::Threads {
    using Clock = std::chrono::steady_clock;

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

    // The config's live part, which SIGHUP may change while running: the start's, then each
    // reload's; `liveReloaded` until the render thread hands it to the shot.
    std::mutex settingsMutex;
    LiveConfig live;
    bool liveReloaded = false;

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

}  // namespace previs
