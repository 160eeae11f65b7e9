#pragma once

// `previs render-session` (DESIGN.md §3, issue 36): a take at final quality. Every frame is a
// refinement of its own — the take's plate, the smoothed camera track (take/take_track.h), the
// lighting snapshot in effect at its time — drawn with a random sequence derived from the
// settings' seed and the frame's index alone, so a frame's pixels do not depend on which range
// or machine rendered it. Written as DIR/frame_NNNNNN.exr (composite RGBA and named layers) and
// .png, each to a temporary name and renamed: a frame that exists is complete, and a frame
// already there is not rendered again.

#include <array>
#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <utility>
#include <vector>

#include "base/result.h"

namespace previs {

struct TakeRenderOptions {
    std::string takeDir;
    std::string outDir;
    std::string frames;       // RANGE (parseFrameRange); "" = every frame
    uint32_t spp = 0;         // samples per pixel; 0 = [refine] max_samples
    double targetNoise = -1;  // stop a frame at this relative RMSE; < 0 = [refine] target_noise
    // Layers besides the composite: mixed, real, mask, differential, albedo, normal, depth.
    std::vector<std::string> aovs = {"mixed", "real", "mask", "differential"};
    uint32_t width = 0, height = 0;  // 0 = the config's [render] size
    uint32_t plan = 0;               // > 0: print this many ranges and render nothing
    bool rawPoses = false;           // the tracker's poses instead of the smoothed track
    bool quiet = false;
};

// RANGE over a take of `count` frames: "A:B" (A inclusive, B exclusive, either may be omitted,
// as a Python slice), or a post tool's inclusive list "1-100", "1-100x2", "1,5,7-9". Frames at
// or past `count` are an error naming them. Sorted, without repeats.
Result<std::vector<size_t>> parseFrameRange(const std::string& text, size_t count);

// `frames` cut into `parts` runs of near-equal length, each as a RANGE parseFrameRange reads
// back: "A:B" when contiguous, else a post tool's list; parts beyond the frames' count are
// empty slices ("N:N"), so array task i always has line i.
std::vector<std::string> planFrameRanges(const std::vector<size_t>& frames, size_t parts);

// The seed of frame `index` of a take rendered with `seed`: a hash of both (splitmix64).
uint32_t takeFrameSeed(uint32_t seed, uint64_t index);

// What each frame's EXR tells a compositor of its camera (OpenEXR's standard attributes, in
// Imath's row-major layout for row vectors, p' = p · M), from a pose in the tracker's axes (OpenCV:
// x right, y down, z forward). worldToCamera: into RenderMan's camera space (x right, y up,
// z forward, left-handed), as ImfStandardAttributes.h defines it.
std::array<float, 16> exrWorldToCamera(const cv::Matx44d& worldFromCamera);
// worldToNDC: the calibration's pinhole (`k` at `size`; its distortion is not in a matrix) onto
// the image, (0, 0) the top-left corner of the frame and (1, 1) its bottom-right (pixel centres
// at x + 0.5), y down; x and y divided by w, z discarded.
std::array<float, 16> exrWorldToNDC(const cv::Matx44d& worldFromCamera, const cv::Matx33d& k,
                                    cv::Size size);
// framesPerSecond as a rational: the standard rate `fps` is (timecode/frame_rate.h
// snapFrameRate, the one rule for a camera's rate), else to a thousandth; {0, 0} when `fps` is
// not positive.
std::pair<int, int> exrFramesPerSecond(double fps);

// Exit code: 0 every frame rendered or already there; 1 a frame could not be (each named);
// 2 the take or the options are unusable; 128 + the signal when SIGTERM or SIGINT stopped it
// (no partial frame is left).
int runTakeRender(const TakeRenderOptions& options);

}  // namespace previs
