#pragma once

// The box against ground truth on a set whose light is known (issue 51): a frame's truth — the
// set rendered at the frame's true pose under the true lighting, mixed (L_om: real and virtual)
// and real-only (L_or), with the virtual mask; bench/make_demo_session.cpp writes it beside the
// demo as truth/ — against what the box made of that frame (render-session's layers), by what a
// crew sees: how much light the virtual objects' shadows take from the real set, where those
// shadows lie, and how bright each virtual object is.

#include <string>
#include <vector>

#include "base/result.h"
#include "image/image.h"

namespace previs {

struct TruthFrame {
    int index = 0;  // the scene camera's frame (0-based line of its index)
    bool still = false;
    ImageF mixed, real, mask;  // linear; mask one channel
};

// truth.toml and its frames' EXRs (bench/make_demo_session.cpp documents the folder).
Result<std::vector<TruthFrame>> loadTruth(const std::string& truthDir);

// What the box made of a frame: render-session's EXR (composite in the default layer; mixed,
// real and mask layers).
struct BoxFrame {
    ImageF composite, mixed, real, mask;
};
Result<BoxFrame> loadBoxFrame(const std::string& exrPath);

struct TruthScore {
    // Σ (L_or − L_om) of the box over the shadow pixels (the union of the box's and the truth's)
    // against the truth's: 1 when the virtual objects take as much light from the set as they
    // would on it.
    double shadowEnergyRatio = 0.0;
    // Intersection over union of the shadow regions: real pixels where the objects take more
    // than kShadowFraction of L_or (3×3 box-smoothed, so single noisy pixels do not count).
    double shadowIoU = 0.0;
    size_t shadowPixelsTruth = 0;
    size_t shadowPixelsBox = 0;
    // Per virtual object (each connected part of the truth's fully virtual pixels, left to
    // right): the box's mean composite luminance over it against the truth's mean L_om.
    std::vector<double> objectRatios;
    std::vector<size_t> objectPixels;
};

constexpr double kShadowFraction = 0.05;

// Truth images larger than the box's by a whole factor are box-filtered down first (the
// renderer's pixel filter is a box, so that is the truth at the box's size).
Result<TruthScore> scoreAgainstTruth(const BoxFrame& box, const TruthFrame& truth);

}  // namespace previs
