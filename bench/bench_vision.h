#pragma once

// Timings of the vision pipeline on this machine (for BENCHMARKS.md and `previs bench`):
// AprilTag detection + board pose per 1280×720 frame, and fisheye → environment + light
// extraction per fisheye frame. Inputs come from shared/data.

#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

struct VisionTiming {
    std::string name;
    int runs = 0;
    double medianMs = 0.0;
    double p90Ms = 0.0;
    std::string note;  // e.g. tags found, reprojection error
};

// dataDir: the shared/data folder. runs: repetitions per measurement (the median is reported).
Result<std::vector<VisionTiming>> benchVision(const std::string& dataDir, int runs);

}  // namespace previs
