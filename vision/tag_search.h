#pragma once

// Where and how finely to look for a board's tags in a frame (issue 38: small and distant tags at
// the default settings). libapriltag's quad_decimate halves the work per factor but loses every
// tag whose decimated image is too small to segment: at its default of 2, 16 of the 22 tags of
// its authors' own test photographs. So the search decimates only as far as the smallest tag the
// last pose predicts allows, re-detects at full resolution around each predicted tag the coarse
// pass missed, and looks at full resolution when nothing predicts the board.

#include <opencv2/core.hpp>
#include <optional>
#include <vector>

#include "vision/camera_calibration.h"
#include "vision/tag_board.h"
#include "vision/tag_detector.h"

namespace previs {

// A tag's edge must keep this many pixels after decimation (3 px a bit for tag36h11's 8 bits
// across its border): libapriltag segments smaller quads unreliably.
inline constexpr double kMinDecimatedTagPx = 24.0;
inline constexpr float kMaxAutoDecimate = 4.0f;

struct PredictedTag {
    int id = -1;
    cv::Rect box;                 // the predicted corners' bounds, inside the frame
    double shortestEdgePx = 0.0;  // of the predicted quad
};

// The board's tags wholly in front of the camera and inside a frame of `frameSize` at
// `worldFromCamera`.
std::vector<PredictedTag> predictTags(const TagBoard& board, const CameraCalibration& calibration,
                                      const cv::Matx44d& worldFromCamera, cv::Size frameSize);

// The coarsest decimation (1, 1.5, 2, 3 or 4: libapriltag's fast paths) that keeps the smallest
// predicted tag at kMinDecimatedTagPx; 1 when nothing is predicted.
float decimationFor(const std::vector<PredictedTag>& predicted);

struct TagSearchStats {
    float decimate = 1.0f;        // of the whole-frame pass
    int redetected = 0;           // tags found only by the full-resolution pass around predictions
    bool fullFrameRetry = false;  // the decimated passes found nothing; full resolution did
};

// One frame's detections. `settings.decimate` > 0 fixes the whole-frame pass's decimation; 0
// chooses it from `predicted` (decimationFor). Tags predicted but missed by a decimated pass are
// looked for again at full resolution in their neighbourhood, and when the decimated passes find
// nothing where tags were predicted, the whole frame is searched at full resolution.
std::vector<TagDetection> searchTags(TagDetector& detector, const cv::Mat& gray,
                                     const std::vector<PredictedTag>& predicted,
                                     TagSearchStats* stats = nullptr);

}  // namespace previs
