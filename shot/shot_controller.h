#pragma once

// The shot (issue 35): the one owner of what the render stage does with the frames it gets —
// preview or refinement, freezing the shot, the size of each refinement step, the restart
// checks, the convergence meter and the ETA, the cap on a preview frame's samples, the dial's
// live correction and the lighting in effect — and of tracking's pace while refining. previsd
// (live clock, threads), `previs replay` (the recorded clock, lock step: nothing dropped) and the
// service benchmark all drive this same object, so the rules a replay or a benchmark shows are
// the box's. Time comes from an injected ShotClock; the renderer behind a ShotRenderer, so the
// rules are tested with a fake clock and a fake renderer (tests/shot/shot_controller_test.cpp).

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "config/service_config.h"
#include "render/convergence.h"
#include "render/plate_consistency.h"
#include "shot/mode_machine.h"
#include "shot/pipeline_stages.h"
#include "shot/preview_settings.h"
#include "shot/refine_watch.h"

namespace previs {

// Where the shot's time comes from: the steady clock live, the session's capture time in a
// replay (it does not advance while a frame renders, so a replay is deterministic and sizes
// nothing by this machine's speed), a hand-advanced clock in tests.
class ShotClock {
public:
    using TimePoint = std::chrono::steady_clock::time_point;
    virtual ~ShotClock() = default;
    virtual TimePoint now() const = 0;
};

class SteadyShotClock final : public ShotClock {
public:
    TimePoint now() const override { return std::chrono::steady_clock::now(); }
};

// A clock set from outside: a replay's recorded frame times, a test's steps.
class ManualShotClock final : public ShotClock {
public:
    TimePoint now() const override { return now_; }
    void set(TimePoint t) { now_ = t; }
    void setNs(uint64_t ns) { now_ = TimePoint(std::chrono::nanoseconds(ns)); }
    void advance(std::chrono::nanoseconds d) { now_ += d; }

private:
    TimePoint now_{};
};

// What the last lighting fit did (status "lightingFit"; docs/previsd.md).
struct LightingFitReport {
    enum class State { NotNeeded, Fitted, Failed, Off };
    State state = State::NotNeeded;
    bool changed = false;  // the lighting rendered with changed
    std::string why;       // Failed: the reason (the last good lighting stays)
    LightingFit fit;       // Fitted: the gains (relative to the lighting it was fitted on)
    uint64_t frame = 0;    // the scene camera frame it was fitted on
};
const char* toString(LightingFitReport::State state);

// What the shot needs of the render stage (PipelineRenderer implements it).
class ShotRenderer {
public:
    virtual ~ShotRenderer() = default;
    // A preview frame of this frame with its own pose and `lighting` (null: the scene's own).
    virtual Status renderPreview(const TrackedFrame& frame,
                                 const std::shared_ptr<const LiveLighting>& lighting) = 0;
    // Freezes frame, pose and lighting and clears the accumulation.
    virtual Status beginRefine(const TrackedFrame& frame,
                               const std::shared_ptr<const LiveLighting>& lighting) = 0;
    virtual Status refineStep(uint32_t samples) = 0;
    // Per pixel: this preview frame's, or the refinement's so far.
    virtual uint64_t samples() const = 0;
    // Whether the last frame rendered the virtual objects (false before the first pose).
    virtual bool rendered() const = 0;
    // One look of the convergence meter: the composite's relative RMSE, if it can say.
    virtual Result<std::optional<double>> measureNoise() = 0;
    // Preview's settings, configured and in use (PipelineRenderer holds them).
    virtual PreviewState preview() const = 0;
    // The one call that changes them: `configured` (the config's, the dial's, a reload's) in
    // use with `samplesInUse` samples, at most its own (the cap lowers them).
    virtual Status setPreview(const PreviewSettings& configured, uint32_t samplesInUse) = 0;
    // The dial (PipelineRenderer::adaptDial): whether it runs, and its live correction from the
    // median live frame time at the point in use and its own depth, and what a held camera's
    // frames cost against that (`heldCost`, 1 when not known): the new setting's description
    // when it changed (the point, or whether a held camera traces refinement's depth).
    virtual bool hasDial() const = 0;
    virtual std::optional<std::string> adaptDial(double liveFrameSeconds, double heldCost) = 0;
    // The last preview frame was traced off the dial's point (a held camera at refinement's
    // depth, [render] preview_hold_depth): it costs more than the point's own frames.
    virtual bool lastPreviewOffDial() const = 0;
    // The plate-consistency meter (render/plate_consistency.h) on the last frame rendered: none
    // when it cannot say (nothing rendered, lighting pending, too few real surfaces in view).
    virtual Result<std::optional<PlateConsistency>> measurePlateConsistency() = 0;
    // Lighting fitted to the plate ([lighting] fit_to_plate, render/lighting_fit.h) after a meter
    // reading on `frame`, the last frame rendered: fits when the policy asks, and from the next
    // frame renders with the corrected lighting. What it did; `changed` when the lighting it
    // renders with is now another (a refinement must start over).
    virtual LightingFitReport fitLighting(const TrackedFrame& frame,
                                          const PlateConsistency& reading) = 0;
    // The virtual objects are lit by a stand-in, not the set's captured lighting (yet).
    virtual bool lightingPending() const = 0;
};

// Tracking's pace (the tracking thread's, or a replay's): every frame in preview; while refining a
// pose only serves the restart check, so a few a second do and the CPU goes to the samples. By the
// frames' capture times, so live and replay agree.
class TrackingPace {
public:
    static constexpr std::chrono::milliseconds kRefinePeriod{250};
    // Whether to track a frame captured at `captureNs` in `mode`; counts it as tracked if so.
    bool due(Mode mode, uint64_t captureNs);

private:
    std::optional<uint64_t> lastNs_;
};

// One step of the shot, for the caller to show and report.
struct ShotStep {
    enum class Kind {
        NoFrame,    // nothing to render: no camera frame yet (preview, or refinement to freeze)
        Previewed,  // a preview frame of `shown`
        Refined,    // a refinement step on the frozen `shown`
        Held,       // refinement converged (or nothing to refine): the shown image is unchanged
    };
    Kind kind = Kind::NoFrame;
    Mode mode = Mode::Preview;
    std::shared_ptr<const TrackedFrame> shown;  // the frame the composite is of
    ShotClock::TimePoint start{};               // when this step's work began
    double fps = 0.0;                           // frames (steps) a second, smoothed
    std::optional<double> noiseEstimate;        // refinement: the meter's, carried forward
    std::optional<double> etaSeconds;           // refinement: until it stops
    bool restarted = false;                     // refinement started over on this step
    bool converged = false;                     // refinement just reached its stopping point
    // The plate-consistency meter's reading, when this step took one (ShotController says when).
    std::optional<PlateConsistencyReading> plateConsistency;
    // What the lighting fit did after that reading, when it tried (or is off).
    std::optional<LightingFitReport> lightingFit;
};

class ShotController {
public:
    // A refinement step is sized to take about this long, so that leaving refinement, a status
    // request and a stop are answered promptly however slow a sample is.
    static constexpr double kRefineStepTargetMs = 250.0;
    // The longest a preview frame may take (its sample count is lowered to fit): a preview
    // frame cannot be interrupted, and the watchdog, a mode change and SIGTERM must be answered.
    static constexpr double kMaxPreviewFrameMs = 3000.0;
    // Preview frames timed before each live correction of the dial (their median).
    static constexpr size_t kDialWindowFrames = 15;
    // The fewest frames of one kind (at the dial's point, or held) whose median, taken as the
    // camera starts or stops holding, pairs with the other kind's window for the held cost.
    static constexpr size_t kDialPairFrames = 5;
    // The plate-consistency meter reads at most this often (shot time), however the camera moves:
    // a reading costs a readback of the accumulation, and the lighting changes slowly.
    static constexpr std::chrono::seconds kPlateMeterPeriod{1};

    ShotController(ShotRenderer& renderer, const ModeMachine& modes, const ShotClock& clock,
                   const RefineConfig& refine);

    // A reload's live settings (SIGHUP): [refine], and preview's configured samples unless the
    // dial runs (it chooses them); a refinement under way goes on.
    void setConfig(const LiveConfig& live);
    // Whether the next step needs a new frame to do anything (preview, or a shot to freeze):
    // the live loop waits for one then, else takes one only if it is there.
    bool wantsFrame() const;
    // One step: `newest` is the newest tracked frame since the last step (null: none came),
    // `lighting` the newest snapshot (null: none yet). An error is the renderer's: the stage
    // cannot go on.
    Result<ShotStep> step(std::shared_ptr<const TrackedFrame> newest,
                          std::shared_ptr<const LiveLighting> lighting);

    // A previewed step's picture is on its way to the monitor: `frameSeconds` is the frame's
    // whole time, from its render's start to its picture's readback (the display pass and the
    // status beside the render). The dial's live correction then budgets what the crew waits
    // for; a caller that never calls it (a lock-step replay) leaves the correction on the
    // render's own time.
    void previewShown(double frameSeconds);

    Mode renderedMode() const { return refining_ ? Mode::Refine : Mode::Preview; }
    uint64_t restarts() const { return restarts_; }
    // The convergence meter's last look at this refinement (not carried forward).
    std::optional<double> measuredNoise() const { return stopping_.measured(); }
    // Preview samples in use (the cap or the dial may have lowered the configured count).
    uint32_t previewSamples() const { return renderer_.preview().inUse.samplesPerFrame; }
    const std::shared_ptr<const TrackedFrame>& frozen() const { return frozen_; }
    // The plate-consistency meter's last reading (none before the first). A reading is taken on a
    // rendered frame with a trusted pose (tracked, not held), the first one and then whenever
    // the pose or the lighting moved beyond [refine]'s restart thresholds since the last one, at
    // most every kPlateMeterPeriod: preview's frame, or refinement's accumulation so far, whose
    // L_or is already there (only the readback costs). Once more as refinement converges: its
    // many samples a cell read the ratio without the few-sample bias (kPlateMeterCellSamples).
    const std::optional<PlateConsistencyReading>& plateConsistency() const { return plate_; }
    // The last lighting fit's report (none before the first try).
    const std::optional<LightingFitReport>& lightingFit() const { return lightingFit_; }

private:
    Result<ShotStep> preview(std::shared_ptr<const TrackedFrame> frame,
                             const std::shared_ptr<const LiveLighting>& lighting);
    Status freeze(std::shared_ptr<const TrackedFrame> frame,
                  const std::shared_ptr<const LiveLighting>& lighting);
    Result<ShotStep> refine(std::shared_ptr<const TrackedFrame> newest,
                            const std::shared_ptr<const LiveLighting>& lighting);
    // Lowers the preview's samples so one frame fits kMaxPreviewFrameMs (logged once).
    Status capPreviewSamples();
    // After a meter reading: the renderer's lighting fit (ShotRenderer::fitLighting), logged.
    void fitLighting(const TrackedFrame& frame, const PlateConsistency& reading, ShotStep& out);
    // Feeds the dial's live correction one preview frame's wall time.
    void correctDial(double frameSeconds);
    // A window's median handed to the dial (a held one as the point's own time, by the held
    // cost); a window paired with the other kind's recent one measures the held cost first.
    void closeDialWindow(bool held);
    // The held cost, where the window of `held`'s kind just closed (from firstFrame) pairs with
    // the other kind's recent one.
    void measureHeldCost(bool held, uint64_t firstFrame);
    // Forgets both kinds' frames and medians: nothing before pairs with what comes after.
    void clearDialWindows();
    uint32_t refineStepSamples() const;
    // Takes a plate-consistency reading of `frame` (just rendered with `lighting`) into `out` if
    // one is due (plateConsistency() says when) or `force`d; a failed readback is logged, not
    // fatal.
    void meterPlate(const TrackedFrame& frame, const std::shared_ptr<const LiveLighting>& lighting,
                    ShotStep& out, bool force = false);
    void tick();
    double msSince(ShotClock::TimePoint t) const;

    ShotRenderer& renderer_;
    const ModeMachine& modes_;
    const ShotClock& clock_;
    RefineConfig refine_;

    uint64_t seenVersion_ = 0;
    bool refining_ = false;
    std::shared_ptr<const TrackedFrame> current_;  // the newest frame seen
    std::shared_ptr<const TrackedFrame> frozen_;
    std::shared_ptr<const LiveLighting> frozenLighting_;  // what the frozen shot is lit by
    RefineWatch watch_;
    // When refinement stops: [refine] target_noise and max_samples, and the meter's looks.
    StoppingRule stopping_;
    uint64_t restarts_ = 0;
    // The ETA's cost per sample is the shot's time since it froze over its samples (steps,
    // meter looks, composites, tracking on the other core).
    ShotClock::TimePoint frozeAt_{};
    double refineMsPerSample_ = 0.0;
    double previewMsPerSample_ = 0.0;
    bool loggedPreviewCap_ = false;
    // The dial's live correction keeps a window for each kind of preview frame: [0] those at
    // the dial's point, [1] a held camera's at refinement's depth (lastPreviewOffDial). A held
    // frame costs heldCost_ times the point's own at the same load: measured where a window of
    // one kind closes right after the other kind's (the hold's first window against the frames
    // before it; the first window after it against the hold's last), kept through a long hold,
    // so the held windows between re-time the dial on the load alone. Unknown (a camera held
    // since the start, or since the dial's point changed: both windows start over): held frames
    // count as they are, which keeps them at the rate.
    struct DialFrameTimes {
        std::vector<double> seconds{};   // since this kind's last correction
        uint64_t lastFrame = 0;          // dialFrames_ at the newest
        std::optional<double> median{};  // the last window's, or the frames' as the kind changed
        uint64_t medianFrame = 0;        // dialFrames_ at its newest frame
    };
    DialFrameTimes dialTimes_[2];
    uint64_t dialFrames_ = 0;  // preview frames timed for the dial
    bool lastDialFrameHeld_ = false;
    std::optional<double> heldCost_;
    bool timesShownFrames_ = false;  // previewShown feeds the dial, not preview()
    double fps_ = 0.0;
    std::optional<ShotClock::TimePoint> lastFrame_;
    // The plate-consistency meter: its last reading, the pose and lighting it was taken with, and
    // its last try (a try without a reading waits kPlateMeterPeriod too).
    std::optional<PlateConsistencyReading> plate_;
    std::optional<LightingFitReport> lightingFit_;
    bool refitRestart_ = false;  // a fit changed the lighting: refinement starts over
    std::optional<cv::Matx44d> platePose_;
    std::shared_ptr<const LiveLighting> plateLighting_;
    std::optional<ShotClock::TimePoint> plateTried_;
};

}  // namespace previs
