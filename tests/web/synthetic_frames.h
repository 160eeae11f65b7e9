#pragma once

// Frames for the web tests and the test server: a picture that changes with its index (a bar
// sweeping across a background whose hue turns), optionally with noise so that JPEGs are large.

#include <cstdint>
#include <memory>
#include <vector>

#include "web/web_frame.h"

namespace previs::test {

inline WebFrame syntheticFrame(uint32_t width, uint32_t height, uint64_t index,
                               bool noisy = false) {
    auto pixels = std::make_shared<std::vector<uint8_t>>(size_t(width) * height * 3);
    const uint8_t r = uint8_t(index * 7), g = uint8_t(128 + index * 3),
                  b = uint8_t(255 - index * 5);
    const uint32_t bar = uint32_t(index * 16 % width);
    uint32_t noise = uint32_t(index) * 2654435761u + 1;
    for (uint32_t y = 0; y < height; ++y) {
        uint8_t* row = pixels->data() + size_t(y) * width * 3;
        for (uint32_t x = 0; x < width; ++x) {
            const bool onBar = x >= bar && x < bar + width / 10;
            uint8_t px[3] = {onBar ? uint8_t(255) : r, onBar ? uint8_t(255) : g,
                             onBar ? uint8_t(255) : b};
            if (noisy) {
                noise = noise * 1664525u + 1013904223u;
                for (uint8_t& c : px) c = uint8_t(c ^ (noise >> 24));
            }
            row[x * 3 + 0] = px[0];
            row[x * 3 + 1] = px[1];
            row[x * 3 + 2] = px[2];
        }
    }
    WebFrame f;
    f.width = width;
    f.height = height;
    f.strideBytes = size_t(width) * 3;
    f.rgb = pixels->data();
    f.index = index;
    f.owner = std::move(pixels);
    return f;
}

}  // namespace previs::test
