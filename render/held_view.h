#pragma once

// A held camera's preview at the output's own resolution. A preview traced at 1/f of the output
// size upsamples its traced pixels (render/upsample.h), and no number of frames averages away
// what the upsampling blurs at the virtual objects' outlines, which the plate (its guide) does
// not show. While the camera holds still, each frame instead samples one output pixel of every
// traced pixel's f × f block (Renderer::setPixelFootprint), the f² phases in turn; this keeps
// those samples per output pixel, so a held preview converges to the full-resolution image that
// refinement converges to, and blends them with the frame's own (upsampled, denoised) estimate
// while they are few.

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <span>
#include <vector>

#include "image/image.h"

namespace previs {

class HeldView {
public:
    // An output of width × height traced at width/f × height/f; none unless f ≥ 2 divides both.
    static std::optional<HeldView> create(uint32_t width, uint32_t height, uint32_t traceWidth,
                                          uint32_t traceHeight);

    uint32_t factor() const { return factor_; }
    // The output pixel of each block the next frame samples, (0, 0) to (f − 1, f − 1), in an
    // order that spreads each f² frames' samples evenly over the block.
    glm::uvec2 phase() const;
    // Keeps a frame traced at phase(): `traced` RGBA per traced pixel (RGB the mean of Eq. 1's
    // plate-free part, A the mask M) over `samples` per traced pixel; the next phase follows.
    void add(const ImageF& traced, std::span<const float> samples);
    // `estimate` (the same RGBA, at the output size) where no sample is kept, else the mean of
    // the kept samples and the estimate weighted as `estimateSamples` samples.
    ImageF blend(const ImageF& estimate, double estimateSamples) const;
    // Frames kept since the camera last moved.
    uint64_t frames() const { return frames_; }
    void reset();

private:
    HeldView(uint32_t width, uint32_t height, uint32_t factor);
    uint32_t width_;
    uint32_t height_;
    uint32_t factor_;
    uint64_t frames_ = 0;
    std::vector<glm::vec4> sum_;  // per output pixel, Σ samples × traced mean
    std::vector<float> count_;    // per output pixel, samples kept
};

}  // namespace previs
