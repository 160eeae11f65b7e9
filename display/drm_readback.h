#pragma once

// What a KMS display shows, read from any root process while another one (previsd) is DRM
// master: the first active CRTC's framebuffer through GETFB2 (which hands GEM handles to root)
// and a dumb-buffer map. For tests: vmtest's VM runs everything as root.

#include <cstdint>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

// `card` is "card0" or a path such as "/dev/dri/card0". Returns width×height XRGB8888 pixels
// (0xXXRRGGBB, rows packed), width and height through the pointers.
Result<std::vector<uint32_t>> readScanout(const std::string& card, uint32_t* width,
                                          uint32_t* height);

}  // namespace previs
