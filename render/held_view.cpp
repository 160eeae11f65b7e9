#include "render/held_view.h"

#include <algorithm>

namespace previs {

std::optional<HeldView> HeldView::create(uint32_t width, uint32_t height, uint32_t traceWidth,
                                         uint32_t traceHeight) {
    if (traceWidth == 0 || traceHeight == 0 || traceWidth >= width || traceHeight >= height)
        return std::nullopt;
    return HeldView(traceWidth, traceHeight);
}

ImageF HeldView::blend(std::span<const glm::vec4> samples, const ImageF& estimate,
                       float estimateSamples, bool testOutline) {
    ImageF out = estimate;
    for (size_t i = 0; i < samples.size() / 2; ++i) {
        float* o = &out.pixels[i * 4];
        const glm::vec4 v =
            shader::heldBlend(samples[2 * i], samples[2 * i + 1].x,
                              glm::vec4(o[0], o[1], o[2], o[3]), estimateSamples, testOutline);
        for (int c = 0; c < 4; ++c) o[c] = v[c];
    }
    return out;
}

}  // namespace previs
