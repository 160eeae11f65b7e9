#pragma once

// Test frames with known content, shared by the host and VM display tests.

#include <cstdint>

#include "display/frame_output.h"

namespace previs::test {

// 4×4 blocks of distinct solid colours: a block's centre keeps its colour exactly through any
// reasonable scaling, so the scaled picture can be checked without a reference resampler.
inline uint32_t blockColour(int bx, int by, int salt = 0) {
    const uint32_t r = uint32_t(40 + 60 * bx + salt * 7) & 0xff;
    const uint32_t g = uint32_t(30 + 70 * by) & 0xff;
    const uint32_t b = uint32_t(200 - 40 * ((bx + by + salt) % 4)) & 0xff;
    return (r << 16) | (g << 8) | b;
}

inline DisplayFrame blockFrame(uint32_t width, uint32_t height, int salt = 0) {
    DisplayFrame f;
    f.width = width;
    f.height = height;
    f.rgb.resize(size_t(width) * height * 3);
    for (uint32_t y = 0; y < height; ++y)
        for (uint32_t x = 0; x < width; ++x) {
            const uint32_t c = blockColour(int(x * 4 / width), int(y * 4 / height), salt);
            uint8_t* p = &f.rgb[(size_t(y) * width + x) * 3];
            p[0] = uint8_t(c >> 16);
            p[1] = uint8_t(c >> 8);
            p[2] = uint8_t(c);
        }
    return f;
}

}  // namespace previs::test
