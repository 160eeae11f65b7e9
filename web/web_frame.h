#pragma once

// The monitor's input: one shown frame, borrowed without a copy. The display thread already
// shares its frames as immutable shared_ptr snapshots (DESIGN.md §6), so the monitor keeps the
// snapshot alive through `owner` and reads the pixels in place on its own encoder thread.

#include <cstddef>
#include <cstdint>
#include <memory>

namespace previs {

struct WebFrame {
    uint32_t width = 0;
    uint32_t height = 0;
    size_t strideBytes = 0;             // bytes from one row to the next; 0 = packed (3·width)
    const uint8_t* rgb = nullptr;       // 8-bit sRGB, 3 bytes per pixel, R first
    std::shared_ptr<const void> owner;  // keeps `rgb` alive while the encoder reads it
    uint64_t index = 0;                 // the producer's frame number (shown in stats only)
};

// Wraps a shared frame with `width`, `height`, a packed `rgb` vector and `index` (the display's
// DisplayFrame) without copying its pixels.
template <typename Frame>
WebFrame webFrameOf(std::shared_ptr<const Frame> frame) {
    WebFrame f;
    f.width = frame->width;
    f.height = frame->height;
    f.strideBytes = size_t(frame->width) * 3;
    f.rgb = frame->rgb.data();
    f.index = frame->index;
    f.owner = std::move(frame);
    return f;
}

}  // namespace previs
