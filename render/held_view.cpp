#include "render/held_view.h"

#include <algorithm>

namespace previs {

std::optional<HeldView> HeldView::create(uint32_t width, uint32_t height, uint32_t traceWidth,
                                         uint32_t traceHeight) {
    if (traceWidth == 0 || traceHeight == 0 || width % traceWidth != 0) return std::nullopt;
    const uint32_t f = width / traceWidth;
    if (f < 2 || height != traceHeight * f) return std::nullopt;
    return HeldView(width, height, f);
}

HeldView::HeldView(uint32_t width, uint32_t height, uint32_t factor)
    : width_(width),
      height_(height),
      factor_(factor),
      sum_(size_t(width) * height, glm::vec4(0.0f)),
      count_(size_t(width) * height, 0.0f) {}

glm::uvec2 HeldView::phase() const {
    // Diagonals in turn: every f frames cover each row and each column of the block once, so the
    // samples spread over the block long before all f² phases have come round.
    const uint32_t k = uint32_t(frames_ % (uint64_t(factor_) * factor_));
    const uint32_t y = k % factor_;
    const uint32_t x = (k / factor_ + y) % factor_;
    return {x, y};
}

void HeldView::add(const ImageF& traced, std::span<const float> samples) {
    const glm::uvec2 p = phase();
    for (uint32_t ty = 0; ty < traced.height; ++ty) {
        for (uint32_t tx = 0; tx < traced.width; ++tx) {
            const size_t t = size_t(ty) * traced.width + tx;
            const float n = samples[t];
            if (!(n > 0.0f)) continue;
            const size_t o = size_t(ty * factor_ + p.y) * width_ + tx * factor_ + p.x;
            const float* v = &traced.pixels[t * 4];
            sum_[o] += n * glm::vec4(v[0], v[1], v[2], v[3]);
            count_[o] += n;
        }
    }
    ++frames_;
}

ImageF HeldView::blend(const ImageF& estimate, double estimateSamples) const {
    ImageF out = estimate;
    for (size_t i = 0; i < size_t(width_) * height_; ++i) {
        if (count_[i] == 0.0f) continue;
        const double total = double(count_[i]) + estimateSamples;
        for (int c = 0; c < 4; ++c)
            out.pixels[i * 4 + c] =
                float((double(sum_[i][c]) + estimateSamples * estimate.pixels[i * 4 + c]) / total);
    }
    return out;
}

void HeldView::reset() {
    frames_ = 0;
    std::fill(sum_.begin(), sum_.end(), glm::vec4(0.0f));
    std::fill(count_.begin(), count_.end(), 0.0f);
}

}  // namespace previs
