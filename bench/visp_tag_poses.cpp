#include "bench/visp_tag_poses.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>

#include "vision/board_pose.h"
#include "vision/camera_calibration.h"
#include "vision/inverse_tone_map.h"
#include "vision/tag_board.h"

namespace previs::bench {

namespace {

constexpr int kTags = 5;
constexpr double kPi = 3.14159265358979323846;

std::string folder(const std::string& dataDir) {
    return dataDir + "/apriltag/visp_benchmark_synthetic/";
}

// README: ids 0-2 are 0.25 m tags, ids 3-4 0.125 m, times the family's black-square scale.
double tagSizeM(const VispTagFamily& f, int id) { return (id <= 2 ? 0.25 : 0.125) * f.scale; }

// ViSP's tag frame is estimateTagPose's turned 180° about x (README).
const cv::Matx44d kVispFromApriltag(1, 0, 0, 0, 0, -1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1);

// The true cameraFromTag of tag `id` in estimateTagPose's frame.
Result<cv::Matx44d> trueCameraFromTag(const std::string& dir, int id) {
    const std::string path = dir + "cMo_" + std::to_string(id) + ".txt";
    std::ifstream in(path);
    cv::Matx44d m;
    for (double& v : m.val) in >> v;
    if (!in) return makeError("{}: cannot read a 4x4 pose", path);
    return m * kVispFromApriltag;
}

Result<std::vector<std::array<cv::Point2d, 4>>> readPublishedCorners(const std::string& path) {
    std::ifstream in(path);
    if (!in) return makeError("{}: cannot open", path);
    std::vector<std::array<cv::Point2d, 4>> corners(kTags);
    int id = -1, read = 0;
    while (in >> id) {
        if (id < 0 || id >= kTags) return makeError("{}: tag id {} is not 0..4", path, id);
        for (cv::Point2d& c : corners[size_t(id)]) in >> c.x >> c.y;
        ++read;
    }
    if (read != kTags) return makeError("{}: {} tags, expected 5", path, read);
    return corners;
}

Result<CameraCalibration> vispCamera() {
    // ViSP's testAprilTag.cpp: fx = fy = 700, cx = 320, cy = 240, no distortion.
    return CameraCalibration::create(cv::Matx33d(700, 0, 320, 0, 700, 240, 0, 0, 1), {},
                                     cv::Size(640, 480), DistortionModel::Pinhole,
                                     "ViSP benchmark camera");
}

// The rendered tags decode with 0 bit errors; correcting 1 instead of 2 bits keeps the decode
// tables of the 48-52 bit families from taking ~25 s to build.
TagDetectorSettings detectorSettings(const VispTagFamily& f) {
    TagDetectorSettings s;
    s.family = f.family;
    s.bitsCorrected = 1;
    return s;
}

std::vector<TagDetection> sortedById(std::vector<TagDetection> d) {
    std::sort(d.begin(), d.end(), [](const auto& a, const auto& b) { return a.id < b.id; });
    return d;
}

// The true corners in OpenCV's pixel convention (openCvPixel's).
std::array<cv::Point2d, 4> trueCorners(const cv::Matx44d& cameraFromTag, double sizeM,
                                       const CameraCalibration& camera) {
    std::array<cv::Point2d, 4> out;
    const std::array<cv::Point3d, 4> tag = tagCornersInTagFrame(sizeM);
    for (int k = 0; k < 4; ++k) {
        const cv::Vec4d c = cameraFromTag * cv::Vec4d(tag[k].x, tag[k].y, tag[k].z, 1.0);
        out[k] = {camera.fx() * c[0] / c[2] + camera.cx(), camera.fy() * c[1] / c[2] + camera.cy()};
    }
    return out;
}

cv::Vec3d thetaU(const cv::Matx44d& m) {
    cv::Vec3d v;
    cv::Rodrigues(cv::Matx33d(m.get_minor<3, 3>(0, 0)), v);
    return v;
}

cv::Vec3d translation(const cv::Matx44d& m) { return {m(0, 3), m(1, 3), m(2, 3)}; }

void setPoseErrors(const cv::Matx44d& estimated, const cv::Matx44d& truth, VispTagError& e) {
    e.translationMm = cv::norm(translation(estimated) - translation(truth)) * 1e3;
    const cv::Matx44d relative = estimated.inv() * truth;
    e.rotationDeg = cv::norm(thetaU(relative)) * 180.0 / kPi;
    // ViSP compares θu vectors of its own frame, component by component.
    const cv::Vec3d dt = translation(estimated) - translation(truth);
    const cv::Vec3d du = thetaU(estimated * kVispFromApriltag) - thetaU(truth * kVispFromApriltag);
    e.vispTranslationM = cv::norm(dt) / std::sqrt(3.0);
    e.vispRotationRad = cv::norm(du) / std::sqrt(3.0);
    e.withinVispThresholds = e.vispTranslationM < vispTranslationThresholdM(e.id) &&
                             e.vispRotationRad < vispRotationThresholdRad(e.id);
}

VispTagError tagError(const TagDetection& d, const VispTagFamily& f, const cv::Matx44d& truth,
                      const CameraCalibration& camera) {
    VispTagError e;
    e.id = d.id;
    e.corners = d.corners;
    const double size = tagSizeM(f, d.id);
    const std::array<cv::Point2d, 4> expected = trueCorners(truth, size, camera);
    cv::Point2d centre(0, 0);
    for (const cv::Point2d& c : expected) centre += 0.25 * c;
    for (int k = 0; k < 4; ++k) {
        const cv::Point2d off = openCvPixel(d.corners[k]) - expected[k];
        const cv::Point2d out = expected[k] - centre;
        e.shiftPx += 0.25 * off;
        e.outwardPx += 0.25 * off.dot(out) / cv::norm(out);
    }
    if (std::optional<cv::Matx44d> pose = estimateTagPose(d, camera, size))
        setPoseErrors(*pose, truth, e);
    else
        e.translationMm = e.rotationDeg = e.vispTranslationM = e.vispRotationRad = INFINITY;
    return e;
}

VispMethodResult measureMethod(const std::string& name, const std::vector<TagDetection>& tags,
                               const std::vector<TagDetection>& libapriltag, Tracker& tracker,
                               const VispTagFamily& f, const std::vector<cv::Matx44d>& truth,
                               const CameraCalibration& camera) {
    VispMethodResult r;
    r.method = name;
    for (size_t i = 0; i < tags.size(); ++i) {
        if (i < libapriltag.size() && tags[i].corners != libapriltag[i].corners) ++r.moved;
        if (tags[i].id >= 0 && tags[i].id < kTags)
            r.tags.push_back(tagError(tags[i], f, truth[size_t(tags[i].id)], camera));
    }
    tracker.reset();
    const TrackingState& s = tracker.update(tags);
    if (!s.lost) {
        // World = the true camera frame: the tracker's worldFromCamera should be the identity.
        const cv::Matx44d& m = s.pose->worldFromCamera;
        r.boardErrorMmDeg = std::array<double, 2>{cv::norm(translation(m)) * 1e3,
                                                  cv::norm(thetaU(m)) * 180.0 / kPi};
    }
    return r;
}

// What a camera with the sRGB curve records of the scene a linear render shows.
cv::Mat throughSrgb(const cv::Mat& linear) {
    cv::Mat lut(1, 256, CV_8U);
    for (int i = 0; i < 256; ++i) {
        const double v = i / 255.0;
        const double e = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
        lut.at<uint8_t>(i) = cv::saturate_cast<uint8_t>(std::lround(255.0 * e));
    }
    cv::Mat out;
    cv::LUT(linear, lut, out);
    return out;
}

std::string joined(const std::vector<VispTagError>& tags, double VispTagError::*field,
                   const char* format) {
    std::string s;
    for (const VispTagError& t : tags)
        s += (s.empty() ? "" : ", ") + fmt::format(fmt::runtime(format), t.*field);
    return s;
}

}  // namespace

const char* toString(VispImage image) {
    return image == VispImage::AsRendered ? "as rendered" : "through sRGB";
}

const std::vector<VispTagFamily>& vispTagFamilies() {
    static const std::vector<VispTagFamily> families = {
        {"tag36_11", "tag36h11", 8.0 / 10.0},        {"tag21_07", "tagCircle21h7", 5.0 / 9.0},
        {"tag41_12", "tagStandard41h12", 5.0 / 9.0}, {"tag48_12", "tagCustom48h12", 6.0 / 10.0},
        {"tag49_12", "tagCircle49h12", 5.0 / 11.0},  {"tag52_13", "tagStandard52h13", 6.0 / 10.0},
    };
    return families;
}

std::vector<CornerMethod> vispCornerMethods() {
    return {{"box default (no curve): libapriltag's", std::nullopt},
            {"refit through gamma 1", identityLinearFromCode()},
            {"refit through sRGB", linearFromCodeTable(InverseToneMapSettings{})}};
}

double vispTranslationThresholdM(int id) {
    static constexpr double t[kTags] = {0.025, 0.09, 0.05, 0.13, 0.09};
    return t[std::clamp(id, 0, kTags - 1)];
}

double vispRotationThresholdRad(int id) {
    static constexpr double t[kTags] = {0.04, 0.075, 0.07, 0.18, 0.13};
    return t[std::clamp(id, 0, kTags - 1)];
}

Result<std::vector<VispFamilyResult>> measureVispFamily(const std::string& dataDir,
                                                        const VispTagFamily& family,
                                                        const std::vector<VispImage>& images,
                                                        const std::vector<CornerMethod>& methods) {
    const std::string dir = folder(dataDir);
    const std::string path = dir + family.file + "_640x480.png";
    const cv::Mat rendered = cv::imread(path, cv::IMREAD_GRAYSCALE);
    if (rendered.empty()) return makeError("{}: cannot read the image", path);
    Result<CameraCalibration> camera = vispCamera();
    if (!camera) return camera.error();
    std::vector<cv::Matx44d> truth;
    std::vector<BoardTag> board;
    for (int id = 0; id < kTags; ++id) {
        Result<cv::Matx44d> t = trueCameraFromTag(dir, id);
        if (!t) return t.error();
        truth.push_back(*t);
        board.push_back({id, tagSizeM(family, id), *t});
    }
    Result<TagBoard> tagBoard = TagBoard::create(board, "ViSP benchmark truth");
    if (!tagBoard) return tagBoard.error();
    Result<std::vector<std::array<cv::Point2d, 4>>> published =
        readPublishedCorners(dir + "corners_" + family.file + ".txt");
    if (!published) return published.error();

    // One detector and one tracker for every image: their decode tables take seconds to build.
    TagDetectorSettings full = detectorSettings(family);
    full.decimate = 1.0f;
    Result<TagDetector> detector = TagDetector::create(full);
    if (!detector) return detector.error();
    Result<Tracker> tracker = Tracker::create(detectorSettings(family), *tagBoard, *camera);
    if (!tracker) return tracker.error();
    std::vector<VispFamilyResult> results;
    for (VispImage image : images) {
        const cv::Mat gray = image == VispImage::ThroughSrgb ? throughSrgb(rendered) : rendered;
        VispFamilyResult& out = results.emplace_back();
        out.family = family;
        out.image = image;
        out.published = *published;
        out.libapriltag = sortedById(detector->detect(gray));
        for (const CornerMethod& m : methods) {
            std::vector<TagDetection> tags = out.libapriltag;
            if (m.curve) {
                // What Tracker::track does with TrackerSettings::linearFromCode set.
                refineTagCornersInLinearLight(tags, gray, *m.curve, detector->border(), &*camera);
            } else {
                // The box as configured by default: the tracker itself, no curve told.
                tracker->reset();
                tracker->track(gray);
                tags = sortedById(tracker->detections());
            }
            out.methods.push_back(
                measureMethod(m.name, tags, out.libapriltag, *tracker, family, truth, *camera));
        }
    }
    return results;
}

Result<std::vector<DuckietownYaw>> measureDuckietownYaw(const std::string& dataDir,
                                                        const std::vector<CornerMethod>& methods) {
    const std::string dir = dataDir + "/apriltag/duckietown_rotation/";
    // README §3: K from the upstream test_info.yaml, rectified (no distortion), a 0.065 m tag.
    Result<CameraCalibration> camera = CameraCalibration::create(
        cv::Matx33d(329.8729619143081, 0, 528, 0, 332.94611303946357, 396, 0, 0, 1), {},
        cv::Size(1056, 792), DistortionModel::Pinhole, "duckietown camera");
    if (!camera) return camera.error();
    TagDetectorSettings settings;
    settings.decimate = 1.0f;
    Result<TagDetector> detector = TagDetector::create(settings);
    if (!detector) return detector.error();
    std::vector<DuckietownYaw> out(methods.size());
    for (int angle : {-70, -60, -40, -30, -20, 0, 20, 40, 50, 70}) {
        const std::string path = dir + "test_image_rotation_" + std::to_string(angle) + ".png";
        const cv::Mat gray = cv::imread(path, cv::IMREAD_GRAYSCALE);
        if (gray.empty()) return makeError("{}: cannot read the image", path);
        const std::vector<TagDetection> detected = detector->detect(gray);
        if (detected.size() != 1)
            return makeError("{}: {} tags, expected 1", path, detected.size());
        for (size_t m = 0; m < methods.size(); ++m) {
            std::vector<TagDetection> tags = detected;
            if (methods[m].curve)
                refineTagCornersInLinearLight(tags, gray, *methods[m].curve, detector->border(),
                                              &*camera);
            std::optional<cv::Matx44d> pose = estimateTagPose(tags[0], *camera, 0.065);
            if (!pose) return makeError("{}: no pose", path);
            const double yaw = std::atan2((*pose)(0, 2), (*pose)(2, 2)) * 180.0 / kPi;
            out[m].method = methods[m].name;
            out[m].angleAndYawDeg.push_back({double(angle), yaw});
        }
    }
    for (DuckietownYaw& d : out) {
        // The yaw turns against the file's angle (README: about −angle + 2°).
        std::vector<double> errors;
        for (size_t i = 0; i < d.angleAndYawDeg.size(); ++i)
            for (size_t j = i + 1; j < d.angleAndYawDeg.size(); ++j) {
                const auto& a = d.angleAndYawDeg[i];
                const auto& b = d.angleAndYawDeg[j];
                errors.push_back(std::abs((a[1] - b[1]) + (a[0] - b[0])));
            }
        std::sort(errors.begin(), errors.end());
        d.medianPairErrorDeg = errors[errors.size() / 2];
        d.maxPairErrorDeg = errors.back();
    }
    return out;
}

std::string duckietownTable(const std::vector<DuckietownYaw>& results) {
    std::string s =
        "| corners | yaw + file angle per photo, ° (−70 … 70) | pair error median, ° | "
        "max, ° |\n|---|---|---|---|\n";
    for (const DuckietownYaw& d : results) {
        std::string yaws;
        for (const auto& [angle, yaw] : d.angleAndYawDeg)
            yaws += (yaws.empty() ? "" : ", ") + fmt::format("{:+.1f}", yaw + angle);
        s += fmt::format("| {} | {} | {:.2f} | {:.2f} |\n", d.method, yaws, d.medianPairErrorDeg,
                         d.maxPairErrorDeg);
    }
    return s;
}

std::string vispTagTable(const std::vector<VispFamilyResult>& results) {
    std::string s =
        "| family | image | corners | tags moved | corners outward, px (ids 0-4) | translation "
        "error, mm | rotation error, ° | within ViSP's thresholds | board of 5, mm / ° |\n"
        "|---|---|---|---|---|---|---|---|---|\n";
    for (const VispFamilyResult& f : results) {
        for (const VispMethodResult& m : f.methods) {
            const auto within = std::count_if(m.tags.begin(), m.tags.end(),
                                              [](const auto& t) { return t.withinVispThresholds; });
            const std::string board = m.boardErrorMmDeg
                                          ? fmt::format("{:.1f} / {:.2f}", (*m.boardErrorMmDeg)[0],
                                                        (*m.boardErrorMmDeg)[1])
                                          : std::string("lost");
            s += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} of {} | {} |\n",
                             f.family.family, toString(f.image), m.method, m.moved,
                             joined(m.tags, &VispTagError::outwardPx, "{:+.2f}"),
                             joined(m.tags, &VispTagError::translationMm, "{:.1f}"),
                             joined(m.tags, &VispTagError::rotationDeg, "{:.2f}"), within,
                             m.tags.size(), board);
        }
    }
    cv::Point2d shift(0, 0);
    int tags = 0;
    for (const VispFamilyResult& f : results)
        for (const VispMethodResult& m : f.methods)
            for (const VispTagError& t : m.tags) shift += t.shiftPx, ++tags;
    if (tags > 0)
        s += fmt::format(
            "\nThe whole tag's mean shift from the true projection, over all rows: "
            "({:+.2f}, {:+.2f}) px\n",
            shift.x / tags, shift.y / tags);
    return s;
}

}  // namespace previs::bench
