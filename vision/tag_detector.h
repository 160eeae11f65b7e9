#pragma once

// AprilTag detection with Debian's libapriltag 3.3, every C handle owned by a unique_ptr.

#include <array>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"

struct apriltag_detector;
struct apriltag_family;

namespace previs {

class CameraCalibration;

// Defaults are libapriltag's own (apriltag_detector_create and apriltag_detector_add_family),
// except decimate.
struct TagDetectorSettings {
    std::string family = "tag36h11";
    // quad_decimate; 0 = automatic: full resolution, or as coarse as the tags that the last pose
    // predicts allow (vision/tag_search.h). libapriltag's default of 2 loses small tags.
    float decimate = 0.0f;
    float sigma = 0.0f;              // quad_sigma, Gaussian blur before segmentation, pixels
    bool refineEdges = true;         // refine_edges
    double decodeSharpening = 0.25;  // decode_sharpening
    int threads = 1;                 // nthreads
    int bitsCorrected = 2;           // hamming errors corrected (memory grows steeply above 2)

    bool operator==(const TagDetectorSettings&) const = default;
};

// Families Debian's libapriltag 3.3 ships.
const std::vector<std::string>& supportedTagFamilies();

// The edge the detector's quad follows: `bits` across it (the family's width_at_border: 8 for
// tag36h11), ink inside and paper outside, or the other way round when `reversed` (the white
// ring inside a black one of tagStandard41h12/52h13, tagCircle21h7/49h12, tagCustom48h12).
struct TagBorder {
    int bits = 8;
    bool reversed = false;
};

struct TagDetection {
    int id = -1;
    int hamming = 0;
    double margin = 0.0;  // decision_margin
    // Exactly apriltag_detection_t::p: pixel coordinates (x = column, y = row, origin at the top
    // left pixel's top-left corner as libapriltag counts it), counter-clockwise around the tag.
    std::array<cv::Point2d, 4> corners;
};

// Owners of libapriltag's handles (outside TagDetector: a nested class's default member
// initialisers are not usable until the enclosing class is complete).
struct TagFamilyDeleter {
    void (*destroy)(apriltag_family*) = nullptr;
    void operator()(apriltag_family* family) const;
};
struct TagDetectorDeleter {
    void operator()(apriltag_detector* detector) const;
};

class TagDetector {
public:
    static Result<TagDetector> create(const TagDetectorSettings& settings);
    TagDetector(TagDetector&&) noexcept;
    TagDetector& operator=(TagDetector&&) noexcept;
    ~TagDetector();

    // 8-bit single-channel image (any stride, a region of a larger one too). Not reentrant: one
    // detector per thread. The first form decimates as the settings say (automatic: not at all).
    std::vector<TagDetection> detect(const cv::Mat& gray);
    std::vector<TagDetection> detect(const cv::Mat& gray, float decimate);

    const TagDetectorSettings& settings() const { return settings_; }
    // The family's quad edge (its width_at_border and reversed_border).
    TagBorder border() const;

private:
    TagDetector() = default;

    TagDetectorSettings settings_;
    // Declared before the detector, so the detector that refers to it is destroyed first.
    std::unique_ptr<apriltag_family, TagFamilyDeleter> family_;
    std::unique_ptr<apriltag_detector, TagDetectorDeleter> detector_;
};

// A TagDetection corner in OpenCV's pixel convention, the one every CameraCalibration uses.
// libapriltag puts a pixel's centre at +0.5 (pixel x covers [x, x+1): its line fit adds 0.5 "for
// pixel center bias" and decimation maps (p − 0.5)·d + 0.5), OpenCV at the integer; measured on
// rendered boards with exact ground truth (tests/vision/rendered_pose_test.cpp).
inline cv::Point2d openCvPixel(const cv::Point2d& apriltagCorner) {
    return apriltagCorner - cv::Point2d(0.5, 0.5);
}

// The tag's pose in the camera frame from libapriltag's estimate_tag_pose (tag frame as it
// defines it: origin at the tag centre, x right, y down, z into the tag, for corner 0 at
// (-s/2, s/2, 0)). Returns nullopt when the corners cannot be undistorted (behind a fisheye).
std::optional<cv::Matx44d> estimateTagPose(const TagDetection& detection,
                                           const CameraCalibration& calibration, double tagSizeM);

// The four corners in the tag frame of estimateTagPose, in the order of TagDetection::corners.
std::array<cv::Point3d, 4> tagCornersInTagFrame(double tagSizeM);

}  // namespace previs
