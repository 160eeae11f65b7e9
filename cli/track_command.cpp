#include "cli/track_command.h"

#include <cstdio>
#include <nlohmann/json.hpp>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgcodecs.hpp>
#include <optional>

#include "base/command_line.h"
#include "base/log.h"
#include "base/progress.h"
#include "cli/tone_curve_options.h"
#include "vision/board_file.h"
#include "vision/board_pose.h"
#include "vision/camera_calibration.h"
#include "vision/tag_board.h"
#include "vision/tag_detector.h"
#include "vision/tag_edges.h"

namespace previs {

namespace {

struct TrackOptions {
    std::vector<std::string> images;
    std::string camera;
    std::string family = "tag36h11";
    bool familyGiven = false;
    std::optional<double> tagSizeM;
    std::string board;
    bool json = false;
    bool quiet = false;
    TagDetectorSettings detector;
    int refineEdges = 1;
    int linearEdges = 1;
    // The images' transfer curve, inverted for linearEdges; known only when --tone-curve names
    // it (a refit through a guessed curve moves every edge: vision/tag_edges.h).
    ToneCurveOptions toneCurve;
    bool curveGiven = false;
};

nlohmann::ordered_json matrixJson(const cv::Matx44d& m) {
    nlohmann::ordered_json rows = nlohmann::ordered_json::array();
    for (int r = 0; r < 4; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2), m(r, 3)});
    return rows;
}

void printText(const std::string& image, const std::vector<TagDetection>& detections,
               const std::vector<std::optional<cv::Matx44d>>& tagPoses,
               const std::optional<BoardPose>& pose) {
    std::printf("%s: %zu tag(s)\n", image.c_str(), detections.size());
    for (size_t i = 0; i < detections.size(); ++i) {
        const TagDetection& d = detections[i];
        std::printf("  id %d margin %.1f corners", d.id, d.margin);
        for (const cv::Point2d& c : d.corners) std::printf(" (%.3f, %.3f)", c.x, c.y);
        if (tagPoses[i]) {
            const cv::Matx44d& m = *tagPoses[i];
            std::printf(" t=(%.4f, %.4f, %.4f) m", m(0, 3), m(1, 3), m(2, 3));
        }
        std::printf("\n");
    }
    if (pose) {
        const cv::Matx44d& m = pose->worldFromCamera;
        std::printf("  camera position (%.4f, %.4f, %.4f) m, reprojection %.3f px, %zu tag(s)\n",
                    m(0, 3), m(1, 3), m(2, 3), pose->reprojErrorPx, pose->tagIds.size());
    } else {
        std::printf("  no camera pose\n");
    }
}

void printJson(const std::string& image, const std::vector<TagDetection>& detections,
               const std::vector<std::optional<cv::Matx44d>>& tagPoses,
               const std::optional<BoardPose>& pose) {
    nlohmann::ordered_json out;
    out["image"] = image;
    out["detections"] = nlohmann::ordered_json::array();
    for (size_t i = 0; i < detections.size(); ++i) {
        const TagDetection& d = detections[i];
        nlohmann::ordered_json j;
        j["id"] = d.id;
        j["corners"] = nlohmann::ordered_json::array();
        for (const cv::Point2d& c : d.corners) j["corners"].push_back({c.x, c.y});
        j["margin"] = d.margin;
        if (tagPoses[i]) j["cameraFromTag"] = matrixJson(*tagPoses[i]);
        out["detections"].push_back(j);
    }
    if (pose) {
        out["pose"] = {{"worldFromCamera", matrixJson(pose->worldFromCamera)},
                       {"reprojErrorPx", pose->reprojErrorPx},
                       {"tags", pose->tagIds}};
    } else {
        out["pose"] = nullptr;
    }
    std::printf("%s\n", out.dump().c_str());
}

// What every image is tracked with, built from the options before the first image.
struct TrackSetup {
    CameraCalibration calibration;
    std::optional<TagBoard> board;
    TagDetector detector;
};

// The board file's family wins when --family is not given, and must agree when it is.
Result<std::optional<TagBoard>> loadBoard(TrackOptions& o) {
    if (o.board.empty()) return std::optional<TagBoard>();
    auto board = loadTagBoard(o.board);
    if (!board) return makeError("--board: {}", board.message());
    if (!board->family().empty()) {
        if (o.familyGiven && board->family() != o.family)
            return makeError(
                "--family {} disagrees with the board file {} (family = \"{}\"); drop "
                "--family or fix the board",
                o.family, o.board, board->family());
        o.family = board->family();
    }
    return std::optional<TagBoard>(std::move(board).value());
}

Result<TrackSetup> makeTrackSetup(TrackOptions& o) {
    if (Status s = o.toneCurve.buildColour(); !s) return s.error();
    auto calibration = CameraCalibration::load(o.camera);
    if (!calibration) return makeError("--camera: {}", calibration.message());
    auto board = loadBoard(o);
    if (!board) return board.error();
    o.detector.family = o.family;
    o.detector.refineEdges = o.refineEdges != 0;
    auto detector = TagDetector::create(o.detector);
    if (!detector) return detector.error();
    return TrackSetup{std::move(calibration).value(), std::move(board).value(),
                      std::move(detector).value()};
}

// Empty when the file cannot be read or decoded (imread throws on some corrupt files: caught
// here, at the edge).
cv::Mat readGray(const std::string& path) {
    try {
        return cv::imread(path, cv::IMREAD_GRAYSCALE);
    } catch (const cv::Exception& e) {
        return cv::Mat();
    }
}

// The camera's pose in the board's frame or, with no board, in the first detected tag's.
std::optional<BoardPose> cameraPose(const TrackSetup& tracker, const TrackOptions& o,
                                    const std::vector<TagDetection>& detections,
                                    const std::string& path) {
    if (tracker.board) return estimateBoardPose(detections, *tracker.board, tracker.calibration);
    if (!o.tagSizeM || detections.empty()) return std::nullopt;
    auto single = TagBoard::create({BoardTag{detections[0].id, *o.tagSizeM}}, path);
    if (!single) return std::nullopt;
    std::vector<TagDetection> first{detections[0]};
    return estimateBoardPose(first, *single, tracker.calibration);
}

int run(TrackOptions& o) {
    // Our own messages name the file and the fix; OpenCV's console warnings would only repeat them.
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    Result<TrackSetup> tracker = makeTrackSetup(o);
    if (!tracker) {
        logError("{}", tracker.message());
        return 2;
    }
    const CameraCalibration& calib = tracker->calibration;
    const LinearFromCode table = linearFromCodeTable(o.toneCurve.inverse());
    const bool refit = o.linearEdges && o.curveGiven;
    // Said once, with the first image that decodes: a run that only fails says one line.
    bool toldCurve = !o.linearEdges || o.curveGiven || o.quiet;
    int failures = 0;
    ProgressLine progress("track", o.quiet);
    for (size_t n = 0; n < o.images.size(); ++n) {
        const std::string& path = o.images[n];
        cv::Mat gray = readGray(path);
        if (gray.empty()) {
            logError("{}: cannot decode the image (not found, or not a format OpenCV reads)", path);
            ++failures;
            continue;
        }
        if (!toldCurve) {
            logInfo(
                "no --tone-curve: the images' transfer curve is unknown, so the tag corners are "
                "libapriltag's; give --tone-curve (srgb, reinhard or banterle, as the camera's "
                "radiometry) or --colour (its OCIO colour space) to re-fit them in linear light");
            toldCurve = true;
        }
        if (gray.size() != calib.imageSize())
            logWarning(
                "{}: image is {}x{} but {} was calibrated at {}x{}; the pose will be wrong "
                "unless the calibration is scaled",
                path, gray.cols, gray.rows, o.camera, calib.imageSize().width,
                calib.imageSize().height);
        std::vector<TagDetection> detections = tracker->detector.detect(gray);
        if (refit)
            refineTagCornersInLinearLight(detections, gray, table, tracker->detector.border(),
                                          &calib);
        std::vector<std::optional<cv::Matx44d>> tagPoses(detections.size());
        if (o.tagSizeM)
            for (size_t i = 0; i < detections.size(); ++i)
                tagPoses[i] = estimateTagPose(detections[i], calib, *o.tagSizeM);
        const std::optional<BoardPose> pose = cameraPose(*tracker, o, detections, path);
        if (o.json)
            printJson(path, detections, tagPoses, pose);
        else
            printText(path, detections, tagPoses, pose);
        std::fflush(stdout);
        if (o.images.size() > 1)
            progress.update(fmt::format("{}/{} {}", n + 1, o.images.size(), path));
    }
    return failures > 0 ? kExitUsage : kExitOk;  // an image that cannot be read is bad input
}

}  // namespace

std::function<int()> addTrackCommand(CLI::App& app) {
    auto o = std::make_shared<TrackOptions>();
    CLI::App* cmd =
        app.add_subcommand("track", "detect AprilTags and estimate the camera pose on images");
    cmd->add_option("IMAGE", o->images, "images (PNG, JPEG, ...)")->required();
    cmd->add_option("--camera", o->camera,
                    "OpenCV calibration YAML (camera_matrix, distortion_coefficients, "
                    "image_width, image_height[, distortion_model: fisheye])")
        ->required()
        ->check(CLI::ExistingFile);
    auto* family = cmd->add_option("--family", o->family, "tag family (default tag36h11)")
                       ->check(CLI::IsMember(supportedTagFamilies()));
    cmd->add_option("--tag-size", o->tagSizeM,
                    "edge of the tag's black square, metres: adds cameraFromTag per detection")
        ->check(CLI::PositiveNumber);
    cmd->add_option("--board", o->board, "tag board TOML (docs/board-format.md): world frame")
        ->check(CLI::ExistingFile);
    cmd->add_flag("--json", o->json, "one JSON object per image on stdout");
    cmd->add_option("--decimate", o->detector.decimate,
                    "quad_decimate (default 0: full resolution, as one image predicts no tag "
                    "sizes; libapriltag's own default is 2)")
        ->check(CLI::Range(0.0, 16.0));
    cmd->add_option("--refine-edges", o->refineEdges, "refine_edges 0|1 (default 1)")
        ->check(CLI::IsMember({0, 1}));
    cmd->add_option("--linear-edges", o->linearEdges,
                    "re-fit the corners in linear light through --tone-curve; without "
                    "--tone-curve they stay libapriltag's (default 1)")
        ->check(CLI::IsMember({0, 1}));
    o->toneCurve.addTo(cmd, "", "images", false);
    // Unlike the other commands', track's curve has no default: a guessed one moves the corners.
    cmd->get_option("--tone-curve")
        ->description(
            "images: their transfer curve, srgb, reinhard or banterle (with --max-radiance and "
            "--white-luminance), for --linear-edges; no default (unknown: libapriltag's corners)");
    o->toneCurve.addColourTo(cmd, "", "images");
    cmd->add_option("--sigma", o->detector.sigma, "quad_sigma: Gaussian blur, pixels (default 0)")
        ->check(CLI::NonNegativeNumber);
    cmd->add_option("--threads", o->detector.threads, "detector threads (default 1)")
        ->check(CLI::Range(1, 64));
    cmd->add_flag("--quiet", o->quiet, "no progress on stderr");
    return [o, family, cmd] {
        o->familyGiven = family->count() > 0;
        o->curveGiven = cmd->count("--tone-curve") > 0 || cmd->count("--colour") > 0;
        return run(*o);
    };
}

}  // namespace previs
