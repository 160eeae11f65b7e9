#pragma once

// Images a test builds in memory: every pixel the same, to start from or to compare against.

#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <vector>

#include "image/image.h"

namespace previs::testing {

// width × height pixels, each `pixel` (its size is the channel count).
inline ImageF uniformImage(uint32_t width, uint32_t height, const std::vector<float>& pixel) {
    ImageF img;
    img.width = width;
    img.height = height;
    img.channels = uint32_t(pixel.size());
    img.pixels.reserve(size_t(width) * height * pixel.size());
    for (size_t i = 0; i < size_t(width) * height; ++i)
        img.pixels.insert(img.pixels.end(), pixel.begin(), pixel.end());
    return img;
}

// Every channel of every pixel `value`.
inline ImageF filledImage(uint32_t width, uint32_t height, uint32_t channels, float value = 0.0f) {
    return uniformImage(width, height, std::vector<float>(channels, value));
}

}  // namespace previs::testing
