#pragma once

// Tag corners and poses on images nobody here made: ViSP's rendered AprilTag benchmark
// (shared/data/apriltag/visp_benchmark_synthetic, its README §2), five tags at true poses, one
// 640x480 render per family. For each way the box can place a tag's corners (libapriltag's, as
// the tracker keeps them when no camera curve is configured, or re-fitted in linear light through
// a curve, vision/tag_edges.h) it measures the corners against the true projection and each
// tag's pose (estimateTagPose, as `previs track` prints it) against the true pose, with ViSP's own
// error measures and thresholds (lagadic/visp, modules/detection/test/apriltag-with-dataset/
// testAprilTag.cpp). The test tests/vision/tag_edges_test.cpp and the program
// previs_bench_tag_corners (bench/results/benchmarks_2026-12-06.md, "Tag corners on third-party
// images") share it.

#include <array>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "vision/tag_detector.h"
#include "vision/tag_edges.h"

namespace previs::bench {

struct VispTagFamily {
    std::string file;    // the image's stem: tag36_11
    std::string family;  // libapriltag's name: tag36h11
    double scale = 1.0;  // the black square over the whole tag's edge (README)
};

// The six families of the shared data, tag36h11 first (the others have a reversed border).
const std::vector<VispTagFamily>& vispTagFamilies();

// The image the box is shown: the render as ViSP made it (linear in its codes:
// tests/vision/tag_edges_test.cpp), or as a camera with the sRGB curve would have recorded the
// same scene (each code re-encoded: 255·srgb(code/255), rounded), the case the refit exists for.
enum class VispImage { AsRendered, ThroughSrgb };
const char* toString(VispImage image);

// How the box places a tag's corners: the tracker (vision/board_pose.h) with this curve as
// TrackerSettings::linearFromCode.
struct CornerMethod {
    std::string name;
    std::optional<LinearFromCode> curve;  // nullopt: no curve told, libapriltag's corners
};

// The box's default (no curve) and a refit through each curve that could describe the images:
// gamma 1 (identityLinearFromCode: the renders' own; no config or command names it yet) and
// sRGB (`--tone-curve srgb`, a radiometry section's defaults). Reinhard and Banterle decode sRGB
// first and bend further, so they are further from gamma 1 than sRGB is.
std::vector<CornerMethod> vispCornerMethods();

struct VispTagError {
    int id = -1;
    std::array<cv::Point2d, 4> corners;  // libapriltag's convention (TagDetection::corners)
    // Against the true projection (in the box's pixel convention, vision/tag_detector.h
    // openCvPixel): the corners' mean offset away from the tag's centre (the tag's scale, which
    // sets its distance), and their mean offset (a shift of the whole tag).
    double outwardPx = 0.0;
    cv::Point2d shiftPx;
    double translationMm = 0.0;  // estimateTagPose against the true pose: distance …
    double rotationDeg = 0.0;    // … and angle
    // ViSP's measures: rms over x, y, z of the translation error, and of the θu vector's.
    double vispTranslationM = 0.0;
    double vispRotationRad = 0.0;
    bool withinVispThresholds = false;
};

struct VispMethodResult {
    std::string method;
    int moved = 0;                   // tags whose corners differ from libapriltag's
    std::vector<VispTagError> tags;  // ids 0..4, those detected
    // The five tags as one board at their true poses: the tracker's own camera pose (world =
    // the true camera frame), its distance and angle from the identity; nullopt when lost.
    std::optional<std::array<double, 2>> boardErrorMmDeg;
};

struct VispFamilyResult {
    VispTagFamily family;
    VispImage image = VispImage::AsRendered;
    std::vector<TagDetection> libapriltag;  // libapriltag at full resolution, sorted by id
    // corners_<file>.txt: libapriltag's corners as ViSP published them, by id (README §2).
    std::vector<std::array<cv::Point2d, 4>> published;
    std::vector<VispMethodResult> methods;  // in the order of the methods asked for
};

// ViSP's thresholds for tag `id` (0..4): translation rms (m), θu rms (rad).
double vispTranslationThresholdM(int id);
double vispRotationThresholdRad(int id);

// One result per image. `dataDir`: the shared data folder (sharedDataDir()). An error names the
// missing file.
Result<std::vector<VispFamilyResult>> measureVispFamily(const std::string& dataDir,
                                                        const VispTagFamily& family,
                                                        const std::vector<VispImage>& images,
                                                        const std::vector<CornerMethod>& methods);

// Real photos with a weaker truth: duckietown_rotation (README §3), one tag36h11 tag turned by
// a known yaw (hand-placed, within a few degrees) in front of a rectified Duckiebot camera. Per
// method, the tag's yaw in each photo (estimateTagPose; the normal's angle in the camera's x-z
// plane), and over all pairs of photos the error of the yaw difference against the file names'.
struct DuckietownYaw {
    std::string method;
    std::vector<std::array<double, 2>> angleAndYawDeg;  // per photo: file angle, measured yaw
    double medianPairErrorDeg = 0.0, maxPairErrorDeg = 0.0;
};
Result<std::vector<DuckietownYaw>> measureDuckietownYaw(const std::string& dataDir,
                                                        const std::vector<CornerMethod>& methods);
std::string duckietownTable(const std::vector<DuckietownYaw>& results);

// The table BENCHMARKS.md quotes: one row per family, image and method.
std::string vispTagTable(const std::vector<VispFamilyResult>& results);

}  // namespace previs::bench
