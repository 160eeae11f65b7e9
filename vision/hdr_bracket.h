#pragma once

// HDR light capture (DESIGN.md §4, "Light capture is HDR"): a camera that cycles through a set
// of exposures gives brackets of 8-bit frames; each complete bracket is checked and merged into
// linear radiance in the scene's units, with the pixels still clipped at the shortest exposure
// flagged (their radiance is only a lower bound there).
//
// Why not cv::MergeDebevec: its response is a 256-entry table per channel, but the camera's
// configured radiometry (vision/inverse_tone_map.h) inverts a curve applied to luminance with the
// colour ratios kept, which no per-channel table represents; MergeDebevec also averages its
// weight over the channels, so a channel clipped in one frame still pulls the result down, and
// it averages logarithms, which biases noisy pixels low. The merge here is Debevec & Malik's
// weighted mean (SIGGRAPH 1997, Eq. 6) taken in linear radiance through the exact inverse, with
// a frame's pixel given no weight when any of its channels clips.

#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "vision/inverse_tone_map.h"

namespace previs {

struct BracketSettings {
    // The exposures of one bracket, in stops relative to the radiometry (0 = as calibrated,
    // −4 = a sixteenth of the light), in the order the camera takes them.
    std::vector<float> stops;
    // A frame's exposure is identified, not assumed: between consecutive frames of a bracket,
    // the median brightness ratio over pixels well exposed in both must be 2^Δstops within this
    // many stops (a control that landed a frame late is off by a whole step).
    float ratioToleranceStops = 0.5f;
    // Fewer pixels well exposed in both frames than this, and the pair cannot be checked by its
    // pictures (counted: BracketCounts::unchecked); its labels are then taken as they are.
    int minCheckPixels = 64;

    bool operator==(const BracketSettings&) const = default;
};

// Validates settings.stops: 2 to 8 finite exposures within ±20 stops, each at least 1 stop from
// the others (so a frame's label says which it is). The message names `where` (a config key).
Status checkBracketStops(const std::vector<float>& stops, const std::string& where);

// An 8-bit code at or above this on any channel counts as clipped: a sensor's highlight and a
// JPEG's ringing around it never quite reach 255.
constexpr int kClippedCode = 250;

struct MergedBracket {
    cv::Mat radiance;              // CV_32FC3 linear RGB, the frames' size
    cv::Mat clipped;               // CV_8U, 255 where even the shortest exposure clipped
    double clippedFraction = 0.0;  // of the pixels
    uint64_t firstSequence = 0;
    uint64_t lastSequence = 0;
    uint64_t timestampNs = 0;  // the last frame's
};

// Brackets seen so far, by what became of them (status and takes report these).
struct BracketCounts {
    uint64_t merged = 0;
    uint64_t droppedUnlabelled = 0;     // a frame came without its exposure
    uint64_t droppedWrongExposure = 0;  // a label not in the bracket, or out of its order
    uint64_t droppedMissing = 0;        // a frame lost (a sequence gap) or a bracket cut short
    uint64_t droppedMismatch = 0;       // the pictures disagree with the labels (late controls)
    uint64_t unchecked = 0;             // frame pairs merged on their labels and order alone
                                        // (too few pixels well exposed in both for a ratio)
    uint64_t dropped() const {
        return droppedUnlabelled + droppedWrongExposure + droppedMissing + droppedMismatch;
    }
};

// Linear radiance of each frame (through `radiometry` at the frame's exposure) merged per pixel:
// E = Σ wᵢ·Eᵢ / Σ wᵢ, Eᵢ = inverse(zᵢ) / 2^sᵢ, wᵢ = 2^sᵢ·hat(max channel of zᵢ), hat(z) =
// min(z + 1, 255 − z) and 0 from kClippedCode up (the longer exposure's better signal weighs
// more). A pixel every frame clipped takes the shortest exposure's value and is flagged; one
// black in every frame takes the longest's. Frames: CV_8UC3 in R, G, B order, one size.
Result<MergedBracket> mergeBracket(const std::vector<cv::Mat>& rgb8,
                                   const std::vector<float>& stops,
                                   const InverseToneMapSettings& radiometry);

// The exposure difference between two frames read from their pictures: the median of
// log2(luminance b / luminance a) over pixels whose channels all lie within [24, 230] in both
// (away from noise and the curve's shoulder); nullopt with fewer than minPixels such pixels.
std::optional<float> measuredStopsBetween(const cv::Mat& rgb8A, const cv::Mat& rgb8B,
                                          const InverseToneMapSettings& radiometry, int minPixels);

// Whether the pictures order the two frames against their labels: of the pixels whose brightest
// channel differs by more than a few codes between them, more go the wrong way (brighter in the
// frame labelled darker) than the right way, and at least minPixels do. A pair too far apart to
// share a well-exposed pixel (measuredStopsBetween gives nothing) is still ordered by every
// pixel one frame exposes and the other does not; a rotated cycle (a frame at −8 labelled 0,
// then 0 labelled −4) reverses nearly all of them, noise and motion only a few.
bool exposureOrderContradicted(const cv::Mat& rgb8A, const cv::Mat& rgb8B, float expectedStops,
                               int minPixels);

// Collects a bracketing camera's frames in order and merges each complete bracket; anything
// else — a frame without its exposure, of an exposure not next in the cycle, a sequence gap, a
// picture that disagrees with its label — drops the bracket in progress, counted, never merged.
class BracketAssembler {
public:
    static Result<BracketAssembler> create(BracketSettings settings,
                                           InverseToneMapSettings radiometry);

    // The next frame (CV_8UC3, RGB). A merged bracket when this frame completed one, else
    // nullopt (in progress or dropped: see counts() and lastDrop()).
    std::optional<MergedBracket> add(const cv::Mat& rgb8, uint64_t sequence, uint64_t timestampNs,
                                     std::optional<float> exposureStops);

    // Whether a frame with this exposure would start a new bracket (the cycle's first exposure).
    bool startsBracket(std::optional<float> exposureStops) const;
    bool inProgress() const { return !frames_.empty(); }
    const BracketCounts& counts() const { return counts_; }
    const std::string& lastDrop() const { return lastDrop_; }
    const BracketSettings& settings() const { return settings_; }

private:
    BracketAssembler(BracketSettings settings, InverseToneMapSettings radiometry)
        : settings_(std::move(settings)), radiometry_(radiometry) {}
    void drop(uint64_t& counter, std::string why);
    std::optional<MergedBracket> complete();

    BracketSettings settings_;
    InverseToneMapSettings radiometry_;
    std::vector<cv::Mat> frames_;  // the bracket in progress
    uint64_t firstSequence_ = 0;
    uint64_t lastSequence_ = 0;
    uint64_t lastTimestampNs_ = 0;
    BracketCounts counts_;
    std::string lastDrop_;
};

}  // namespace previs
