#include "vision/tag_search.h"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <set>

#include "vision/board_pose.h"

namespace previs {

namespace {

// Around a predicted tag the full-resolution pass looks this far beyond the predicted quad (the
// pose is a frame old, and libapriltag needs the white border around the black square).
constexpr double kSearchMarginFraction = 0.5;
constexpr int kMinSearchMarginPx = 16;

std::vector<cv::Rect> searchRegions(const std::vector<PredictedTag>& missed, cv::Size frame) {
    std::vector<cv::Rect> regions;
    for (const PredictedTag& t : missed) {
        const int margin =
            std::max(kMinSearchMarginPx,
                     int(std::ceil(kSearchMarginFraction * std::max(t.box.width, t.box.height))));
        cv::Rect r(t.box.x - margin, t.box.y - margin, t.box.width + 2 * margin,
                   t.box.height + 2 * margin);
        regions.push_back(r & cv::Rect(cv::Point(0, 0), frame));
    }
    // Overlapping regions become one, so no tag is searched (and found) twice.
    for (bool merged = true; merged;) {
        merged = false;
        for (size_t i = 0; i < regions.size() && !merged; ++i)
            for (size_t j = i + 1; j < regions.size() && !merged; ++j)
                if ((regions[i] & regions[j]).area() > 0) {
                    regions[i] |= regions[j];
                    regions.erase(regions.begin() + std::ptrdiff_t(j));
                    merged = true;
                }
    }
    return regions;
}

}  // namespace

std::vector<PredictedTag> predictTags(const TagBoard& board, const CameraCalibration& calibration,
                                      const cv::Matx44d& worldFromCamera, cv::Size frameSize) {
    const cv::Matx44d cameraFromWorld = invertRigid(worldFromCamera);
    std::vector<PredictedTag> out;
    for (const BoardTag& tag : board.tags()) {
        std::vector<cv::Point3d> camera;
        for (const cv::Point3d& p : board.worldCorners(tag)) {
            const cv::Vec4d q = cameraFromWorld * cv::Vec4d(p.x, p.y, p.z, 1.0);
            camera.emplace_back(q[0], q[1], q[2]);
        }
        if (std::any_of(camera.begin(), camera.end(),
                        [](const cv::Point3d& p) { return !(p.z > 0.0); }))
            continue;
        const std::vector<cv::Point2d> px = calibration.projectPoints(camera);
        bool inside = true;
        for (const cv::Point2d& p : px)
            inside = inside && p.x >= 0 && p.y >= 0 && p.x <= frameSize.width - 1 &&
                     p.y <= frameSize.height - 1;
        if (!inside) continue;
        PredictedTag t;
        t.id = tag.id;
        std::vector<cv::Point2f> pf(px.begin(), px.end());
        t.box = cv::boundingRect(pf);
        t.shortestEdgePx = INFINITY;
        for (size_t i = 0; i < 4; ++i)
            t.shortestEdgePx = std::min(t.shortestEdgePx, cv::norm(px[i] - px[(i + 1) % 4]));
        out.push_back(t);
    }
    return out;
}

float decimationFor(const std::vector<PredictedTag>& predicted) {
    if (predicted.empty()) return 1.0f;
    double smallest = INFINITY;
    for (const PredictedTag& t : predicted) smallest = std::min(smallest, t.shortestEdgePx);
    for (float d : {4.0f, 3.0f, 2.0f, 1.5f})
        if (d <= kMaxAutoDecimate && smallest / d >= kMinDecimatedTagPx) return d;
    return 1.0f;
}

std::vector<TagDetection> searchTags(TagDetector& detector, const cv::Mat& gray,
                                     const std::vector<PredictedTag>& predicted,
                                     TagSearchStats* stats) {
    const float fixed = detector.settings().decimate;
    const float decimate = fixed > 0.0f ? fixed : decimationFor(predicted);
    std::vector<TagDetection> found = detector.detect(gray, decimate);
    TagSearchStats local;
    local.decimate = decimate;
    if (decimate > 1.0f) {
        std::set<int> seen;
        for (const TagDetection& d : found) seen.insert(d.id);
        std::vector<PredictedTag> missed;
        for (const PredictedTag& t : predicted)
            if (!seen.count(t.id)) missed.push_back(t);
        std::set<int> wanted;
        for (const PredictedTag& t : missed) wanted.insert(t.id);
        for (const cv::Rect& r : searchRegions(missed, gray.size())) {
            for (TagDetection d : detector.detect(gray(r), 1.0f)) {
                if (!wanted.count(d.id) || seen.count(d.id)) continue;
                for (cv::Point2d& c : d.corners) c += cv::Point2d(r.x, r.y);
                seen.insert(d.id);
                found.push_back(d);
                ++local.redetected;
            }
        }
        // The prediction was wrong (the camera moved far, or to another board): the whole frame
        // at full resolution before calling the frame lost.
        if (found.empty() && !predicted.empty()) {
            found = detector.detect(gray, 1.0f);
            local.decimate = 1.0f;
            local.fullFrameRetry = true;
        }
    }
    if (stats) *stats = local;
    return found;
}

}  // namespace previs
