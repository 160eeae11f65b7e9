// The tracker on tag boards rendered by the path tracer at known poses through calibrated lenses
// (render/board_render.h): pose errors against the exact ground truth, and the cases where the
// tracker must say "lost" instead of reporting a pose. The full sweep is `previs bench --only
// pose` (bench/results/benchmarks_2026-11-22.md, "Pose accuracy (rendered boards)").
//
// Tolerances (each from the reasoning given, none fitted to the results):
// - Corners: the detected corners' RMS distance to their true projection is at most
//   kCornerBudgetPx = 0.25 px (quarter-pixel edge fitting). A half-pixel convention error or a
//   lens-model mismatch breaks it. It holds for a linear (gamma 1) camera and, since the tracker
//   re-fits corners in linear light (vision/tag_edges.h), for an sRGB one: through the sRGB
//   curve a blurred edge's codes cross the midpoint on the dark side, and libapriltag's own
//   corners missed it by 0.6–0.7 px RMS at σ = 1 px here.
// - Pose given the corners: the board pose is a least-squares fit to the corners in ideal pinhole
//   pixels, so to first order its error is A·e, with e the measured corner errors there and
//   A = (JᵀJ)⁻¹Jᵀ from the projection's Jacobian J at the true pose. The camera centre and
//   rotation errors must match that prediction within 5% (second-order terms: the errors are
//   ~10⁻³ of the distance) plus 10 µm / 10 µrad (the solver's stopping tolerance): the solver
//   and the frame conventions add nothing of their own.
// - On-set requirement: camera position within 1% of the distance, rotation within 0.5°.
// - Clean image, ideal lens, linear camera, 1 m: under 1 mm and 0.05° (the angle 1 mm subtends
//   at 1 m), the convention check.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>

#include "render/board_render.h"
#include "tests/integrator/gpu_fixture.h"
#include "vision/board_pose.h"
#include "vision/camera_calibration.h"
#include "vision/tag_detector.h"

namespace previs::testing {
namespace {

constexpr double kCornerBudgetPx = 0.25;
constexpr double kSecondOrder = 0.05;
constexpr double kSolverToleranceM = 10e-6;
constexpr double kSolverToleranceRad = 10e-6;
constexpr double kMaxRelativeTranslation = 0.01;
constexpr double kMaxRotationDeg = 0.5;
// Antialiasing samples per pixel. The box filter's Monte Carlo noise on edge pixels is part of
// the corner budget; at 4 spp it alone moves the clean 1 m pose by up to ~1 mm (measured over
// seeds), so the sub-millimetre convention check renders 16 (≤ 0.3 mm).
constexpr uint32_t kSpp = 4;
constexpr uint32_t kCleanSpp = 16;

// 640×480 lenses: an ideal pinhole, a wide rad-tan lens (barrel distortion, a little tangential)
// and a Kannala–Brandt fisheye seeing 84° off axis at the farthest image corner.
CameraCalibration idealLens() {
    return CameraCalibration::create(cv::Matx33d(500, 0, 319.5, 0, 500, 239.5, 0, 0, 1), {},
                                     cv::Size(640, 480), DistortionModel::Pinhole, "ideal lens")
        .value();
}
CameraCalibration radTanLens() {
    return CameraCalibration::create(cv::Matx33d(502, 0, 322.4, 0, 498, 236.9, 0, 0, 1),
                                     {-0.25, 0.08, 3e-4, -2e-4, 0.0}, cv::Size(640, 480),
                                     DistortionModel::Pinhole, "rad-tan lens")
        .value();
}
CameraCalibration fisheyeLens() {
    return CameraCalibration::create(cv::Matx33d(280, 0, 321.0, 0, 280, 241.0, 0, 0, 1),
                                     {-0.02, 0.015, -0.006, 0.0005}, cv::Size(640, 480),
                                     DistortionModel::Fisheye, "fisheye lens")
        .value();
}

// Projections of world points by a camera at worldFromCamera through `project`.
template <typename Project>
std::vector<cv::Point2d> projectWorld(const std::vector<cv::Point3d>& world,
                                      const cv::Matx44d& worldFromCamera, Project project) {
    cv::Matx44d cameraFromWorld = invertRigid(worldFromCamera);
    std::vector<cv::Point3d> camera;
    for (const cv::Point3d& p : world) {
        cv::Vec4d q = cameraFromWorld * cv::Vec4d(p.x, p.y, p.z, 1.0);
        camera.emplace_back(q[0], q[1], q[2]);
    }
    return project(camera);
}

// A = (JᵀJ)⁻¹Jᵀ of the least-squares pose fit to the ideal pinhole pixels of `world` at the true
// pose (6 × 2N; see the header comment), by central differences. Parameters: the camera centre
// (world) and a rotation ω with R = R_true·exp([ω]×), so |ω| is the angle cameraPoseError reports.
cv::Mat pnpLinearisation(const CameraCalibration& calib, const std::vector<cv::Point3d>& world,
                         const cv::Matx44d& worldFromCamera) {
    const cv::Matx33d k = calib.cameraMatrix();
    auto pinhole = [&](const std::vector<cv::Point3d>& camera) {
        std::vector<cv::Point2d> out;
        for (const cv::Point3d& p : camera)
            out.emplace_back(k(0, 0) * p.x / p.z + k(0, 2), k(1, 1) * p.y / p.z + k(1, 2));
        return out;
    };
    auto perturbed = [&](int i, double h) {
        cv::Matx44d m = worldFromCamera;
        if (i < 3) {
            m(i, 3) += h;
        } else {
            cv::Vec3d w(0, 0, 0);
            w[i - 3] = h;
            cv::Matx33d dr;
            cv::Rodrigues(w, dr);
            cv::Matx33d r = worldFromCamera.get_minor<3, 3>(0, 0) * dr;
            for (int a = 0; a < 3; ++a)
                for (int b = 0; b < 3; ++b) m(a, b) = r(a, b);
        }
        return projectWorld(world, m, pinhole);
    };
    cv::Mat j(int(2 * world.size()), 6, CV_64F);
    for (int i = 0; i < 6; ++i) {
        const double h = 1e-6;
        auto plus = perturbed(i, h);
        auto minus = perturbed(i, -h);
        for (size_t p = 0; p < world.size(); ++p) {
            j.at<double>(int(2 * p), i) = (plus[p].x - minus[p].x) / (2 * h);
            j.at<double>(int(2 * p + 1), i) = (plus[p].y - minus[p].y) / (2 * h);
        }
    }
    return (j.t() * j).inv(cv::DECOMP_SVD) * j.t();
}

cv::Vec3d translationOf(const cv::Matx44d& m) { return {m(0, 3), m(1, 3), m(2, 3)}; }

class RenderedPoseTest : public GpuTest {
protected:
    std::optional<BoardRenderer> makeRenderer(const CameraCalibration& calib, uint32_t spp = kSpp) {
        auto r = BoardRenderer::create(ctx(), posterBoard(), "tag36h11", calib, spp);
        EXPECT_TRUE(r.ok()) << r.message();
        if (!r) return std::nullopt;
        return std::move(r).value();
    }

    ImageF render(BoardRenderer& renderer, const cv::Matx44d& worldFromCamera) {
        auto linear = renderer.render(worldFromCamera);
        EXPECT_TRUE(linear.ok()) << linear.message();
        return linear ? std::move(linear).value() : ImageF{};
    }

    struct Outcome {
        TrackingState state;
        double cornerRmsPx = 0.0;                         // vs the true projection, raw pixels
        cv::Vec3d centreError, predictedCentreError;      // metres, world frame
        cv::Vec3d rotationError, predictedRotationError;  // ω, radians
        CameraPoseError error;
    };

    // Degrades the rendered `linear` image, tracks it with `tracker` and compares with `truth`.
    Outcome track(Tracker& tracker, const CameraCalibration& calib, const cv::Matx44d& truth,
                  const ImageF& linear, const Degradation& degradation) {
        Outcome out;
        if (linear.pixels.empty()) return out;
        out.state = tracker.track(toCameraGray8(linear, degradation));
        const std::vector<TagDetection>& detections = tracker.detections();
        if (out.state.lost) return out;
        out.error = cameraPoseError(out.state.pose->worldFromCamera, truth);

        const TagBoard board = posterBoard();
        std::vector<cv::Point3d> world;
        std::vector<cv::Point2d> detected;
        for (const TagDetection& d : detections) {
            const BoardTag* tag = board.find(d.id);
            if (!tag) continue;
            auto c = board.worldCorners(*tag);
            world.insert(world.end(), c.begin(), c.end());
            for (const cv::Point2d& p : d.corners) detected.push_back(openCvPixel(p));
        }
        auto truePixels = projectWorld(world, truth, [&](const std::vector<cv::Point3d>& c) {
            return calib.projectPoints(c);
        });
        std::vector<cv::Point2d> idealDetected = calib.undistortPixels(detected);
        std::vector<cv::Point2d> idealTrue = calib.undistortPixels(truePixels);
        double sum = 0.0;
        cv::Mat e(int(2 * world.size()), 1, CV_64F);
        for (size_t i = 0; i < world.size(); ++i) {
            cv::Point2d d = detected[i] - truePixels[i];
            sum += d.dot(d);
            e.at<double>(int(2 * i)) = idealDetected[i].x - idealTrue[i].x;
            e.at<double>(int(2 * i + 1)) = idealDetected[i].y - idealTrue[i].y;
        }
        out.cornerRmsPx = std::sqrt(sum / double(world.size()));
        cv::Mat predicted = pnpLinearisation(calib, world, truth) * e;
        for (int i = 0; i < 3; ++i) {
            out.predictedCentreError[i] = predicted.at<double>(i);
            out.predictedRotationError[i] = predicted.at<double>(3 + i);
        }
        out.centreError = translationOf(out.state.pose->worldFromCamera) - translationOf(truth);
        cv::Rodrigues(
            truth.get_minor<3, 3>(0, 0).t() * out.state.pose->worldFromCamera.get_minor<3, 3>(0, 0),
            out.rotationError);
        std::printf(
            "%s, blur %.1f px, noise %.1f, %s: %zu tags, corner RMS %.3f px, error "
            "%.3f mm / %.4f° (first-order prediction %.3f mm / %.4f°), reprojection "
            "%.3f px\n",
            calib.model() == DistortionModel::Fisheye ? "fisheye" : "pinhole",
            degradation.blurSigmaPx, degradation.noiseSigmaLevels,
            degradation.curve == TransferCurve::Srgb ? "sRGB" : "linear",
            out.state.pose->tagIds.size(), out.cornerRmsPx, out.error.translationM * 1e3,
            out.error.rotationDeg, cv::norm(out.predictedCentreError) * 1e3,
            cv::norm(out.predictedRotationError) * 180.0 / M_PI, out.state.pose->reprojErrorPx);
        return out;
    }

    // Renders the board seen from `view` and tracks that frame, as track() does.
    Outcome trackView(Tracker& tracker, const CameraCalibration& calib, BoardRenderer& renderer,
                      const BoardView& view, const Degradation& degradation) {
        const cv::Matx44d truth = cameraViewingBoard(view);
        return track(tracker, calib, truth, render(renderer, truth), degradation);
    }

    // A tracker that has seen nothing yet, so a reported pose is this frame's own; it reads the
    // frames through the camera's curve, as the service does from its radiometry.
    Tracker freshTracker(const CameraCalibration& calib,
                         TransferCurve curve = TransferCurve::Srgb) {
        TrackerSettings settings;
        settings.linearFromCode = curve == TransferCurve::Linear
                                      ? identityLinearFromCode()
                                      : linearFromCodeTable(InverseToneMapSettings{});
        return Tracker::create({}, posterBoard(), calib, settings).value();
    }

    // Pose given the corners, and the on-set requirement (header comment).
    void expectPoseFollowsCorners(const Outcome& o, double distanceM) {
        ASSERT_FALSE(o.state.lost) << o.state.reason;
        EXPECT_LE(cv::norm(o.centreError - o.predictedCentreError),
                  kSecondOrder * cv::norm(o.predictedCentreError) + kSolverToleranceM);
        EXPECT_LE(cv::norm(o.rotationError - o.predictedRotationError),
                  kSecondOrder * cv::norm(o.predictedRotationError) + kSolverToleranceRad);
        EXPECT_LT(o.error.translationM, kMaxRelativeTranslation * distanceM);
        EXPECT_LT(o.error.rotationDeg, kMaxRotationDeg);
    }
    // A lost frame just after the good one `lastGood`: counted, and holding that pose.
    void expectHoldsLastGoodPose(const Outcome& lost, const Outcome& lastGood) {
        EXPECT_EQ(lost.state.framesSinceGood, 1u);
        ASSERT_TRUE(lost.state.pose.has_value());
        EXPECT_EQ(cv::norm(lost.state.pose->worldFromCamera - lastGood.state.pose->worldFromCamera),
                  0.0)
            << "a lost frame holds the last good pose";
    }
    // All of the header comment's checks.
    void expectAccurate(const Outcome& o, double distanceM) {
        expectPoseFollowsCorners(o, distanceM);
        EXPECT_LE(o.cornerRmsPx, kCornerBudgetPx);
    }

    // One view through one lens: a linear and an sRGB camera must meet every check.
    void checkView(const CameraCalibration& calib, const BoardView& view, double blurPx,
                   double noiseLevels) {
        auto renderer = makeRenderer(calib);
        ASSERT_TRUE(renderer.has_value());
        const cv::Matx44d truth = cameraViewingBoard(view);
        ImageF linear = render(*renderer, truth);
        for (TransferCurve curve : {TransferCurve::Linear, TransferCurve::Srgb}) {
            Tracker tracker = freshTracker(calib, curve);
            Outcome o =
                track(tracker, calib, truth, linear,
                      {.blurSigmaPx = blurPx, .noiseSigmaLevels = noiseLevels, .curve = curve});
            expectAccurate(o, view.distanceM);
        }
    }
};

// The convention check: ideal lens, no blur, no noise, linear camera.
TEST_F(RenderedPoseTest, CleanRenderThroughIdealLensGivesSubMillimetrePose) {
    const CameraCalibration lens = idealLens();
    auto renderer = makeRenderer(lens, kCleanSpp);
    ASSERT_TRUE(renderer.has_value());
    BoardView view{.distanceM = 1.0, .angleDeg = 20.0, .azimuthDeg = 30.0, .rollDeg = 10.0};
    const cv::Matx44d truth = cameraViewingBoard(view);
    ImageF linear = render(*renderer, truth);
    Tracker tracker = freshTracker(lens, TransferCurve::Linear);
    Outcome o = track(tracker, lens, truth, linear, {.curve = TransferCurve::Linear});
    expectAccurate(o, view.distanceM);
    EXPECT_LT(o.error.translationM, 1e-3);
    EXPECT_LT(o.error.rotationDeg, 0.05);
    // The same frame from an sRGB camera.
    Tracker srgbTracker = freshTracker(lens);
    expectAccurate(track(srgbTracker, lens, truth, linear, {}), view.distanceM);
}

// The lens models with a real frame's blur and noise; the board oblique and off the optical
// axis, where the distortion is strong.
TEST_F(RenderedPoseTest, RadTanLensObliqueBoard) {
    checkView(radTanLens(),
              {.distanceM = 0.9,
               .angleDeg = 45.0,
               .azimuthDeg = 200.0,
               .rollDeg = -15.0,
               .offAxisDeg = 10.0},
              1.0, 2.0);
}

TEST_F(RenderedPoseTest, FisheyeLensOffAxisBoard) {
    checkView(fisheyeLens(),
              {.distanceM = 0.8,
               .angleDeg = 30.0,
               .azimuthDeg = 300.0,
               .rollDeg = 20.0,
               .offAxisDeg = 25.0},
              1.0, 2.0);
}

// A board seen at a grazing angle: no pose (the last good one held), or one that meets the
// requirement — never a wrong pose silently.
TEST_F(RenderedPoseTest, GrazingBoardIsLostNotWrong) {
    const CameraCalibration lens = radTanLens();
    auto renderer = makeRenderer(lens);
    ASSERT_TRUE(renderer.has_value());
    Tracker tracker = freshTracker(lens);
    BoardView good{.distanceM = 1.2, .angleDeg = 30.0, .azimuthDeg = 10.0};
    Outcome first =
        trackView(tracker, lens, *renderer, good, {.blurSigmaPx = 0.5, .noiseSigmaLevels = 2.0});
    expectPoseFollowsCorners(first, good.distanceM);

    BoardView grazing{.distanceM = 1.2, .angleDeg = 85.0, .azimuthDeg = 10.0};
    Outcome o =
        trackView(tracker, lens, *renderer, grazing, {.blurSigmaPx = 0.5, .noiseSigmaLevels = 2.0});
    if (o.state.lost) {
        expectHoldsLastGoodPose(o, first);
    } else {
        EXPECT_LT(o.error.translationM, kMaxRelativeTranslation * grazing.distanceM);
        EXPECT_LT(o.error.rotationDeg, kMaxRotationDeg);
    }
}

// Too far for any tag to decode (a 100 mm tag is 2 px wide at 25 m through this lens): lost,
// the last good pose held, the frame counted.
TEST_F(RenderedPoseTest, DistantBoardIsLost) {
    const CameraCalibration lens = radTanLens();
    auto renderer = makeRenderer(lens);
    ASSERT_TRUE(renderer.has_value());
    Tracker tracker = freshTracker(lens);
    BoardView good{.distanceM = 1.5, .angleDeg = 0.0, .rollDeg = 30.0};
    Outcome first = trackView(tracker, lens, *renderer, good, {.noiseSigmaLevels = 2.0});
    ASSERT_FALSE(first.state.lost) << first.state.reason;

    BoardView far{.distanceM = 25.0, .angleDeg = 0.0, .rollDeg = 30.0};
    Outcome o = trackView(tracker, lens, *renderer, far, {.noiseSigmaLevels = 2.0});
    EXPECT_TRUE(o.state.lost);
    EXPECT_EQ(o.state.reason, "no tags detected");
    expectHoldsLastGoodPose(o, first);
}

// Small tags at the defaults (issue 38): the tracker finds every tag full-resolution detection
// finds, on a frame of its own and after a pose (the decimation then chosen from the predicted
// tag sizes); a tracker fixed at libapriltag's decimate 2 finds them too once a pose predicts
// them, by the full-resolution search around the predicted tags it missed.
TEST_F(RenderedPoseTest, SmallTagsAreFoundAtTheDefaults) {
    const CameraCalibration lens = radTanLens();
    auto renderer = makeRenderer(lens);
    ASSERT_TRUE(renderer.has_value());
    for (double distance : {1.0, 2.2}) {
        const BoardView view{.distanceM = distance, .angleDeg = 30.0, .azimuthDeg = 60.0};
        const cv::Mat gray = toCameraGray8(render(*renderer, cameraViewingBoard(view)),
                                           {.blurSigmaPx = 0.5, .noiseSigmaLevels = 2.0});
        auto fullResolution = TagDetector::create({.decimate = 1.0f});
        auto coarse = TagDetector::create({.decimate = 2.0f});
        ASSERT_TRUE(fullResolution && coarse);
        const size_t all = fullResolution->detect(gray).size();
        const size_t coarseCount = coarse->detect(gray).size();
        if (distance > 2.0) {
            EXPECT_LT(coarseCount, all)
                << "this view must lose tags at decimate 2 to test anything";
        }
        std::printf("%.1f m: %zu tags at full resolution, %zu at decimate 2\n", distance, all,
                    coarseCount);

        Tracker tracker = freshTracker(lens);
        ASSERT_FALSE(tracker.track(gray).lost) << tracker.state().reason;
        EXPECT_EQ(tracker.detections().size(), all);
        EXPECT_EQ(tracker.searchStats().decimate, 1.0f) << "no pose: full resolution";
        ASSERT_FALSE(tracker.track(gray).lost) << tracker.state().reason;
        EXPECT_EQ(tracker.detections().size(), all);
        std::printf("  after a pose: decimate %.1f, %d re-detected\n",
                    tracker.searchStats().decimate, tracker.searchStats().redetected);

        auto fixed = Tracker::create({.decimate = 2.0f}, posterBoard(), lens);
        ASSERT_TRUE(fixed.ok());
        fixed->track(gray);
        EXPECT_EQ(fixed->detections().size(), coarseCount);
        if (fixed->state().lost) continue;  // nothing predicts the tags it missed
        fixed->track(gray);
        EXPECT_EQ(fixed->detections().size(), all);
        EXPECT_EQ(size_t(fixed->searchStats().redetected), all - coarseCount);
    }
}

// Bad input (issue 38): another tag family, a board half out of the frame, a frame smeared by
// motion. Each is lost with its reason, or tracked within the on-set requirement; never a pose
// outside it.
TEST_F(RenderedPoseTest, BadFramesAreLostOrRight) {
    const CameraCalibration lens = radTanLens();
    const BoardView view{.distanceM = 1.0, .angleDeg = 20.0, .azimuthDeg = 45.0};
    const cv::Matx44d truth = cameraViewingBoard(view);

    auto other = BoardRenderer::create(ctx(), posterBoard(), "tag25h9", lens, kSpp);
    ASSERT_TRUE(other.ok()) << other.message();
    Tracker wrongFamily = freshTracker(lens);
    const TrackingState& family = wrongFamily.track(toCameraGray8(render(*other, truth), {}));
    EXPECT_TRUE(family.lost);
    EXPECT_EQ(family.lostReason, LostReason::NoTags) << family.reason;
    EXPECT_FALSE(family.pose.has_value());

    auto renderer = makeRenderer(lens);
    ASSERT_TRUE(renderer.has_value());
    auto lostOrRight = [&](const char* what, const TrackingState& st, const cv::Matx44d& t,
                           double distanceM) {
        if (st.lost) {
            std::printf("%s: lost (%s)\n", what, st.reason.c_str());
            EXPECT_NE(st.lostReason, LostReason::None);
            return;
        }
        const CameraPoseError e = cameraPoseError(st.pose->worldFromCamera, t);
        std::printf("%s: %zu tags, %.2f mm, %.3f deg\n", what, st.pose->tagIds.size(),
                    e.translationM * 1e3, e.rotationDeg);
        EXPECT_LT(e.translationM, kMaxRelativeTranslation * distanceM) << what;
        EXPECT_LT(e.rotationDeg, kMaxRotationDeg) << what;
    };

    // The board's centre 30° off the optical axis at 0.6 m: half of it beyond the frame's edge.
    const BoardView edge{.distanceM = 0.6, .angleDeg = 20.0, .offAxisDeg = 30.0};
    const cv::Matx44d edgeTruth = cameraViewingBoard(edge);
    Tracker halfOut = freshTracker(lens);
    lostOrRight("half out of frame",
                halfOut.track(toCameraGray8(render(*renderer, edgeTruth),
                                            {.blurSigmaPx = 0.5, .noiseSigmaLevels = 2.0})),
                edgeTruth, edge.distanceM);

    // A pan smears the frame 12 px sideways (in linear light, as a shutter integrates).
    ImageF smeared = render(*renderer, truth);
    cv::Mat radiance(int(smeared.height), int(smeared.width), CV_32FC1, smeared.pixels.data());
    cv::Mat kernel = cv::Mat::ones(1, 12, CV_32FC1) / 12.0f;
    cv::filter2D(radiance.clone(), radiance, -1, kernel, cv::Point(-1, -1), 0,
                 cv::BORDER_REPLICATE);
    Tracker blurred = freshTracker(lens);
    lostOrRight("motion blur 12 px",
                blurred.track(toCameraGray8(smeared, {.noiseSigmaLevels = 2.0})), truth,
                view.distanceM);
}

}  // namespace
}  // namespace previs::testing
