#include "bench/pose_accuracy.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/bench_stats.h"
#include "render/board_render.h"
#include "vision/board_pose.h"
#include "vision/tag_detector.h"

namespace previs::bench {

namespace {

// The on-set requirement the "over spec" column counts against: camera position within 1% of
// the distance, rotation within 0.5° (tests/vision/rendered_pose_test.cpp).
constexpr double kSpecRelativeTranslation = 0.01;
constexpr double kSpecRotationDeg = 0.5;
// A pose so far off that using it would visibly break the composite: a wrong pose.
constexpr double kGrossRelativeTranslation = 0.10;
constexpr double kGrossRotationDeg = 5.0;

struct Lens {
    std::string name;
    CameraCalibration calibration;
};

// 1280×720 lenses: a wide rad-tan lens (barrel distortion, 78° horizontal field) and a
// Kannala–Brandt fisheye (133° horizontal field), principal points off centre as real ones are.
Result<std::vector<Lens>> sweepLenses() {
    auto radTan = CameraCalibration::create(cv::Matx33d(905, 0, 643.1, 0, 903, 357.4, 0, 0, 1),
                                            {-0.25, 0.08, 3e-4, -2e-4, 0.0}, cv::Size(1280, 720),
                                            DistortionModel::Pinhole, "sweep rad-tan lens");
    if (!radTan) return radTan.error();
    auto fisheye = CameraCalibration::create(cv::Matx33d(560, 0, 641.3, 0, 560, 358.2, 0, 0, 1),
                                             {-0.02, 0.015, -0.006, 0.0005}, cv::Size(1280, 720),
                                             DistortionModel::Fisheye, "sweep fisheye lens");
    if (!fisheye) return fisheye.error();
    return std::vector<Lens>{{"rad-tan", std::move(radTan).value()},
                             {"fisheye", std::move(fisheye).value()}};
}

struct BoardFrame {
    size_t lens = 0;
    double distanceM = 0.0;
    double angleDeg = 0.0;
    double blurPx = 0.0;
    double noiseLevels = 0.0;
    TransferCurve curve = TransferCurve::Srgb;
    bool tracked = false;
    CameraPoseError error;
};

struct Summary {
    size_t frames = 0;
    size_t tracked = 0;
    size_t overSpec = 0;  // tracked, but outside the on-set requirement
    size_t gross = 0;     // tracked, but a wrong pose
    double medianMm = 0.0, maxMm = 0.0;
    double medianPercent = 0.0, maxPercent = 0.0;
    double medianDeg = 0.0, maxDeg = 0.0;
};

template <typename Pred>
Summary summarise(const std::vector<BoardFrame>& frames, Pred select) {
    Summary s;
    std::vector<double> mm, percent, deg;
    for (const BoardFrame& f : frames) {
        if (!select(f)) continue;
        ++s.frames;
        if (!f.tracked) continue;
        ++s.tracked;
        mm.push_back(f.error.translationM * 1e3);
        percent.push_back(100.0 * f.error.translationM / f.distanceM);
        deg.push_back(f.error.rotationDeg);
        if (f.error.translationM > kSpecRelativeTranslation * f.distanceM ||
            f.error.rotationDeg > kSpecRotationDeg)
            ++s.overSpec;
        if (f.error.translationM > kGrossRelativeTranslation * f.distanceM ||
            f.error.rotationDeg > kGrossRotationDeg)
            ++s.gross;
    }
    if (!mm.empty()) {
        s.medianMm = median(mm);
        s.maxMm = *std::max_element(mm.begin(), mm.end());
        s.medianPercent = median(percent);
        s.maxPercent = *std::max_element(percent.begin(), percent.end());
        s.medianDeg = median(deg);
        s.maxDeg = *std::max_element(deg.begin(), deg.end());
    }
    return s;
}

void printRow(const std::string& label, const Summary& s) {
    if (s.tracked == 0) {
        std::printf("| %s | 0/%zu | – | – | – | – | – | – | – | – |\n", label.c_str(), s.frames);
        return;
    }
    std::printf("| %s | %zu/%zu | %.2f | %.2f | %.3f | %.3f | %.3f | %.3f | %zu | %zu |\n",
                label.c_str(), s.tracked, s.frames, s.medianMm, s.maxMm, s.medianPercent,
                s.maxPercent, s.medianDeg, s.maxDeg, s.overSpec, s.gross);
}

// A table's header: its label columns, then the metric columns printRow fills.
void printHeader(const std::vector<const char*>& labels) {
    const char* metrics[] = {"detected", "median mm", "max mm", "median % of distance",
                             "max %",    "median °",  "max °",  "over spec",
                             "wrong"};
    std::string head;
    std::string rule = "|";
    for (const char* l : labels) {
        head += fmt::format("| {} ", l);
        rule += "---|";
    }
    for (const char* m : metrics) {
        head += fmt::format("| {} ", m);
        rule += "---|";
    }
    std::printf("%s|\n%s\n", head.c_str(), rule.c_str());
}

const char* curveName(TransferCurve c) { return c == TransferCurve::Srgb ? "sRGB" : "linear"; }

}  // namespace

int runPoseSweep(GpuContext& ctx, const PoseSweepOptions& o) {
    auto lenses = sweepLenses();
    if (!lenses) {
        logError("{}", lenses.message());
        return 1;
    }
    const TagBoard board = posterBoard();
    const uint32_t spp = o.quick ? 4 : o.spp;
    const std::vector<double> distances =
        o.quick ? std::vector<double>{1.0, 4.0} : std::vector<double>{0.5, 1.0, 2.0, 4.0, 8.0};
    const std::vector<double> angles =
        o.quick ? std::vector<double>{0.0, 60.0} : std::vector<double>{0.0, 30.0, 60.0, 75.0};
    // Several views per distance and angle: the tilt toward each side, rolled, and the board
    // off the optical axis where the lens distorts most.
    std::vector<BoardView> views = {{.azimuthDeg = 0.0, .rollDeg = 0.0, .offAxisDeg = 0.0},
                                    {.azimuthDeg = 90.0, .rollDeg = 20.0, .offAxisDeg = 8.0},
                                    {.azimuthDeg = 180.0, .rollDeg = -20.0, .offAxisDeg = 15.0},
                                    {.azimuthDeg = 270.0, .rollDeg = 40.0, .offAxisDeg = 4.0}};
    if (o.quick) views.resize(1);
    const std::vector<double> blurs =
        o.quick ? std::vector<double>{0.0, 2.0} : std::vector<double>{0.0, 1.0, 2.0};
    const std::vector<double> noises =
        o.quick ? std::vector<double>{0.0, 5.0} : std::vector<double>{0.0, 2.0, 5.0};
    const TransferCurve curves[] = {TransferCurve::Srgb, TransferCurve::Linear};
    const TagDetectorSettings detectorSettings;  // libapriltag's defaults, as the service runs

    // The tracker logs each lost/regained transition; over thousands of unrelated frames that
    // is noise, so the sweep logs errors only (the default level again afterwards).
    setLogLevel(LogLevel::Error);
    const auto start = std::chrono::steady_clock::now();
    std::vector<BoardFrame> frames;
    uint64_t seed = 1;
    uint32_t renderSeed = 0;
    for (size_t l = 0; l < lenses->size(); ++l) {
        const Lens& lens = (*lenses)[l];
        auto renderer = BoardRenderer::create(ctx, board, "tag36h11", lens.calibration, spp);
        // One tracker per camera curve, each told its curve as the service is by the camera's
        // radiometry (the edge refit inverts it: vision/tag_edges.h).
        TrackerSettings srgbCamera, linearCamera;
        srgbCamera.linearFromCode = linearFromCodeTable(InverseToneMapSettings{});
        linearCamera.linearFromCode = identityLinearFromCode();
        auto srgbTracker = Tracker::create(detectorSettings, board, lens.calibration, srgbCamera);
        auto linearTracker =
            Tracker::create(detectorSettings, board, lens.calibration, linearCamera);
        if (!renderer || !srgbTracker || !linearTracker) {
            setLogLevel(LogLevel::Info);
            logError("pose sweep, {} lens: {}", lens.name,
                     !renderer ? renderer.message() : srgbTracker.message());
            return 1;
        }
        for (double d : distances) {
            for (double a : angles) {
                for (size_t v = 0; v < views.size(); ++v) {
                    BoardView view = views[v];
                    view.distanceM = d;
                    view.angleDeg = a;
                    const cv::Matx44d truth = cameraViewingBoard(view);
                    benchProgress("pose {} lens, {} m, {}°, view {}/{}", lens.name, d, a, v + 1,
                                  views.size());
                    auto linear = renderer->render(truth, renderSeed++);
                    if (!linear) {
                        setLogLevel(LogLevel::Info);
                        logError("pose sweep render: {}", linear.message());
                        return 1;
                    }
                    for (TransferCurve curve : curves) {
                        for (double blur : blurs) {
                            for (double noise : noises) {
                                cv::Mat gray = toCameraGray8(*linear, {.blurSigmaPx = blur,
                                                                       .noiseSigmaLevels = noise,
                                                                       .seed = seed++,
                                                                       .curve = curve});
                                // Each frame on its own: a lost frame's held pose is not its
                                // answer.
                                Tracker& tracker =
                                    curve == TransferCurve::Srgb ? *srgbTracker : *linearTracker;
                                tracker.reset();
                                const TrackingState& st = tracker.track(gray);
                                BoardFrame f{l, d, a, blur, noise, curve, !st.lost, {}};
                                if (f.tracked)
                                    f.error = cameraPoseError(st.pose->worldFromCamera, truth);
                                frames.push_back(f);
                            }
                        }
                    }
                }
            }
        }
    }
    setLogLevel(LogLevel::Info);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

    std::printf("## Pose accuracy (rendered boards)\n\n");
    std::printf(
        "Board: A2 poster, 4×3 tag36h11, 100 mm tags at 140 mm pitch, rendered by the path "
        "tracer (emissive print: paper 0.8, ink 0.04; %u spp box filter) through the calibrated "
        "lens at 1280×720, then Gaussian blur (σ px, in linear light), the camera's transfer "
        "curve (sRGB, or linear for a gamma-1 camera), Gaussian noise (σ in 8-bit levels), "
        "8-bit rounding. Lenses: rad-tan (f 905 px, k1 −0.25, k2 0.08, 78° wide), Kannala–Brandt "
        "fisheye (f 560 px, 133° wide). Tracker: libapriltag defaults (decimate 2, 1 thread) + "
        "board pose (SQPnP + LM), max reprojection error 3 px. Error: distance between the "
        "estimated and true camera centres, and angle of R_estᵀR_true. %zu views per distance "
        "and angle (tilted toward each side, rolled, board up to 15° off axis). Detected: the "
        "tracker reported a pose. Over spec: detected, but beyond 1%% of the distance or 0.5°; "
        "wrong: beyond 10%% or 5°. %zu frames in %.0f s.\n\n",
        spp, views.size(), frames.size(), seconds);

    std::printf("### By distance and viewing angle: sRGB camera, all blur and noise levels\n\n");
    printHeader({"lens", "distance", "angle"});
    for (size_t l = 0; l < lenses->size(); ++l)
        for (double d : distances)
            for (double a : angles)
                printRow(fmt::format("{} | {} m | {}°", (*lenses)[l].name, d, a),
                         summarise(frames, [&](const BoardFrame& f) {
                             return f.lens == l && f.distanceM == d && f.angleDeg == a &&
                                    f.curve == TransferCurve::Srgb;
                         }));
    std::printf("\n### By camera, blur and noise: distances up to 4 m, angles up to 60°\n\n");
    printHeader({"lens", "camera", "blur σ px", "noise σ levels"});
    for (size_t l = 0; l < lenses->size(); ++l)
        for (TransferCurve c : curves)
            for (double b : blurs)
                for (double n : noises)
                    printRow(
                        fmt::format("{} | {} | {} | {}", (*lenses)[l].name, curveName(c), b, n),
                        summarise(frames, [&](const BoardFrame& f) {
                            return f.lens == l && f.curve == c && f.blurPx == b &&
                                   f.noiseLevels == n && f.distanceM <= 4.0 && f.angleDeg <= 60.0;
                        }));
    std::printf("\n### Overall\n\n");
    printHeader({"lens", "camera", "frames"});
    for (size_t l = 0; l < lenses->size(); ++l) {
        for (TransferCurve c : curves) {
            printRow(fmt::format("{} | {} | all", (*lenses)[l].name, curveName(c)),
                     summarise(frames,
                               [&](const BoardFrame& f) { return f.lens == l && f.curve == c; }));
            printRow(fmt::format("{} | {} | ≤ 4 m, ≤ 60°", (*lenses)[l].name, curveName(c)),
                     summarise(frames, [&](const BoardFrame& f) {
                         return f.lens == l && f.curve == c && f.distanceM <= 4.0 &&
                                f.angleDeg <= 60.0;
                     }));
        }
    }
    std::printf("\n");
    std::fflush(stdout);
    return 0;
}

int runReachSweep(GpuContext& ctx, bool quick) {
    auto lenses = sweepLenses();
    if (!lenses) {
        logError("{}", lenses.message());
        return 1;
    }
    const Lens& lens = (*lenses)[0];
    const TagBoard board = posterBoard();
    const uint32_t spp = quick ? 4 : 8;
    const std::vector<double> distances =
        quick ? std::vector<double>{2.0, 4.0, 6.0} : std::vector<double>{1, 2, 3, 4, 5, 6, 8, 10};
    const std::vector<double> angles =
        quick ? std::vector<double>{30.0} : std::vector<double>{0, 45};
    std::vector<BoardView> views = {{.azimuthDeg = 0.0, .rollDeg = 0.0, .offAxisDeg = 0.0},
                                    {.azimuthDeg = 180.0, .rollDeg = -20.0, .offAxisDeg = 12.0}};
    if (quick) views.resize(1);
    const std::vector<double> blurs = {0.5, 1.0};

    struct Variant {
        const char* name;
        TagDetectorSettings detector;
        TrackerSettings tracker;
        bool primed;  // tracked after a frame at the same view: the live case
    };
    TrackerSettings asDetected;
    asDetected.linearEdges = false;
    // The frames are rendered through sRGB (TransferCurve::Srgb): the camera's curve is known.
    TrackerSettings previs;
    previs.linearFromCode = linearFromCodeTable(InverseToneMapSettings{});
    const Variant variants[] = {
        {"libapriltag defaults (decimate 2, its corners)", {.decimate = 2.0f}, asDetected, false},
        {"previs, a frame on its own", {}, previs, false},
        {"previs, after the previous frame's pose", {}, previs, true},
    };
    struct Row {
        size_t frames = 0, tracked = 0, withinSpec = 0;
        std::vector<double> percent, deg, ms;
    };
    std::vector<std::vector<Row>> rows(std::size(variants), std::vector<Row>(distances.size()));

    auto renderer = BoardRenderer::create(ctx, board, "tag36h11", lens.calibration, spp);
    if (!renderer) {
        logError("reach sweep: {}", renderer.message());
        return 1;
    }
    std::vector<Tracker> trackers;
    for (const Variant& v : variants) {
        auto t = Tracker::create(v.detector, board, lens.calibration, v.tracker);
        if (!t) {
            logError("reach sweep: {}", t.message());
            return 1;
        }
        trackers.push_back(std::move(t).value());
    }
    setLogLevel(LogLevel::Error);
    const auto start = std::chrono::steady_clock::now();
    uint64_t seed = 1;
    uint32_t renderSeed = 0;
    for (size_t di = 0; di < distances.size(); ++di)
        for (double a : angles)
            for (BoardView view : views) {
                view.distanceM = distances[di];
                view.angleDeg = a;
                const cv::Matx44d truth = cameraViewingBoard(view);
                benchProgress("reach {} m, {}°", view.distanceM, a);
                auto linear = renderer->render(truth, renderSeed++);
                if (!linear) {
                    setLogLevel(LogLevel::Info);
                    logError("reach sweep render: {}", linear.message());
                    return 1;
                }
                for (double blur : blurs) {
                    const cv::Mat gray = toCameraGray8(
                        *linear, {.blurSigmaPx = blur, .noiseSigmaLevels = 2.0, .seed = seed++});
                    for (size_t vi = 0; vi < std::size(variants); ++vi) {
                        Tracker& tracker = trackers[vi];
                        tracker.reset();
                        if (variants[vi].primed) tracker.track(gray);
                        const auto t0 = std::chrono::steady_clock::now();
                        const TrackingState& st = tracker.track(gray);
                        Row& row = rows[vi][di];
                        row.ms.push_back(std::chrono::duration<double, std::milli>(
                                             std::chrono::steady_clock::now() - t0)
                                             .count());
                        ++row.frames;
                        if (st.lost) continue;
                        ++row.tracked;
                        const CameraPoseError e = cameraPoseError(st.pose->worldFromCamera, truth);
                        row.percent.push_back(100.0 * e.translationM / view.distanceM);
                        row.deg.push_back(e.rotationDeg);
                        if (e.translationM <= kSpecRelativeTranslation * view.distanceM &&
                            e.rotationDeg <= kSpecRotationDeg)
                            ++row.withinSpec;
                    }
                }
            }
    setLogLevel(LogLevel::Info);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

    std::printf("## Reach: the A2 board by distance (rendered, sRGB, rad-tan lens 1280×720)\n\n");
    std::printf(
        "%u spp, blur σ 0.5 and 1 px, noise σ 2 levels; %zu angles × %zu views per distance; "
        "within spec: position within 1%% of the distance and rotation within 0.5°. %.0f s.\n\n",
        spp, angles.size(), views.size(), seconds);
    std::printf(
        "| distance | tracker | pose | within spec | median %% of distance | median ° | ms/frame "
        "(median) |\n|---|---|---|---|---|---|---|\n");
    for (size_t di = 0; di < distances.size(); ++di)
        for (size_t vi = 0; vi < std::size(variants); ++vi) {
            const Row& r = rows[vi][di];
            const std::string pct =
                r.percent.empty() ? "–" : fmt::format("{:.3f}", median(r.percent));
            const std::string deg = r.deg.empty() ? "–" : fmt::format("{:.3f}", median(r.deg));
            std::printf("| %g m | %s | %zu/%zu | %zu | %s | %s | %.1f |\n", distances[di],
                        variants[vi].name, r.tracked, r.frames, r.withinSpec, pct.c_str(),
                        deg.c_str(), median(r.ms));
        }
    std::printf("\n");
    std::fflush(stdout);
    return 0;
}

}  // namespace previs::bench
