#pragma once

// Drawing a DisplayFrame for a screen: scaled to fit and letterboxed, with the one-line status
// overlay. Shared by the KMS output (into a dumb buffer) and the files output (at render size),
// so both show the same pixels.

#include <cstdint>
#include <string>

#include "display/frame_output.h"

namespace previs {

// Where a srcW×srcH image lands inside an outW×outH screen: the largest aspect-preserving
// rectangle, centred (black bars fill the rest).
struct LetterboxRect {
    uint32_t x = 0;
    uint32_t y = 0;
    uint32_t width = 0;
    uint32_t height = 0;
};
LetterboxRect letterboxRect(uint32_t srcW, uint32_t srcH, uint32_t outW, uint32_t outH);

// Height in rows of the status band at the bottom of an image `imageHeight` rows high (the band
// and its font scale with the height, readable from 180 to 2160 rows).
uint32_t statusBandHeight(uint32_t imageHeight);

// Draws `frame` into an XRGB8888 buffer (little-endian 0xXXRRGGBB per pixel, X = 0xff) of
// outW×outH pixels, `strideBytes` per row: scaled and letterboxed, status band overlaid across
// the bottom when frame.status is not empty. A frame whose rgb size does not match its
// width/height is a bug in the caller and draws black.
void composeFrame(const DisplayFrame& frame, uint32_t outW, uint32_t outH, uint32_t* xrgbOut,
                  uint32_t strideBytes);

// The status band drawn over a packed RGB image (3 bytes per pixel, stride 3·width), as
// composeFrame draws it: the files output writes frames this way.
void drawStatusRgb(uint8_t* rgb, uint32_t width, uint32_t height, const std::string& status);

}  // namespace previs
