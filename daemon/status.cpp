// The service's status: its one-line and JSON forms (docs/previsd.md, "Status"), and the
// ServiceStatus they are made from.

#include <nlohmann/json.hpp>

#include "daemon/service.h"
#include "daemon/service_threads.h"

namespace previs {

namespace {

using Clock = std::chrono::steady_clock;

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
        s.samples = t.renderer->previewSamples();
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

}  // namespace previs
