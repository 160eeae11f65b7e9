#include "bench/bench_pose_filter.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <optional>
#include <vector>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "io/session.h"
#include "render/board_render.h"
#include "take/take_files.h"
#include "take/take_track.h"
#include "vision/board_file.h"
#include "vision/board_pose.h"
#include "vision/pose_filter.h"

namespace previs::bench {

namespace {

// One sequence: per frame its time, the truth (if known) and the tracker's raw samples.
struct Sequence {
    std::string name;
    std::vector<double> seconds;
    std::vector<std::optional<cv::Matx44d>> truth;
    std::vector<TrackSample> samples;
    std::vector<size_t> still;   // frames where the camera holds still
    std::vector<size_t> moving;  // frames where it moves
    size_t motionStart = 0;      // first frame of a move after a hold (0: none)
};

cv::Vec3d positionOf(const cv::Matx44d& m) { return {m(0, 3), m(1, 3), m(2, 3)}; }

struct Measured {
    double jitterMm = NAN, jitterDeg = NAN;  // over the still frames
    double movingMm = NAN;                   // median position error while moving
    double lagMs = NAN;                      // the delay that best aligns with the truth
    double stepMaxMm = NAN;                  // largest error in the 5 frames after the move starts
};

// Jitter: the standard deviation about the mean over the still frames, RMS over the three axes,
// of the position and of the rotation (as small rotation vectors from the first still pose).
Measured measure(const Sequence& s, const std::vector<std::optional<cv::Matx44d>>& poses) {
    Measured m;
    std::vector<cv::Vec3d> p, r;
    std::optional<cv::Matx33d> reference;
    for (size_t i : s.still) {
        if (!poses[i]) continue;
        const cv::Matx33d rotation = poses[i]->get_minor<3, 3>(0, 0);
        if (!reference) reference = rotation;
        cv::Vec3d v;
        cv::Rodrigues(reference->t() * rotation, v);
        p.push_back(positionOf(*poses[i]) * 1e3);
        r.push_back(v * (180.0 / CV_PI));
    }
    auto spread = [](const std::vector<cv::Vec3d>& values) {
        cv::Vec3d mean(0, 0, 0);
        for (const cv::Vec3d& v : values) mean += v;
        mean *= 1.0 / double(values.size());
        double sum = 0.0;
        for (const cv::Vec3d& v : values) sum += (v - mean).dot(v - mean);
        return std::sqrt(sum / double(values.size()) / 3.0);
    };
    if (p.size() >= 3) {
        m.jitterMm = spread(p);
        m.jitterDeg = spread(r);
    }
    std::vector<double> errors;
    for (size_t i : s.moving)
        if (poses[i] && s.truth[i])
            errors.push_back(cv::norm(positionOf(*poses[i]) - positionOf(*s.truth[i])) * 1e3);
    if (!errors.empty()) {
        std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
        m.movingMm = errors[errors.size() / 2];
    }
    // Lag: the delay d (0…200 ms, 1 ms steps) minimising the RMS distance between each moving
    // pose and the truth d earlier (linearly interpolated between frames).
    auto truthAt = [&](double t) -> std::optional<cv::Vec3d> {
        for (size_t i = 0; i + 1 < s.seconds.size(); ++i)
            if (s.seconds[i] <= t && t <= s.seconds[i + 1] && s.truth[i] && s.truth[i + 1]) {
                const double w = (t - s.seconds[i]) / (s.seconds[i + 1] - s.seconds[i]);
                return (1 - w) * positionOf(*s.truth[i]) + w * positionOf(*s.truth[i + 1]);
            }
        return std::nullopt;
    };
    double best = INFINITY;
    for (int d = 0; d <= 200; ++d) {
        double sum = 0.0;
        int n = 0;
        for (size_t i : s.moving) {
            if (!poses[i]) continue;
            std::optional<cv::Vec3d> t = truthAt(s.seconds[i] - d * 1e-3);
            if (!t) continue;
            sum += cv::norm(positionOf(*poses[i]) - *t) * cv::norm(positionOf(*poses[i]) - *t);
            ++n;
        }
        if (n > 0 && sum / n < best) {
            best = sum / n;
            m.lagMs = d;
        }
    }
    if (s.motionStart > 0) {
        m.stepMaxMm = 0.0;
        for (size_t i = s.motionStart; i < std::min(s.samples.size(), s.motionStart + 5); ++i)
            if (poses[i] && s.truth[i])
                m.stepMaxMm = std::max(
                    m.stepMaxMm, cv::norm(positionOf(*poses[i]) - positionOf(*s.truth[i])) * 1e3);
    }
    return m;
}

std::vector<std::optional<cv::Matx44d>> rawPoses(const Sequence& s) {
    std::vector<std::optional<cv::Matx44d>> out;
    for (const TrackSample& t : s.samples) out.push_back(t.worldFromCamera);
    return out;
}

std::vector<std::optional<cv::Matx44d>> filteredPoses(const Sequence& s) {
    PoseFilter filter;
    std::vector<std::optional<cv::Matx44d>> out;
    for (const TrackSample& t : s.samples) out.push_back(filter.update(t));
    return out;
}

void addSample(Sequence& s, const TrackingState& st, double seconds) {
    TrackSample t;
    t.timestampNs = uint64_t(std::llround(seconds * 1e9));
    if (!st.lost && st.pose) {
        t.worldFromCamera = st.pose->worldFromCamera;
        t.positionStdM = st.pose->positionStdM;
        t.rotationStdDeg = st.pose->rotationStdDeg;
    }
    s.samples.push_back(t);
    s.seconds.push_back(seconds);
}

// The A2 poster at 1.5 m, 30° off its normal, 30 fps: still for `still` frames, then orbiting
// the board's normal at 30°/s (0.4 m/s) for as many.
Result<Sequence> renderedOrbit(GpuContext& ctx, int still, uint32_t spp) {
    Sequence s;
    s.name = "rendered orbit (A2 board, 1.5 m, 640×480)";
    const CameraCalibration lens =
        CameraCalibration::create(cv::Matx33d(502, 0, 322.4, 0, 498, 236.9, 0, 0, 1),
                                  {-0.25, 0.08, 3e-4, -2e-4, 0.0}, cv::Size(640, 480),
                                  DistortionModel::Pinhole, "rad-tan lens")
            .value();
    auto renderer = BoardRenderer::create(ctx, posterBoard(), "tag36h11", lens, spp);
    if (!renderer) return renderer.error();
    TrackerSettings srgbCamera;  // the orbit is rendered through sRGB
    srgbCamera.linearFromCode = linearFromCodeTable(InverseToneMapSettings{});
    auto tracker = Tracker::create({}, posterBoard(), lens, srgbCamera);
    if (!tracker) return tracker.error();
    for (int i = 0; i < 2 * still; ++i) {
        benchProgress("filter: rendered orbit frame {}/{}", i + 1, 2 * still);
        const double t = i / 30.0;
        const double moveSeconds = std::max(0.0, t - (still - 1) / 30.0);
        const cv::Matx44d truth = cameraViewingBoard(
            {.distanceM = 1.5, .angleDeg = 30.0, .azimuthDeg = 30.0 * moveSeconds});
        auto linear = renderer->render(truth, uint32_t(i));
        if (!linear) return linear.error();
        const cv::Mat gray = toCameraGray8(
            *linear, {.blurSigmaPx = 0.7, .noiseSigmaLevels = 2.0, .seed = uint64_t(i + 1)});
        addSample(s, tracker->track(gray), t);
        s.truth.push_back(truth);
        if (i >= still / 3 && i < still) s.still.push_back(size_t(i));
        if (i >= still) s.moving.push_back(size_t(i));
    }
    s.motionStart = size_t(still);
    return s;
}

// The bundled demo take, tracked as the service tracks it; its still stretch is frames 20–44.
Result<Sequence> demoTake(const std::string& examplesDir) {
    Sequence s;
    s.name = "demo take (640×360, 15 fps)";
    Result<SessionInfo> session = openSession(examplesDir + "/demo/session");
    if (!session) return session.error();
    Result<ServiceConfig> config = loadSessionConfig(*session);
    if (!config) return config.error();
    Result<TakeTrack> track = trackTake(*session, *config);
    if (!track) return track.error();
    Result<std::vector<PoseRecord>> poses = loadPoses(session->dir);
    if (!poses) return poses.error();
    std::map<uint64_t, cv::Matx44d> truth;
    for (const PoseRecord& p : *poses)
        if (p.kind == PoseKind::Truth && p.frame && p.worldFromCamera)
            truth[*p.frame] = cv::Matx44d(p.worldFromCamera->data());
    const uint64_t t0 = track->frames.empty() ? 0 : track->frames[0].entry.timestampNs;
    for (size_t i = 0; i < track->frames.size(); ++i) {
        const TakeFrame& f = track->frames[i];
        TrackSample t;
        t.timestampNs = f.entry.timestampNs - t0;
        t.worldFromCamera = f.tracked;
        t.positionStdM = f.positionStdM;
        t.rotationStdDeg = f.rotationStdDeg;
        s.samples.push_back(t);
        s.seconds.push_back(double(t.timestampNs) * 1e-9);
        auto it = truth.find(f.entry.sequence);
        s.truth.push_back(it == truth.end() ? std::nullopt : std::optional(it->second));
        if (i >= 26 && i <= 44) s.still.push_back(i);  // 0.4 s after it stops: settled
        if (i < 20 || i > 45) s.moving.push_back(i);
    }
    s.motionStart = 45;
    return s;
}

// The ViSP RBT video's first frames (0–5 present: 0, 1, 3, 4, 5), where the hand-held camera
// holds within 1 mm a frame; its truth is ViSP's own tracker, so only jitter is reported.
Result<Sequence> vispHeld(const std::string& dataDir) {
    Sequence s;
    s.name = "ViSP RBT video, held start (frames 0–5 present)";
    const std::string dir = dataDir + "/video/visp_rbt_sequence/";
    nlohmann::json data;
    try {
        std::ifstream(dir + "apriltag_data.json") >> data;
    } catch (const std::exception& e) {
        return makeError("{}apriltag_data.json: {}", dir, e.what());
    }
    auto calib =
        CameraCalibration::create(cv::Matx33d(607.178466796875, 0, 321.39129638671875, 0,
                                              607.2342529296875, 241.91822814941406, 0, 0, 1),
                                  {}, cv::Size(640, 480), DistortionModel::Pinhole, "ViSP camera");
    if (!calib) return calib.error();
    auto tracker = Tracker::create({}, vispRbtBoard(), *calib);
    if (!tracker) return tracker.error();
    for (int frame : data["frames"].get<std::vector<int>>()) {
        if (frame > 5) break;
        const cv::Mat gray =
            cv::imread(fmt::format("{}color_image_{:04d}.png", dir, frame), cv::IMREAD_GRAYSCALE);
        if (gray.empty()) return makeError("{}: frame {} does not read", dir, frame);
        addSample(s, tracker->track(gray), frame / 30.0);
        s.truth.push_back(std::nullopt);
        s.still.push_back(s.samples.size() - 1);
    }
    return s;
}

std::string number(double v, const char* format) {
    return std::isnan(v) ? "–" : fmt::format(fmt::runtime(format), v);
}

}  // namespace

int runPoseFilterBench(GpuContext& ctx, const std::string& dataDir, const std::string& examplesDir,
                       bool quick) {
    setLogLevel(LogLevel::Error);
    std::vector<Sequence> sequences;
    auto orbit = renderedOrbit(ctx, quick ? 15 : 30, quick ? 4 : 8);
    auto demo = demoTake(examplesDir);
    auto visp = vispHeld(dataDir);
    setLogLevel(LogLevel::Info);
    for (auto* r : {&orbit, &demo, &visp}) {
        if (!*r) {
            logError("filter bench: {}", r->message());
            return 1;
        }
        sequences.push_back(std::move(r->value()));
    }
    std::printf("## The live pose filter (vision/pose_filter.h)\n\n");
    std::printf(
        "| sequence | poses | still jitter mm | still jitter ° | error moving mm (median) | lag ms "
        "| max error, 5 frames after the move starts, mm |\n|---|---|---|---|---|---|---|\n");
    for (const Sequence& s : sequences)
        for (int filtered = 0; filtered < 2; ++filtered) {
            const Measured m = measure(s, filtered ? filteredPoses(s) : rawPoses(s));
            std::printf("| %s | %s | %s | %s | %s | %s | %s |\n", s.name.c_str(),
                        filtered ? "filtered" : "raw", number(m.jitterMm, "{:.3f}").c_str(),
                        number(m.jitterDeg, "{:.4f}").c_str(), number(m.movingMm, "{:.2f}").c_str(),
                        number(m.lagMs, "{:.0f}").c_str(), number(m.stepMaxMm, "{:.2f}").c_str());
        }
    std::printf("\n");
    std::fflush(stdout);
    return 0;
}

}  // namespace previs::bench
