#include "shot/pipeline_stages.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "base/log.h"
#include "image/image.h"
#include "scene/environment_map.h"
#include "vision/equirect.h"
#include "vision/inverse_tone_map.h"

namespace previs {

namespace {

double millisecondsSince(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
        .count();
}

// ∫ luminance dω over an equirectangular map (exact texel solid angles per row), and the
// luminance's projection ∫ L(ω) Y_lm(ω) dω on the real spherical harmonics of bands 0–2 (texel
// centres as quadrature points).
double luminanceMoments(const cv::Mat& radiance, std::array<double, 9>& sh) {
    const int w = radiance.cols, h = radiance.rows;
    double total = 0.0;
    sh.fill(0.0);
    for (int y = 0; y < h; ++y) {
        const cv::Vec3f* row = radiance.ptr<cv::Vec3f>(y);
        const double texel = equirectTexelSolidAngle(y, w, h);
        double rowSum = 0.0;
        for (int x = 0; x < w; ++x) {
            const double l = luminance(glm::vec3(row[x][0], row[x][1], row[x][2]));
            if (!std::isfinite(l) || l <= 0.0) continue;
            rowSum += l;
            const cv::Vec3d d = equirectTexelDirection(x, y, w, h);
            const std::array<double, 9> basis = realShBand2(d);
            for (size_t i = 0; i < sh.size(); ++i) sh[i] += l * texel * basis[i];
        }
        total += rowSum * texel;
    }
    return total;
}

}  // namespace

Result<TrackingStage> TrackingStage::create(const ServiceConfig& config,
                                            std::shared_ptr<FreedInput> freed) {
    TrackerSettings settings = config.tracking.tracker;
    // One radiometric model per camera: the curve the plate is linearised with is the one the
    // tag edges are; a camera without one keeps libapriltag's corners (vision/tag_edges.h).
    if (config.sceneCamera.encodingGiven())
        settings.linearFromCode = linearFromCodeTable(config.sceneCamera.radiometry);
    else if (settings.linearEdges && !config.tracking.freedSource)
        logInfo(
            "{}: [cameras.scene] has no radiometry, so its tone curve is unknown and the tag "
            "corners are libapriltag's; give [cameras.scene.radiometry] (docs/config-format.md) "
            "for [tracking] linear_edges to re-fit them in linear light",
            config.path);
    Result<Tracker> tracker = Tracker::create(config.tracking.detector, *config.tracking.board,
                                              *config.sceneCamera.calibration, settings);
    if (!tracker) return tracker.error();
    std::optional<PoseFilter> filter;
    if (config.tracking.poseFilter) filter.emplace();
    TrackingStage stage(std::move(*tracker), config.sceneCamera.calibration->imageSize(),
                        std::move(filter));
    if (!config.tracking.freedSource) return stage;
    if (!freed && config.sceneCamera.source == CameraSourceKind::Session) {
        // The recorded camera's folder is the take's cameras/scene.
        const std::string csv =
            (std::filesystem::path(config.sceneCamera.device).parent_path().parent_path() /
             "freed.csv")
                .string();
        Result<std::unique_ptr<FreedInput>> recorded = FreedInput::recorded(csv, config.tracking);
        if (!recorded) return makeError("[tracking] source = \"freed\": {}", recorded.message());
        freed = std::move(*recorded);
    }
    if (!freed)
        return makeError("[tracking] source = \"freed\": no FreeD input (set [tracking] listen)");
    stage.freedLive_ = freed->live();
    stage.freed_ = std::move(freed);
    if (stage.freedLive_) {
        const double delayMs =
            config.tracking.freedCalibration ? config.tracking.freedCalibration->delayMs : 0.0;
        stage.freedWait_ = std::chrono::milliseconds(int64_t(std::max(delayMs, 0.0)) + 50);
    }
    return stage;
}

void TrackingStage::trackFreed(TrackedFrame& out) {
    // Live packets are stamped on arrival: matched to when this machine saw the frame taken
    // (a recording's frames carry old timestamps); recorded ones to the recorded times.
    const int64_t frameNs =
        freedLive_ ? captureInstantNs(out, out.receivedNs) : int64_t(out.frame->timestampNs);
    const std::optional<cv::Matx44d> pose = freed_->worldFromCamera(frameNs, freedWait_);
    out.lost = !pose;
    if (!pose) {
        out.lostReason = LostReason::NoTrackerData;
        out.reason = "no FreeD packet near the frame's time";
        out.worldFromCamera = lastFreed_;  // the last one, as a lost tag pose does
        return;
    }
    out.lostReason = LostReason::None;
    out.reason.clear();
    out.worldFromCamera = pose;
    out.trackedWorldFromCamera = pose;
    lastFreed_ = pose;
}

int64_t captureInstantNs(const TrackedFrame& frame, int64_t nowNs) {
    const int64_t captured = int64_t(frame.frame->timestampNs);
    return std::llabs(nowNs - captured) < 10'000'000'000LL ? captured : frame.receivedNs;
}

TrackedFrame TrackingStage::process(std::shared_ptr<const Frame> frame) {
    const auto start = std::chrono::steady_clock::now();
    TrackedFrame out;
    out.receivedNs =
        std::chrono::duration_cast<std::chrono::nanoseconds>(start.time_since_epoch()).count();
    if (freed_) {
        out.frame = std::move(frame);
        trackFreed(out);
        out.trackMs = millisecondsSince(start);
        return out;
    }
    if (int(frame->width) != calibrated_.width || int(frame->height) != calibrated_.height) {
        out.lostReason = LostReason::FrameSize;
        out.reason =
            fmt::format("the frame is {}x{} but the calibration is for {}x{}", frame->width,
                        frame->height, calibrated_.width, calibrated_.height);
        if (!loggedSize_)
            logError("tracking: {}; no pose is tracked (record or calibrate at one size)",
                     out.reason);
        loggedSize_ = true;
        const TrackingState& held = tracker_.state();
        if (held.pose) out.worldFromCamera = held.pose->worldFromCamera;
        out.frame = std::move(frame);
        return out;
    }
    const cv::Mat rgb(int(frame->height), int(frame->width), CV_8UC3,
                      const_cast<uint8_t*>(frame->rgb.data()));
    cv::Mat gray;
    cv::cvtColor(rgb, gray, cv::COLOR_RGB2GRAY);
    const TrackingState& state = tracker_.track(gray);
    const uint64_t timestampNs = frame->timestampNs;
    out.frame = std::move(frame);
    out.lost = state.lost;
    out.reason = state.reason;
    out.lostReason = state.lostReason;
    if (state.pose) {
        out.worldFromCamera = state.pose->worldFromCamera;
        out.tags = int(state.pose->tagIds.size());
        out.reprojErrorPx = state.pose->reprojErrorPx;
        out.positionStdM = state.pose->positionStdM;
        out.rotationStdDeg = state.pose->rotationStdDeg;
        if (!state.lost) out.trackedWorldFromCamera = state.pose->worldFromCamera;
    }
    if (filter_) {
        const TrackSample sample{timestampNs, out.trackedWorldFromCamera, out.positionStdM,
                                 out.rotationStdDeg};
        if (std::optional<cv::Matx44d> filtered = filter_->update(sample)) {
            out.worldFromCamera = filtered;
            out.filtered = true;
        }
    }
    out.trackMs = millisecondsSince(start);
    return out;
}

Result<LightingStage> LightingStage::create(const ServiceConfig& config) {
    if (!config.fisheyeCamera) return makeError("{}: no [cameras.fisheye]", config.path);
    Result<FisheyeToEquirect> toEquirect =
        FisheyeToEquirect::create(*config.fisheyeCamera->calibration, config.lighting.fisheye);
    if (!toEquirect)
        return makeError("{}: [cameras.fisheye]: {}", config.path, toEquirect.message());
    std::optional<BracketAssembler> bracket;
    if (config.fisheyeCamera->bracket) {
        Result<BracketAssembler> a = BracketAssembler::create(*config.fisheyeCamera->bracket,
                                                              config.fisheyeCamera->radiometry);
        if (!a) return makeError("{}: [cameras.fisheye.bracket]: {}", config.path, a.message());
        bracket = std::move(*a);
    }
    return LightingStage(std::move(*toEquirect), config.fisheyeCamera->radiometry,
                         std::move(bracket), config.lighting.mode, config.lighting.lights,
                         config.lighting.updateHz);
}

bool LightingStage::due(const Frame& frame) const {
    if (bracket_ && bracket_->inProgress()) return true;
    const bool timeHasCome =
        !lastNs_ || frame.timestampNs < *lastNs_ || frame.timestampNs - *lastNs_ >= periodNs_;
    // A bracket starts only at the cycle's first exposure; the frames between brackets are the
    // camera's other exposures, which process() would only set aside.
    return timeHasCome && (!bracket_ || bracket_->startsBracket(frame.exposureStops));
}

const BracketCounts* LightingStage::bracketCounts() const {
    return bracket_ ? &bracket_->counts() : nullptr;
}

std::string LightingStage::lastBracketDrop() const {
    return bracket_ ? bracket_->lastDrop() : std::string();
}

Result<std::shared_ptr<const LiveLighting>> LightingStage::process(const Frame& frame) {
    const auto start = std::chrono::steady_clock::now();
    const cv::Mat rgb(int(frame.height), int(frame.width), CV_8UC3,
                      const_cast<uint8_t*>(frame.rgb.data()));
    Result<std::shared_ptr<LiveLighting>> out = std::shared_ptr<LiveLighting>();
    if (bracket_) {
        const bool starts = !bracket_->inProgress();
        std::optional<MergedBracket> merged =
            bracket_->add(rgb, frame.sequence, frame.timestampNs, frame.exposureStops);
        // The period runs from a bracket's first frame, as from a single frame's.
        if (starts && bracket_->inProgress()) lastNs_ = frame.timestampNs;
        if (!merged) return std::shared_ptr<const LiveLighting>();
        out = fromBracket(*merged);
    } else {
        lastNs_ = frame.timestampNs;
        // One frame is a bracket of one: linearised at its exposure (a bracketing camera's frame
        // lit on its own is labelled), its clipped pixels flagged.
        Result<MergedBracket> one =
            mergeBracket({rgb}, {frame.exposureStops.value_or(0.0f)}, radiometry_);
        if (!one) return one.error();
        one->firstSequence = one->lastSequence = frame.sequence;
        out = fromBracket(*one);
    }
    if (!out) return out.error();
    (*out)->sequence = frame.sequence;
    (*out)->timestampNs = frame.timestampNs;
    (*out)->computeMs = millisecondsSince(start);
    return std::shared_ptr<const LiveLighting>(std::move(*out));
}

Result<std::shared_ptr<LiveLighting>> LightingStage::fromBracket(const MergedBracket& merged) {
    Result<cv::Mat> map = toEquirect_.apply(merged.radiance);
    if (!map) return map.error();
    auto out = fromMap(*map, bracket_ ? fmt::format("fisheye bracket {}-{}", merged.firstSequence,
                                                    merged.lastSequence)
                                      : fmt::format("fisheye frame {}", merged.firstSequence));
    if (!out) return out.error();
    if (bracket_) (*out)->bracketFrames = int(merged.lastSequence - merged.firstSequence + 1);
    if (merged.clippedFraction > 0.0) {
        Result<cv::Mat> clipped = toEquirect_.applyAny(merged.clipped);
        if (!clipped) return clipped.error();
        double solidAngle = 0.0;
        for (int y = 0; y < clipped->rows; ++y)
            for (int x = 0; x < clipped->cols; ++x)
                if (clipped->at<uint8_t>(y, x))
                    solidAngle += equirectTexelSolidAngle(y, clipped->cols, clipped->rows);
        (*out)->clippedTexels = std::move(*clipped);
        (*out)->clippedSolidAngleFraction = solidAngle / (4.0 * M_PI);
    }
    return out;
}

Result<std::shared_ptr<const LiveLighting>> LightingStage::restore(const std::string& path) {
    Result<EnvironmentMap> map = loadEnvironmentMap(path);
    if (!map) return map.error();
    auto out = fromMap(environmentMapToMat(*map), fmt::format("{} (saved lighting)", path));
    if (!out) return out.error();
    (*out)->restored = true;
    return std::shared_ptr<const LiveLighting>(std::move(*out));
}

Result<std::shared_ptr<LiveLighting>> LightingStage::fromMap(const cv::Mat& map,
                                                             const std::string& name) {
    auto out = std::make_shared<LiveLighting>();
    out->totalLuminancePower = luminanceMoments(map, out->luminanceSh);
    out->captured = std::make_shared<const EnvironmentMap>(matToEnvironmentMap(map, name));
    if (mode_ == LightingMode::Lights) {
        Result<LightingSnapshot> lights = estimator_.estimate(map);
        if (!lights) return lights.error();
        out->lights = std::move(lights->lights);
        out->environment = std::make_shared<const EnvironmentMap>(
            matToEnvironmentMap(lights->residual, name + " (residual)"));
    } else {
        out->environment = out->captured;
    }
    return out;
}

Status writeLightingMap(const LiveLighting& lighting, AtomicFile& file) {
    if (!lighting.captured) return makeError("lighting '{}': no captured map", file.path());
    const EnvironmentMap& map = *lighting.captured;
    ImageF image;
    image.width = map.width;
    image.height = map.height;
    image.channels = 3;
    image.pixels.reserve(map.radiance.size() * 3);
    for (const glm::vec3& v : map.radiance)
        image.pixels.insert(image.pixels.end(), {v.r, v.g, v.b});
    return writeExr(file.fd(), file.path(), image);
}

Status saveLighting(const LiveLighting& lighting, const std::string& path) {
    // Not synced, as before: the next save follows within seconds.
    Result<AtomicFile> file = AtomicFile::create(path, {.durable = false});
    if (!file) return makeError("cannot save the lighting: {}", file.message());
    if (Status s = writeLightingMap(lighting, *file); !s) return s;
    if (Status s = file->commit(); !s)
        return makeError("cannot save the lighting: {}", s.message());
    return {};
}

std::shared_ptr<const LiveLighting> correctedLighting(
    const std::shared_ptr<const LiveLighting>& lighting, const LightingCorrection& correction) {
    if (!lighting || !lighting->captured) return lighting;
    const std::vector<std::vector<int>> clusters = clippedClusters(lighting->clippedTexels);
    auto out = std::make_shared<LiveLighting>(*lighting);
    const cv::Mat captured =
        applyCorrection(environmentMapToMat(*lighting->captured), clusters, correction);
    out->totalLuminancePower = luminanceMoments(captured, out->luminanceSh);
    out->captured = std::make_shared<const EnvironmentMap>(
        matToEnvironmentMap(captured, lighting->captured->path + " (fitted to the plate)"));
    if (lighting->environment == lighting->captured) {
        out->environment = out->captured;
    } else if (lighting->environment) {
        // The lights were split off the map: the residual holds no clipped cluster (the
        // lights took them), so it takes the global gain, and each light its cluster's too.
        out->environment = std::make_shared<const EnvironmentMap>(matToEnvironmentMap(
            applyCorrection(environmentMapToMat(*lighting->environment), {}, correction),
            lighting->environment->path + " (fitted to the plate)"));
        const float cosMatch = float(std::cos(kCorrectionMatchDeg * M_PI / 180.0));
        for (EstimatedLight& l : out->lights) {
            const glm::vec3 d(float(l.direction[0]), float(l.direction[1]), float(l.direction[2]));
            double gain = 1.0;
            for (const LightingCorrection::Cluster& c : correction.clusters)
                if (glm::dot(c.direction, d) >= cosMatch) gain = c.gain;
            for (int ch = 0; ch < 3; ++ch) {
                l.radiance[ch] *= gain * correction.globalGain[size_t(ch)];
                l.power[ch] *= gain * correction.globalGain[size_t(ch)];
            }
        }
    }
    return out;
}

std::string estimatedLightsJson(const std::vector<EstimatedLight>& lights) {
    nlohmann::ordered_json list = nlohmann::ordered_json::array();
    for (const EstimatedLight& l : lights)
        list.push_back({{"direction", {l.direction[0], l.direction[1], l.direction[2]}},
                        {"solidAngleSr", l.solidAngleSr},
                        {"radiance", {l.radiance[0], l.radiance[1], l.radiance[2]}}});
    return nlohmann::ordered_json{{"lights", list}}.dump();
}

PoseDelta poseDelta(const cv::Matx44d& a, const cv::Matx44d& b) {
    PoseDelta d;
    const cv::Vec3d ta(a(0, 3), a(1, 3), a(2, 3)), tb(b(0, 3), b(1, 3), b(2, 3));
    d.translationM = cv::norm(ta - tb);
    // Angle of Ra^T Rb from its trace.
    double trace = 0.0;
    for (int i = 0; i < 3; ++i)
        for (int k = 0; k < 3; ++k) trace += a(k, i) * b(k, i);
    d.rotationDeg = std::acos(std::clamp((trace - 1.0) / 2.0, -1.0, 1.0)) * 180.0 / M_PI;
    return d;
}

std::array<double, 9> realShBand2(const cv::Vec3d& d) {
    const double x = d[0], y = d[1], z = d[2];
    return {0.282094791773878,
            0.488602511902920 * y,
            0.488602511902920 * z,
            0.488602511902920 * x,
            1.092548430592079 * x * y,
            1.092548430592079 * y * z,
            0.315391565252520 * (3.0 * z * z - 1.0),
            1.092548430592079 * x * z,
            0.546274215296040 * (x * x - y * y)};
}

}  // namespace previs
