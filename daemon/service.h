#pragma once

// previsd (DESIGN.md §1, §6, issue 7): the box a film crew switches on. Threads — one per
// camera, one for tracking, one for lighting, one render thread owning the Vulkan device, one
// display thread, plus the button's and the control socket's — pass immutable snapshots through
// latest-value slots: a slow stage drops frames (counted), it never stalls capture.

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <thread>

#include "base/result.h"
#include "config/service_config.h"
#include "daemon/tracking_out.h"
#include "io/session.h"
#include "render/plate_consistency.h"
#include "shot/freed_input.h"
#include "shot/mode_machine.h"
#include "shot/shot_controller.h"
#include "take/take_recorder.h"
#include "timecode/timecode_source.h"
#include "vision/board_pose.h"
#include "web/web_monitor.h"

namespace previs {

// What `previs ctl status` reports (DESIGN.md §3), as one consistent snapshot.
struct ServiceStatus {
    // "starting" from the moment the control socket and the page answer until the pipeline runs
    // (issue 54), then "running"; `starting` says what the start is doing meanwhile
    // ("compiling pipelines: 3/12"), empty once running.
    std::string state = "running";
    std::string starting;
    Mode mode = Mode::Preview;
    uint64_t framesShown = 0;
    uint64_t framesDropped = 0;  // camera frames that never reached the screen, all stages
    // capture: frames tracking never took (tracking too slow); render: tracked frames replaced
    // before the renderer took them; display: rendered frames replaced before being shown.
    uint64_t droppedCapture = 0, droppedRender = 0, droppedDisplay = 0;
    uint64_t framesRendered = 0;
    uint64_t samples = 0;  // per frame in preview, accumulated in refinement
    // Refinement only: the convergence meter's relative RMSE of the composite, and the seconds
    // until refinement stops (shot/refine_watch.h); none in preview or before an estimate.
    std::optional<double> noiseEstimate;
    std::optional<double> etaSeconds;
    uint64_t refineRestarts = 0;  // refinements started over on a changed pose or lighting
    double fps = 0.0;
    std::string display = "none";
    std::optional<cv::Matx44d> worldFromCamera;  // OpenCV camera axes, board frame
    int tags = 0;
    bool trackingLost = true;
    double uptimeSeconds = 0.0;
    double renderMs = 0.0;    // the last frame's: render + composite + tone map
    double trackMs = 0.0;     // the last frame's detection and pose
    double lightingMs = 0.0;  // the last lighting snapshot's fisheye → map (→ lights)
    // Camera frame (its V4L2 timestamp; a recording's: when the pipeline received it) → shown
    // (page flip queued or file written), for the last frame shown.
    double latencyMs = 0.0;
    uint64_t deviceBytes = 0;                // the renderer's device memory
    uint32_t photonsPerIteration = 0;        // 0: no photon pass (docs/caustics.md)
    float photonRadiusM = 0.0f;              // the gather radius of the frame's last iteration
    std::string sceneCamera, fisheyeCamera;  // capture states
    std::string sceneCameraProblem, fisheyeCameraProblem;  // CaptureStats::problem
    uint64_t lightingUpdates = 0;
    // [cameras.fisheye.bracket]: the brackets merged and dropped so far, the last drop's reason,
    // and the share of the sphere the last snapshot's light clipped in (status "lightCapture").
    std::optional<BracketCounts> brackets;
    std::string lastBracketDrop;
    double clippedSolidAngleFraction = 0.0;
    // A live V4L2 fisheye's frames withheld while its bracket's exposure control landed
    // (CaptureStats::withheld; "lightCapture.framesWithheld").
    uint64_t bracketFramesWithheld = 0;
    // No lighting snapshot yet: the virtual objects are lit by a neutral environment.
    bool lightingPending = false;
    // Preview: frames averaged into the shown one (temporal accumulation; 0: fixed sequence).
    uint32_t previewHistoryFrames = 0;
    // Preview: frames the held view keeps per output pixel since the camera last moved
    // (render/held_view.h; 0 while the camera moves, at full resolution, or in refinement).
    uint64_t heldViewFrames = 0;
    // The take recorder (take/take_recorder.h): "recording" and the "record" object.
    RecordStatus record;
    // The mode button and the status LED: "connected", "absent" (its GPIO chip or line is not
    // there yet, or went away: previsd looks for it every second) or "none" (not configured).
    // Frames tracking gave no trusted pose since start, by LostReason (index; 0 unused).
    std::array<uint64_t, kLostReasonCount> trackingLostFrames{};
    std::string button = "none";
    std::string led = "none";
    // The set's network (issue 39): the timecode of the last tracked frame and its source, the
    // tracking packets sent ([freed], [opentrackio]; none when neither is configured) and the
    // web monitor's viewers and refused requests (none without [web]).
    std::optional<Timecode> timecode;
    TimecodeStatus timecodeStatus;
    std::optional<TrackingOutStats> trackingOut;
    std::optional<WebStats> web;
    std::optional<FreedInputStats> freedIn;  // [tracking] listen
    // The plate-consistency meter's last reading (DESIGN.md §4; shot/shot_controller.h says
    // when it reads); none before the first.
    std::optional<PlateConsistencyReading> plateConsistency;
    std::optional<LightingFitReport> lightingFit;  // the last lighting fit's (status "lightingFit")
};

std::string statusJson(const ServiceStatus& status);
// "PREVIEW 1 spp 9.8 fps", "REFINE 256 spp noise 1.8% ETA 12 s 2.0 fps" — the display overlay.
std::string statusLine(const ServiceStatus& status);

// previsd's exit code for a failed start (DESIGN.md: 2 for the config's errors, which systemd does
// not restart; 1 for the device's and the others).
inline int exitCodeOf(const Error& error) { return error.kind == Error::Kind::Config ? 2 : 1; }

class Service {
public:
    // Opens what answers at once, the control socket and the web monitor, so that a second
    // previsd on the same socket or port is refused before any slow work; status says "starting"
    // until run() has started the rest. An error's kind tells a failure the config caused
    // (Error::Kind::Config, exit 2) from the others (exit 1): exitCodeOf.
    static Result<std::unique_ptr<Service>> open(const ServiceConfig& config);
    // open() and start(): ready to run when it returns (the benchmarks, which time the start).
    static Result<std::unique_ptr<Service>> create(const ServiceConfig& config);
    ~Service();
    Service(const Service&) = delete;
    Service& operator=(const Service&) = delete;

    // The slow part of the start: opens everything the config names that must exist at start
    // (scene, GPU and its pipelines, button); cameras and the display may be absent and come
    // later. Each stage is logged as it begins and shown by status(). Fails with "stopped" once
    // a stop was asked for (a SIGTERM while starting).
    Status start();

    // Starts the pipeline (on a thread, unless start() ran) and runs until SIGTERM/SIGINT (exit
    // 0), a failed start (2 or 1) or a fatal error (1); a SIGTERM while starting stops at the
    // start's next stage or GPU pass. Speaks sd_notify (ready once started), feeds the watchdog
    // while no thread is stuck in a step (base/stage_watch.h), reloads on SIGHUP. The caller must
    // have blocked SIGTERM, SIGINT and SIGHUP in every thread (blockServiceSignals()).
    int run();
    // Asks run() to return (tests; signals do the same).
    void requestStop();

    ServiceStatus status() const;
    ModeMachine& modes() { return modes_; }
    // The answer to one control-socket command line.
    std::string handleCommand(const std::string& command);

private:
    explicit Service(ServiceConfig config);
    struct Threads;
    // start()'s stages: logged ("starting: loading the scene ...") and kept for status(), with
    // how many steps the stage counts (0: none; PipelineStartHooks); false once a stop was
    // asked for.
    bool beginStartStage(const std::string& what, size_t steps = 0);
    std::string startingNow() const;
    ServiceStatus startingStatus() const;
    // run()'s first part: start() on a thread while this one answers signals (a SIGTERM stops
    // the start). The exit code when the start failed or was stopped; none once it runs.
    std::optional<int> startAnsweringSignals(int signalFd);
    // start()'s parts after the renderer: the stages, the button, the cameras and threads.
    Status startStages();
    Status openButton(const ButtonConfig& button);
    Status startThreads();
    // Rereads the config and applies what a running pipeline can take ([refine], the preview's
    // samples), keeping the running config when the new one is bad. Returns what was applied,
    // and what would need a restart (SIGHUP and `previs ctl reload`; the latter answers with it).
    Result<std::string> reload();
    void setLed(bool on);
    // The LED while the loop runs: on in refinement, off in preview; while a take rolls it
    // blinks once a second, lit 80 % of the time in refinement and 20 % in preview.
    void updateLed();
    Result<std::string> startRecording(const std::string& name);
    Result<std::string> stopRecording();
    void recordEvent(const std::string& source, const std::string& event);
    void applyRecordedEvent(const SessionEvent& event);

    ServiceConfig config_;
    ModeMachine modes_;
    std::unique_ptr<Threads> threads_;
    std::chrono::steady_clock::time_point started_;
    std::atomic<bool> stop_{false};
    // Set (release) once start() has made every thread's part: until then status() and the
    // commands touch none of it.
    std::atomic<bool> running_{false};
    mutable std::mutex startMutex_;
    std::string startStage_;  // what start() is doing, and since when (under startMutex_)
    std::chrono::steady_clock::time_point startStageSince_;
    size_t startStepsDone_ = 0;  // of startSteps_ (0: the stage counts none; under startMutex_)
    size_t startSteps_ = 0;
    int stopFd_ = -1;         // eventfd owned by threads_
    std::mutex reloadMutex_;  // SIGHUP (the main thread) and `ctl reload` (the socket's)
};

// Blocks SIGTERM, SIGINT and SIGHUP in the calling thread and the threads it starts later, so
// only run()'s signalfd sees them.
void blockServiceSignals();

// The descriptors previsd wants at least: the cameras' buffers, a take's files, the GPU's, the
// sockets (the unit's LimitNOFILE= is 16384; docs/systemd.md).
constexpr uint64_t kWantedOpenFiles = 4096;

// Raises the soft limit on open descriptors to the hard one (a shell's soft limit is 1024, which
// the network's clients could leave the cameras and the take without) and returns the soft
// limit in effect. Logs once when it stays under kWantedOpenFiles.
uint64_t raiseOpenFileLimit();

}  // namespace previs
