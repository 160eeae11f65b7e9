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
    : factor_(factor),
      sum_(size_t(width) * height, glm::vec4(0.0f)),
      count_(size_t(width) * height, 0.0f) {}

void HeldView::add(std::span<const glm::vec4> samples) {
    for (size_t i = 0; i < count_.size(); ++i) {
        const float n = samples[2 * i + 1].x;
        if (n == 0.0f) continue;
        sum_[i] += samples[2 * i];
        count_[i] += n;
    }
    ++frames_;
}

ImageF HeldView::blend(const ImageF& estimate) const {
    ImageF out = estimate;
    for (size_t i = 0; i < count_.size(); ++i) {
        const double n = count_[i];
        if (n == 0.0) continue;
        float* o = &out.pixels[i * 4];
        for (int c = 0; c < 4; ++c)
            o[c] = float((double(sum_[i][c]) + kEstimateSamples * o[c]) / (n + kEstimateSamples));
    }
    return out;
}

void HeldView::reset() {
    frames_ = 0;
    std::fill(sum_.begin(), sum_.end(), glm::vec4(0.0f));
    std::fill(count_.begin(), count_.end(), 0.0f);
}

}  // namespace previs
