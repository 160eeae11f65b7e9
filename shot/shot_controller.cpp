#include "shot/shot_controller.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "base/log.h"

namespace previs {

bool TrackingPace::due(Mode mode, uint64_t captureNs) {
    const uint64_t periodNs = uint64_t(std::chrono::nanoseconds(kRefinePeriod).count());
    // A looping recording starts its clock over: a time before the last one is a new pass.
    const bool waited = !lastNs_ || captureNs < *lastNs_ || captureNs - *lastNs_ >= periodNs;
    if (mode == Mode::Refine && !waited) return false;
    lastNs_ = captureNs;
    return true;
}

ShotController::ShotController(ShotRenderer& renderer, const ModeMachine& modes,
                               const ShotClock& clock, const RefineConfig& refine)
    : renderer_(renderer),
      modes_(modes),
      clock_(clock),
      refine_(refine),
      seenVersion_(modes.version()),
      watch_(refine),
      stopping_(refine.targetNoise, refine.maxSamples) {}

void ShotController::setConfig(const LiveConfig& live) {
    refine_ = live.refine;
    watch_.setConfig(live.refine);
    stopping_.setLimits(live.refine.targetNoise, live.refine.maxSamples);
    // The dial chooses preview's samples while it runs ([render] preview_fps).
    if (renderer_.hasDial()) return;
    const uint32_t samples = live.liveRender.samplesPerFrame;
    PreviewSettings configured = renderer_.preview().configured;
    if (samples == configured.samplesPerFrame) return;
    configured.samplesPerFrame = samples;
    if (Status s = renderer_.setPreview(configured, samples); !s)
        logError("render: samples_per_frame = {}: {}", samples, s.message());
    loggedPreviewCap_ = false;
}

bool ShotController::wantsFrame() const {
    const bool refineNow = modes_.mode() == Mode::Refine;
    const bool versionChanged = modes_.version() != seenVersion_;
    return !refineNow || !refining_ || versionChanged;
}

double ShotController::msSince(ShotClock::TimePoint t) const {
    return std::chrono::duration<double, std::milli>(clock_.now() - t).count();
}

void ShotController::tick() {
    const ShotClock::TimePoint now = clock_.now();
    if (lastFrame_) {
        const double dt = std::chrono::duration<double>(now - *lastFrame_).count();
        // An exponential average over about 8 frames: steady on screen, quick to follow.
        if (dt > 0.0) fps_ = fps_ == 0.0 ? 1.0 / dt : 0.875 * fps_ + 0.125 / dt;
    }
    lastFrame_ = now;
}

const char* toString(LightingFitReport::State state) {
    switch (state) {
        case LightingFitReport::State::NotNeeded:
            return "not-needed";
        case LightingFitReport::State::Fitted:
            return "fitted";
        case LightingFitReport::State::Failed:
            return "failed";
        case LightingFitReport::State::Off:
            return "off";
    }
    return "?";
}

Result<ShotStep> ShotController::step(std::shared_ptr<const TrackedFrame> newest,
                                      std::shared_ptr<const LiveLighting> lighting) {
    const Mode mode = modes_.mode();
    // Out of refinement and back within one step still re-freezes on the newest frame.
    const uint64_t version = modes_.version();
    if (refining_ && version != seenVersion_) refining_ = false;
    seenVersion_ = version;
    if (mode == Mode::Preview) {
        if (frozen_) {
            // Back from refinement: the first frames re-size the traced buffers.
            frozen_.reset();
            frozenLighting_.reset();
            fps_ = 0.0;
            lastFrame_.reset();
            clearDialWindows();
        }
        return preview(std::move(newest), lighting);
    }
    return refine(std::move(newest), lighting);
}

Result<ShotStep> ShotController::preview(std::shared_ptr<const TrackedFrame> frame,
                                         const std::shared_ptr<const LiveLighting>& lighting) {
    ShotStep out;
    out.mode = Mode::Preview;
    if (!frame) return out;
    current_ = frame;
    if (Status s = capPreviewSamples(); !s) return s.error();
    out.start = clock_.now();
    if (Status s = renderer_.renderPreview(*frame, lighting); !s) return s.error();
    const double ms = msSince(out.start);
    previewMsPerSample_ = ms / std::max(1u, previewSamples());
    tick();
    out.kind = ShotStep::Kind::Previewed;
    out.shown = std::move(frame);
    out.fps = fps_;
    if (!timesShownFrames_) correctDial(ms * 1e-3);
    meterPlate(*out.shown, lighting, out);
    return out;
}

void ShotController::meterPlate(const TrackedFrame& frame,
                                const std::shared_ptr<const LiveLighting>& lighting, ShotStep& out,
                                bool force) {
    // A held pose (tracking lost) may be off by anything: the phantom set would not lie on the
    // plate's real surfaces.
    // A stand-in lighting says nothing of the set's.
    if (!renderer_.rendered() || !frame.worldFromCamera || frame.lost || !frame.frame ||
        renderer_.lightingPending())
        return;
    const ShotClock::TimePoint now = clock_.now();
    // A looping recording starts its clock over: a time before the last try is a new pass.
    if (!force && plateTried_ && now >= *plateTried_ && now - *plateTried_ < kPlateMeterPeriod)
        return;
    bool due = force || !platePose_;
    if (!due) {
        const PoseDelta d = poseDelta(*platePose_, *frame.worldFromCamera);
        due = d.translationM > refine_.poseThresholdM || d.rotationDeg > refine_.poseThresholdDeg;
    }
    if (!due && lighting != plateLighting_)
        due = !lighting || !plateLighting_ ||
              lightingDelta(*lighting, *plateLighting_).change > refine_.lightingThreshold;
    if (!due) return;
    plateTried_ = now;
    Result<std::optional<PlateConsistency>> measured = renderer_.measurePlateConsistency();
    if (!measured) {
        logWarning("plate consistency: {}", measured.message());
        return;
    }
    if (!*measured) return;
    platePose_ = frame.worldFromCamera;
    plateLighting_ = lighting;
    PlateConsistencyReading reading{**measured, frame.frame->sequence, frame.frame->timestampNs};
    const PlateConsistency& v = reading.value;
    // Said once as it goes out of range (and once back), not every reading.
    if (!v.ok && (!plate_ || plate_->value.ok))
        logWarning(
            "plate consistency: the real-only render is {:.2f} {:.2f} {:.2f} (RGB) times the plate "
            "over {} real-surface cells of frame {}, outside [{}, {}]: the captured lighting does "
            "not explain the picture (a fisheye that clips the lamps reads far below 1)",
            v.ratio[0], v.ratio[1], v.ratio[2], v.pixels, reading.frame, kPlateConsistencyLow,
            kPlateConsistencyHigh);
    else if (v.ok && plate_ && !plate_->value.ok)
        logInfo("plate consistency: back within range ({:.2f} {:.2f} {:.2f})", v.ratio[0],
                v.ratio[1], v.ratio[2]);
    plate_ = reading;
    out.plateConsistency = std::move(reading);
    fitLighting(frame, v, out);
}

void ShotController::fitLighting(const TrackedFrame& frame, const PlateConsistency& reading,
                                 ShotStep& out) {
    LightingFitReport fit = renderer_.fitLighting(frame, reading);
    if (fit.state == LightingFitReport::State::NotNeeded) return;
    const bool firstFailure = fit.state == LightingFitReport::State::Failed &&
                              (!lightingFit_ || lightingFit_->state != fit.state);
    if (fit.state == LightingFitReport::State::Fitted) {
        std::string gains;
        for (double g : fit.fit.clusterGains) gains += fmt::format(" {:.3g}", g);
        logInfo(
            "lighting: fitted to the plate on frame {}: clipped lights ×{}, global ×{:.3f} "
            "{:.3f} {:.3f}; |log residual| {:.3f} -> {:.3f} over {} cells",
            fit.frame, gains.empty() ? " (none)" : gains, fit.fit.globalGain[0],
            fit.fit.globalGain[1], fit.fit.globalGain[2], fit.fit.residualBefore,
            fit.fit.residualAfter, fit.fit.samples);
    } else if (firstFailure) {
        logWarning(
            "lighting: the fit to the plate failed on frame {} ({}); the last good "
            "lighting stays",
            fit.frame, fit.why);
    }
    if (fit.changed && refining_) refitRestart_ = true;
    lightingFit_ = fit;
    out.lightingFit = std::move(fit);
}

Status ShotController::capPreviewSamples() {
    const PreviewState preview = renderer_.preview();
    const uint32_t wanted = preview.configured.samplesPerFrame;
    if (!(previewMsPerSample_ > 0.0) || renderer_.hasDial()) return {};
    const uint32_t fits = std::max(1u, uint32_t(kMaxPreviewFrameMs / previewMsPerSample_));
    const uint32_t use = std::min(wanted, fits);
    if (use < wanted && !loggedPreviewCap_) {
        logWarning(
            "render: {} samples per preview frame would take {:.0f} ms; rendering {} (lower "
            "render.samples_per_frame)",
            wanted, wanted * previewMsPerSample_, use);
        loggedPreviewCap_ = true;
    }
    if (use == preview.inUse.samplesPerFrame) return {};
    return renderer_.setPreview(preview.configured, use);
}

void ShotController::previewShown(double frameSeconds) {
    // The first shown frame's render time went in already (preview() could not know yet).
    std::vector<double>& window = dialTimes_[lastDialFrameHeld_].seconds;
    if (!timesShownFrames_ && !window.empty()) window.pop_back();
    timesShownFrames_ = true;
    correctDial(frameSeconds);
}

namespace {

double medianOf(std::vector<double> values) {
    const auto middle = values.begin() + ptrdiff_t(values.size() / 2);
    std::nth_element(values.begin(), middle, values.end());
    return *middle;
}

}  // namespace

void ShotController::clearDialWindows() {
    for (DialFrameTimes& t : dialTimes_) t = {};
}

void ShotController::correctDial(double frameSeconds) {
    if (!renderer_.hasDial() || !(frameSeconds > 0.0)) return;
    const bool held = renderer_.lastPreviewOffDial();
    const uint64_t frame = ++dialFrames_;
    DialFrameTimes& mine = dialTimes_[held];
    DialFrameTimes& other = dialTimes_[!held];
    // Frames a window of the other kind ago are another load's (a long hold, a long move).
    if (!mine.seconds.empty() && frame - mine.lastFrame > kDialWindowFrames) mine.seconds.clear();
    // The camera starts or stops holding: the frames before it are what pairs with this kind's
    // first window (and, dated by their newest, with no later one).
    if (held != lastDialFrameHeld_ && other.seconds.size() >= kDialPairFrames) {
        other.median = medianOf(other.seconds);
        other.medianFrame = other.lastFrame;
    }
    lastDialFrameHeld_ = held;
    mine.seconds.push_back(frameSeconds);
    mine.lastFrame = frame;
    if (mine.seconds.size() >= kDialWindowFrames) closeDialWindow(held);
}

void ShotController::closeDialWindow(bool held) {
    DialFrameTimes& mine = dialTimes_[held];
    const double median = medianOf(mine.seconds);
    const uint64_t firstFrame = mine.lastFrame + 1 - mine.seconds.size();
    mine.seconds.clear();
    mine.median = median;
    mine.medianFrame = mine.lastFrame;
    measureHeldCost(held, firstFrame);
    const double pointSeconds = held && heldCost_ ? median / *heldCost_ : median;
    const PreviewSettings pointBefore = renderer_.preview().configured;
    std::optional<std::string> now = renderer_.adaptDial(pointSeconds, heldCost_.value_or(1.0));
    if (!now) return;
    logInfo("render: preview now at {}", *now);
    // Another point: the frames so far, and the held cost, are the old point's.
    if (!(renderer_.preview().configured == pointBefore)) {
        clearDialWindows();
        heldCost_.reset();
    }
}

void ShotController::measureHeldCost(bool held, uint64_t firstFrame) {
    const DialFrameTimes& mine = dialTimes_[held];
    const DialFrameTimes& other = dialTimes_[!held];
    // The other kind's window just before or during this one: the same load.
    if (!other.median || other.medianFrame + kDialWindowFrames < firstFrame) return;
    const double heldMedian = held ? *mine.median : *other.median;
    const double pointMedian = held ? *other.median : *mine.median;
    // As measured, under 1 too (a held view's frames can be quicker: BENCHMARKS.md), so a hold
    // re-times the dial on the load alone.
    const double cost = heldMedian / pointMedian;
    // Said when it first is known and as it changes by a tenth, not at every hold.
    if (!heldCost_ || std::abs(cost / *heldCost_ - 1.0) > 0.1)
        logInfo("render: a held camera's frames take {:.2f}x the dial point's ({:.0f} ms)", cost,
                heldMedian * 1e3);
    heldCost_ = cost;
}

Status ShotController::freeze(std::shared_ptr<const TrackedFrame> frame,
                              const std::shared_ptr<const LiveLighting>& lighting) {
    frozen_ = std::move(frame);
    frozenLighting_ = lighting;
    if (Status s = renderer_.beginRefine(*frozen_, lighting); !s)
        return makeError("cannot start refinement: {}", s.message());
    refining_ = true;
    watch_.freeze(*frozen_, lighting);
    stopping_.restart();
    frozeAt_ = clock_.now();
    refineMsPerSample_ = 0.0;
    fps_ = 0.0;
    lastFrame_.reset();
    logInfo("refinement: frame {} frozen{}", frozen_->frame->sequence,
            renderer_.rendered() ? "" : " (no pose yet: showing the camera picture)");
    return {};
}

uint32_t ShotController::refineStepSamples() const {
    uint32_t step = refine_.samplesPerStep;
    if (refineMsPerSample_ > 0.0)
        step = std::clamp(uint32_t(kRefineStepTargetMs / refineMsPerSample_), 1u, step);
    if (stopping_.maxSamples() > 0)
        step = uint32_t(std::min<uint64_t>(step, stopping_.maxSamples() - renderer_.samples()));
    return step;
}

Result<ShotStep> ShotController::refine(std::shared_ptr<const TrackedFrame> newest,
                                        const std::shared_ptr<const LiveLighting>& lighting) {
    ShotStep out;
    out.mode = Mode::Refine;
    out.start = clock_.now();
    if (newest) current_ = newest;
    if (!refining_) {
        if (!current_) return out;  // nothing to freeze yet
        if (Status s = freeze(current_, lighting); !s) return s.error();
    } else {
        // A change of pose or lighting that persists re-freezes the shot on the newest frame and
        // lighting and starts the accumulation over; anything smaller is noise.
        std::optional<std::string> restart;
        if (newest) restart = watch_.observeFrame(*newest);
        if (!restart) restart = watch_.observeLighting(lighting);
        if (!restart && refitRestart_) restart = "the lighting was fitted to the plate";
        refitRestart_ = false;
        if (restart) {
            logInfo("refinement: restarting on frame {}: {}", current_->frame->sequence, *restart);
            ++restarts_;
            out.restarted = true;
            if (Status s = freeze(current_, lighting); !s) return s.error();
        }
    }
    out.shown = frozen_;
    if (!renderer_.rendered() || stopping_.done(renderer_.samples())) {
        out.kind = ShotStep::Kind::Held;
        out.noiseEstimate = stopping_.noiseAt(renderer_.samples());
        return out;
    }
    const uint32_t samples = refineStepSamples();
    const ShotClock::TimePoint stepStart = clock_.now();
    if (Status s = renderer_.refineStep(samples); !s) return s.error();
    refineMsPerSample_ = msSince(stepStart) / samples;
    tick();
    const uint64_t total = renderer_.samples();
    if (Status s = stopping_.lookIfDue(total, [this] { return renderer_.measureNoise(); }); !s)
        logWarning("render: convergence meter: {}", s.message());
    out.kind = ShotStep::Kind::Refined;
    out.fps = fps_;
    out.noiseEstimate = stopping_.noiseAt(total);
    out.etaSeconds =
        stopping_.eta(total, msSince(frozeAt_) * 1e-3 / double(std::max<uint64_t>(total, 1)));
    const bool converged = stopping_.done(total);
    // Converged, the refinement's L_or is the meter's best input, and already there.
    meterPlate(*frozen_, frozenLighting_, out, converged);
    if (converged) {
        out.converged = true;
        logInfo("refinement: reached {} samples per pixel{}", total,
                stopping_.measured()
                    ? fmt::format(", noise estimate {:.2f} %", *stopping_.measured() * 100.0)
                    : "");
    }
    return out;
}

}  // namespace previs
