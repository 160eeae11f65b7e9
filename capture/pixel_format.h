#pragma once

// Camera pixel formats (V4L2 fourccs) and their conversion to the RGB8 frames the pipeline uses.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

// "YUYV" for V4L2_PIX_FMT_YUYV; non-printable bytes as '?' so logs stay readable.
std::string fourccToString(uint32_t fourcc);
// Inverse of fourccToString for 1–4 character names ("MJPG", "NV12"); 0 when malformed.
uint32_t fourccFromString(const std::string& name);

// Whether convertToRgb handles this fourcc.
bool isSupportedFormat(uint32_t fourcc);
// MJPEG or JPEG: frames that are complete JPEG files (the recorder keeps their bytes).
bool isJpegFourcc(uint32_t fourcc);

// A raw frame's bytes with the line padding removed (stride = packedStride), as a take stores it;
// a JPEG's bytes unchanged. Empty when `data` is too short for the format and size.
std::vector<uint8_t> packedFrameBytes(uint32_t fourcc, std::span<const uint8_t> data,
                                      uint32_t width, uint32_t height, uint32_t stride);
// The stride of a frame without line padding (0 for JPEG).
uint32_t packedStride(uint32_t fourcc, uint32_t width);
// The supported fourccs, for messages ("YUYV, UYVY, NV12, ...").
std::string supportedFormatList();

// Converts one frame of `fourcc` to tightly packed RGB8 in `rgb` (resized to width*height*3).
// `data` holds the bytes the driver filled (bytesused); `stride` is the line pitch in bytes of
// the first plane (v4l2_pix_format::bytesperline; 0 = packed). YUV is BT.601 limited range,
// what UVC webcams and vivid send by default. Fails on a short or undecodable buffer (a camera
// delivering garbage) without touching anything but `rgb`.
Status convertToRgb(uint32_t fourcc, std::span<const uint8_t> data, uint32_t width, uint32_t height,
                    uint32_t stride, std::vector<uint8_t>& rgb);

}  // namespace previs
