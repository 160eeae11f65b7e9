#include "vision/tag_detector.h"

#include <apriltag/apriltag.h>
#include <apriltag/apriltag_pose.h>
#include <apriltag/tag16h5.h>
#include <apriltag/tag25h9.h>
#include <apriltag/tag36h11.h>
#include <apriltag/tagCircle21h7.h>
#include <apriltag/tagCircle49h12.h>
#include <apriltag/tagCustom48h12.h>
#include <apriltag/tagStandard41h12.h>
#include <apriltag/tagStandard52h13.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <opencv2/imgproc.hpp>
#include <utility>

#include "base/log.h"
#include "vision/camera_calibration.h"

namespace previs {

namespace {

struct FamilyEntry {
    const char* name;
    apriltag_family_t* (*create)();
    void (*destroy)(apriltag_family_t*);
};

const FamilyEntry kFamilies[] = {
    {"tag36h11", tag36h11_create, tag36h11_destroy},
    {"tag25h9", tag25h9_create, tag25h9_destroy},
    {"tag16h5", tag16h5_create, tag16h5_destroy},
    {"tagCircle21h7", tagCircle21h7_create, tagCircle21h7_destroy},
    {"tagCircle49h12", tagCircle49h12_create, tagCircle49h12_destroy},
    {"tagStandard41h12", tagStandard41h12_create, tagStandard41h12_destroy},
    {"tagStandard52h13", tagStandard52h13_create, tagStandard52h13_destroy},
    {"tagCustom48h12", tagCustom48h12_create, tagCustom48h12_destroy},
};

struct DetectionsDeleter {
    void operator()(zarray_t* detections) const { apriltag_detections_destroy(detections); }
};

// apriltag_pose_t's matrices come from libapriltag's own malloc; Debian's library does not export
// matd_destroy, and a matd_t is one malloc block, so free() releases it.
struct MatdFree {
    void operator()(matd_t* m) const { std::free(m); }
};
using MatdPtr = std::unique_ptr<matd_t, MatdFree>;

MatdPtr makeMatd(unsigned rows, unsigned cols) {
    auto* m = static_cast<matd_t*>(std::calloc(1, sizeof(matd_t) + sizeof(double) * rows * cols));
    PV_ASSERT(m != nullptr);
    m->nrows = rows;
    m->ncols = cols;
    return MatdPtr(m);
}

}  // namespace

const std::vector<std::string>& supportedTagFamilies() {
    static const std::vector<std::string> names = [] {
        std::vector<std::string> n;
        for (const FamilyEntry& f : kFamilies) n.emplace_back(f.name);
        return n;
    }();
    return names;
}

void TagFamilyDeleter::operator()(apriltag_family* family) const {
    if (family && destroy) destroy(family);
}

void TagDetectorDeleter::operator()(apriltag_detector* detector) const {
    apriltag_detector_destroy(detector);
}

TagDetector::TagDetector(TagDetector&&) noexcept = default;
TagDetector& TagDetector::operator=(TagDetector&&) noexcept = default;
TagDetector::~TagDetector() = default;

Result<TagDetector> TagDetector::create(const TagDetectorSettings& settings) {
    const FamilyEntry* entry = nullptr;
    for (const FamilyEntry& f : kFamilies)
        if (settings.family == f.name) entry = &f;
    if (!entry) {
        std::string list;
        for (const FamilyEntry& f : kFamilies)
            list += std::string(list.empty() ? "" : ", ") + f.name;
        return makeError("--family {}: unknown AprilTag family (supported: {})", settings.family,
                         list);
    }
    if (!(settings.decimate >= 1.0f || settings.decimate == 0.0f) ||
        !std::isfinite(settings.decimate))
        return makeError("--decimate {}: must be 0 (automatic) or a number >= 1",
                         settings.decimate);
    if (!(settings.sigma >= 0.0f) || !std::isfinite(settings.sigma))
        return makeError("--sigma {}: must be a number >= 0", settings.sigma);
    if (settings.bitsCorrected < 0 || settings.bitsCorrected > 3)
        return makeError("AprilTag bits corrected {}: must be 0..3", settings.bitsCorrected);

    TagDetector detector;
    detector.settings_ = settings;
    detector.family_ = std::unique_ptr<apriltag_family, TagFamilyDeleter>(
        entry->create(), TagFamilyDeleter{entry->destroy});
    detector.detector_.reset(apriltag_detector_create());
    if (!detector.family_ || !detector.detector_)
        return makeError("AprilTag detector for family {}: out of memory", settings.family);
    apriltag_detector_t* td = detector.detector_.get();
    apriltag_detector_add_family_bits(td, detector.family_.get(), settings.bitsCorrected);
    td->quad_sigma = settings.sigma;
    td->refine_edges = settings.refineEdges;
    td->decode_sharpening = settings.decodeSharpening;
    td->nthreads = std::max(1, settings.threads);
    return detector;
}

TagBorder TagDetector::border() const {
    return {family_->width_at_border, family_->reversed_border};
}

std::vector<TagDetection> TagDetector::detect(const cv::Mat& gray) {
    return detect(gray, settings_.decimate > 0.0f ? settings_.decimate : 1.0f);
}

std::vector<TagDetection> TagDetector::detect(const cv::Mat& gray, float decimate) {
    std::vector<TagDetection> out;
    PV_ASSERT(decimate >= 1.0f);
    detector_->quad_decimate = decimate;
    PV_ASSERT(gray.type() == CV_8UC1);
    if (gray.empty()) return out;
    // libapriltag reads the buffer only; its image type has no const member.
    image_u8_t image{gray.cols, gray.rows, static_cast<int32_t>(gray.step[0]),
                     const_cast<uint8_t*>(gray.ptr<uint8_t>())};
    std::unique_ptr<zarray_t, DetectionsDeleter> detections(
        apriltag_detector_detect(detector_.get(), &image));
    if (!detections) return out;
    const int n = zarray_size(detections.get());
    out.reserve(n);
    for (int i = 0; i < n; ++i) {
        apriltag_detection_t* det = nullptr;
        zarray_get(detections.get(), i, &det);
        TagDetection d;
        d.id = det->id;
        d.hamming = det->hamming;
        d.margin = det->decision_margin;
        for (int c = 0; c < 4; ++c) d.corners[c] = cv::Point2d(det->p[c][0], det->p[c][1]);
        out.push_back(d);
    }
    return out;
}

std::array<cv::Point3d, 4> tagCornersInTagFrame(double tagSizeM) {
    // libapriltag's homography maps the ideal tag (-1,1), (1,1), (1,-1), (-1,-1) to p[0..3], and
    // estimate_tag_pose scales that square by tagsize/2.
    const double h = 0.5 * tagSizeM;
    return {cv::Point3d(-h, h, 0.0), cv::Point3d(h, h, 0.0), cv::Point3d(h, -h, 0.0),
            cv::Point3d(-h, -h, 0.0)};
}

std::optional<cv::Matx44d> estimateTagPose(const TagDetection& detection,
                                           const CameraCalibration& calibration, double tagSizeM) {
    // estimate_tag_pose assumes an ideal pinhole camera: it back-projects p[] with fx, fy, cx, cy
    // only. So the corners are undistorted with the calibration first, and the homography it
    // starts from is recomputed from the undistorted corners (det->H of the raw corners would
    // disagree with them on a distorted lens).
    std::vector<cv::Point2d> raw;
    for (const cv::Point2d& c : detection.corners) raw.push_back(openCvPixel(c));
    std::vector<cv::Point2d> ideal = calibration.undistortPixels(raw);
    for (const cv::Point2d& p : ideal)
        if (!std::isfinite(p.x) || !std::isfinite(p.y)) return std::nullopt;

    const cv::Point2f square[4] = {{-1.f, 1.f}, {1.f, 1.f}, {1.f, -1.f}, {-1.f, -1.f}};
    cv::Point2f dst[4];
    for (int i = 0; i < 4; ++i) dst[i] = cv::Point2f(float(ideal[i].x), float(ideal[i].y));
    cv::Mat h = cv::getPerspectiveTransform(square, dst, cv::DECOMP_LU);
    MatdPtr hm = makeMatd(3, 3);
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) MATD_EL(hm.get(), r, c) = h.at<double>(r, c);

    apriltag_detection_t det{};
    det.id = detection.id;
    det.hamming = detection.hamming;
    det.decision_margin = float(detection.margin);
    det.H = hm.get();
    for (int i = 0; i < 4; ++i) {
        det.p[i][0] = ideal[i].x;
        det.p[i][1] = ideal[i].y;
    }
    det.c[0] = MATD_EL(hm.get(), 0, 2) / MATD_EL(hm.get(), 2, 2);
    det.c[1] = MATD_EL(hm.get(), 1, 2) / MATD_EL(hm.get(), 2, 2);

    apriltag_detection_info_t info{
        &det, tagSizeM, calibration.fx(), calibration.fy(), calibration.cx(), calibration.cy()};
    apriltag_pose_t pose{nullptr, nullptr};
    estimate_tag_pose(&info, &pose);
    MatdPtr rotation(pose.R);
    MatdPtr translation(pose.t);
    if (!rotation || !translation) return std::nullopt;
    cv::Matx44d cameraFromTag = cv::Matx44d::eye();
    for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) cameraFromTag(r, c) = MATD_EL(rotation.get(), r, c);
        cameraFromTag(r, 3) = MATD_EL(translation.get(), r, 0);
    }
    for (int i = 0; i < 16; ++i)
        if (!std::isfinite(cameraFromTag.val[i])) return std::nullopt;
    return cameraFromTag;
}

}  // namespace previs
