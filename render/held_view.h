#pragma once

// A held camera's preview at the output's own resolution. A preview traced at a fraction of the
// output size upsamples its traced pixels (render/upsample.h), and no number of frames averages
// away what the upsampling blurs at the virtual objects' outlines, which the plate (its guide)
// does not show. Yet each traced pixel's samples are jittered over its whole footprint of output
// pixels, in a phase schedule that visits each of its k × k output pixels once in k² samples
// (RenderSettings::previewPhases; shared/sampler.h's heldPhaseJitter): the path tracer also adds
// each sample to the output pixel it landed in
// (PV_BINDING_HELD_SAMPLES), and while the camera holds still that buffer keeps summing them per
// output pixel (the renderer clears it only when a held view starts), so a held preview converges
// to the full-resolution image that refinement converges to. The frame's own (upsampled, denoised)
// estimate counts as the samples behind it per output pixel beside them (estimateSamples): it
// carries the picture while they are few, and they take over as they grow (the estimate's error is
// mostly the upsampling's bias at outlines and contact shadows, which a few more samples do not
// tell apart from noise: path tracing's heavy tails make a few samples agree too often, e.g. all
// miss a soft shadow, for a per-pixel confidence test).
//
// While the camera moves the samples are not dropped: they follow it (render/held_reprojection.h)
// and fade by kFollowKeep a frame, so the output's resolution keeps a short history during a pan
// too, and a hold starts from it. A moved pixel's history is kept only where the new camera's
// first sample there meets the same surface: distance, normal and virtual mask agree
// (shared/held_reprojection_params.h's heldHistoryAgrees, run by the path tracer as it adds).

#include <algorithm>
#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <span>

#include "gpu/shaders/shared/composite.h"
#include "image/image.h"
#include "render/denoiser.h"

namespace previs {

class HeldView {
public:
    // An output of width × height traced smaller in both directions (any fraction; at a
    // fraction that is not a whole one, the samples landing on an output pixel whose centre
    // another traced pixel holds are not kept); none at full resolution.
    static std::optional<HeldView> create(uint32_t width, uint32_t height, uint32_t traceWidth,
                                          uint32_t traceHeight);

    // Whether it was made for this traced size.
    bool traces(uint32_t traceWidth, uint32_t traceHeight) const {
        return traceWidth == traceWidth_ && traceHeight == traceHeight_;
    }
    // A frame's samples, traced from `camera`, joined the kept ones.
    void frameAdded(const DenoiseCamera& camera) {
        if (!following_) ++frames_;
        camera_ = camera;
    }
    // `estimate` (RGBA at the output size: RGB the mean of Eq. 1's plate-free part, A the mask
    // M) averaged with the kept samples (per output pixel two vec4, as PV_BINDING_HELD_SAMPLES
    // holds them), the estimate counted as `estimateSamples` samples (shared/composite.h's
    // heldBlend, which the display pass runs too); `testOutline`: its weight after the test of
    // its outline against the samples' mask (shared/composite.h's heldEstimateWeight).
    static ImageF blend(std::span<const glm::vec4> samples, const ImageF& estimate,
                        float estimateSamples, bool testOutline);
    // Whether the blend may test the estimate's outline: the camera holds, and long enough
    // (kOutlineTestFrames) that the samples traced in their own output pixels outnumber those
    // carried from a move; where those disagree with the estimate's mask, the estimate is wrong
    // (while the camera moves, a moved sample that disagrees may be the stale one).
    bool testsOutline() const { return !following_ && frames_ >= kOutlineTestFrames; }
    // About 1/(1 − kFollowKeep): the frames' worth of samples a move leaves.
    static constexpr uint64_t kOutlineTestFrames = 4;
    // What the estimate counts as: PV_HELD_ESTIMATE_SAMPLES_PER_SPP for each of the `spp`
    // samples a frame traces per traced pixel, which feed its history. Measured
    // (`previs bench --only shot`, BENCHMARKS.md): 16 at 1 spp, as the dial ships the demo; at
    // 4 spp 16, 32 and 64 left 0.136, 0.121 and 0.117 after 64 held frames. Counting the
    // denoiser's history frames and the traced pixels' share of the output too (the samples
    // behind the estimate) weighed it 36 at half resolution and 1 spp, where the held view's
    // unclamped samples then no longer halved their error in 32 frames
    // (Preview.AtHalfResolutionAHeldCameraGoesBelowTheUpsamplingFloor): the estimate's bias at
    // the outlines, which no number of its samples removes, caps its worth.
    static float estimateSamples(uint32_t spp) {
        return PV_HELD_ESTIMATE_SAMPLES_PER_SPP * float(std::max<uint32_t>(spp, 1));
    }
    // Frames kept since the camera last moved.
    uint64_t frames() const { return frames_; }
    // The camera the kept samples are aligned with; none: there are none (to be cleared).
    const std::optional<DenoiseCamera>& camera() const { return camera_; }
    // The camera holds: its frames count (frames()).
    void hold() { following_ = false; }
    // The camera moves: the samples follow it (render/held_reprojection.h), its frames do not
    // count.
    void follow() {
        following_ = true;
        frames_ = 0;
    }
    // The weight a sample keeps each time the camera moves: the history of a moving camera is
    // about 1/(1 − kFollowKeep) frames long, short enough that what the view changes (a
    // reflection, a shadow's edge seen from aside) does not trail behind.
    static constexpr float kFollowKeep = 0.75f;
    void reset() {
        frames_ = 0;
        camera_.reset();
        following_ = false;
    }

private:
    HeldView(uint32_t traceWidth, uint32_t traceHeight)
        : traceWidth_(traceWidth), traceHeight_(traceHeight) {}

    uint32_t traceWidth_;
    uint32_t traceHeight_;
    uint64_t frames_ = 0;
    std::optional<DenoiseCamera> camera_;
    bool following_ = false;
};

}  // namespace previs
