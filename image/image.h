#pragma once

// Image files in and out: OpenEXR (linear float), Radiance .hdr, PNG/JPEG (8-bit, sRGB-encoded).
// Every error names the file, what is wrong and what to do.

#include <cstdint>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

// Interleaved float pixels, row-major, row 0 at the top.
struct ImageF {
    uint32_t width = 0;
    uint32_t height = 0;
    uint32_t channels = 0;  // 1 (grey / "Y"), 3 (RGB) or 4 (RGBA)
    std::vector<float> pixels;
    // True for PNG/JPEG: the values are the 8-bit codes / 255, still sRGB-encoded (the caller
    // decides how to linearise or inverse tone map them). False: linear HDR (EXR, .hdr).
    bool ldrSrgb = false;

    float at(uint32_t x, uint32_t y, uint32_t c) const {
        return pixels[(size_t(y) * width + x) * channels + c];
    }
};

// Reads .exr (float; channels R,G,B[,A] or Y), .hdr (Radiance RGBE), .png/.jpg/.jpeg.
Result<ImageF> readImage(const std::string& path);

// Writes float32 (never half: linear HDR must survive a round trip bit-exactly), lossless ZIP
// compression. 1 channel is written as "Y", 3 as RGB, 4 as RGBA.
Status writeExr(const std::string& path, const ImageF& image);

// Writes an 8-bit RGB PNG; rgb8 holds width*height*3 bytes, row 0 at the top.
Status writePng(const std::string& path, uint32_t width, uint32_t height,
                const std::vector<uint8_t>& rgb8);

}  // namespace previs
