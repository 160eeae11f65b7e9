#pragma once

// A take's camera track, offline (issue 36): the tracker run on every scene frame in order (not
// only on those the live service had time for), and the whole track smoothed
// (vision/track_smoother.h). `previs render-session` renders with it, `previs export-track`
// hands it to post.

#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "config/service_config.h"
#include "io/session.h"

namespace previs {

struct TakeFrame {
    RecordedFrameEntry entry;             // entry.file empty: the index line was unusable
    std::string problem;                  // why this frame cannot be rendered; empty when it can
    std::optional<cv::Matx44d> tracked;   // the tracker's pose on this very frame
    std::optional<cv::Matx44d> smoothed;  // over the whole take
    int tags = 0;
    double reprojErrorPx = 0.0;
    double positionStdM = 0.0;  // the tracked pose's one sigma (BoardPose::positionStdM)
    double rotationStdDeg = 0.0;
};

struct TakeTrack {
    std::vector<TakeFrame> frames;  // the take's scene frames, index = frame number from 0
    // Index lines that could not be used, each "FILE:LINE: why" (reported, never fatal).
    std::vector<std::string> skippedLines;
};

// Reads the scene camera's index leniently and tracks every frame (decoding each). A frame that
// does not decode gets its problem set and no pose; the track goes on. `progress` (optional)
// hears of each frame tracked: (frames done, frames in the take).
using TrackProgress = std::function<void(size_t done, size_t total)>;
Result<TakeTrack> trackTake(const SessionInfo& session, const ServiceConfig& config,
                            const TrackProgress& progress = {});

}  // namespace previs
