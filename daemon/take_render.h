#pragma once

// `previs render-session` (DESIGN.md §3, issue 36): a take at final quality. Every frame is a
// refinement of its own — the take's plate, the smoothed camera track (daemon/take_track.h), the
// lighting snapshot in effect at its time — drawn with a random sequence derived from the
// settings' seed and the frame's index alone, so a frame's pixels do not depend on which range
// or machine rendered it. Written as DIR/frame_NNNNNN.exr (composite RGBA and named layers) and
// .png, each to a temporary name and renamed: a frame that exists is complete, and a frame
// already there is not rendered again.

#include <cstddef>
#include <cstdint>
#include <string>
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

// Exit code: 0 every frame rendered or already there; 1 a frame could not be (each named);
// 2 the take or the options are unusable; 128 + the signal when SIGTERM or SIGINT stopped it
// (no partial frame is left).
int runTakeRender(const TakeRenderOptions& options);

}  // namespace previs
