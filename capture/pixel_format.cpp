#include "capture/pixel_format.h"

#include <fmt/format.h>
#include <linux/videodev2.h>

#include <array>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace previs {

namespace {

struct FormatInfo {
    uint32_t fourcc;
    // Bytes per pixel of the first plane, to derive the default stride.
    uint32_t bytesPerPixel;
};

// MJPEG and JPEG differ only in whether the driver strips the Huffman tables; libjpeg-turbo (via
// imdecode) handles both, since UVC cameras send the standard tables implicitly.
constexpr std::array kFormats = {
    FormatInfo{V4L2_PIX_FMT_YUYV, 2},   FormatInfo{V4L2_PIX_FMT_UYVY, 2},
    FormatInfo{V4L2_PIX_FMT_YVYU, 2},   FormatInfo{V4L2_PIX_FMT_NV12, 1},
    FormatInfo{V4L2_PIX_FMT_NV21, 1},   FormatInfo{V4L2_PIX_FMT_YUV420, 1},
    FormatInfo{V4L2_PIX_FMT_MJPEG, 0},  FormatInfo{V4L2_PIX_FMT_JPEG, 0},
    FormatInfo{V4L2_PIX_FMT_RGB24, 3},  FormatInfo{V4L2_PIX_FMT_BGR24, 3},
    FormatInfo{V4L2_PIX_FMT_GREY, 1},   FormatInfo{V4L2_PIX_FMT_XBGR32, 4},
    FormatInfo{V4L2_PIX_FMT_RGBX32, 4},
};

const FormatInfo* findFormat(uint32_t fourcc) {
    for (const FormatInfo& f : kFormats)
        if (f.fourcc == fourcc) return &f;
    return nullptr;
}

Status convert(uint32_t fourcc, std::span<const uint8_t> data, uint32_t width, uint32_t height,
               uint32_t stride, cv::Mat& dst) {
    const int w = int(width), h = int(height);
    // cv::Mat wants a non-const pointer; every use below only reads the source.
    auto* src = const_cast<uint8_t*>(data.data());

    auto need = [&](size_t bytes) -> Status {
        if (data.size() < bytes)
            return makeError("{} frame {}x{} is {} bytes, expected at least {} (truncated buffer)",
                             fourccToString(fourcc), width, height, data.size(), bytes);
        return {};
    };

    switch (fourcc) {
        case V4L2_PIX_FMT_YUYV:
        case V4L2_PIX_FMT_UYVY:
        case V4L2_PIX_FMT_YVYU: {
            if (Status s = need(size_t(stride) * (height - 1) + size_t(width) * 2); !s) return s;
            const int code = fourcc == V4L2_PIX_FMT_YUYV   ? cv::COLOR_YUV2RGB_YUYV
                             : fourcc == V4L2_PIX_FMT_UYVY ? cv::COLOR_YUV2RGB_UYVY
                                                           : cv::COLOR_YUV2RGB_YVYU;
            cv::cvtColor(cv::Mat(h, w, CV_8UC2, src, stride), dst, code);
            return {};
        }
        case V4L2_PIX_FMT_NV12:
        case V4L2_PIX_FMT_NV21:
        case V4L2_PIX_FMT_YUV420: {
            if (width % 2 || height % 2)
                return makeError("{} needs an even frame size, got {}x{}", fourccToString(fourcc),
                                 width, height);
            // Single-planar layout: the chroma plane(s) follow the luma plane at the same pitch
            // (I420's half-width planes at half the pitch), so one Mat of 3/2 the height spans all.
            if (fourcc == V4L2_PIX_FMT_YUV420 && stride != width)
                return makeError("YU12 with padded lines (stride {} for width {}) is not supported",
                                 stride, width);
            if (Status s = need(size_t(stride) * height * 3 / 2); !s) return s;
            const int code = fourcc == V4L2_PIX_FMT_NV12   ? cv::COLOR_YUV2RGB_NV12
                             : fourcc == V4L2_PIX_FMT_NV21 ? cv::COLOR_YUV2RGB_NV21
                                                           : cv::COLOR_YUV2RGB_I420;
            cv::cvtColor(cv::Mat(h * 3 / 2, w, CV_8UC1, src, stride), dst, code);
            return {};
        }
        case V4L2_PIX_FMT_MJPEG:
        case V4L2_PIX_FMT_JPEG: {
            if (data.size() < 4 || data[0] != 0xff || data[1] != 0xd8)
                return makeError("MJPEG frame of {} bytes has no JPEG start marker", data.size());
            // A frame cut short (a UVC camera losing USB packets, a buffer overwritten while
            // read) still decodes, grey or garbled below the cut, with only a libjpeg warning;
            // the end marker tells. Some cameras pad the payload with zeros after it.
            size_t end = data.size();
            while (end > 2 && data[end - 1] == 0) --end;
            if (data[end - 2] != 0xff || data[end - 1] != 0xd9)
                return makeError("MJPEG frame of {} bytes has no JPEG end marker (cut short)",
                                 data.size());
            cv::Mat bgr =
                cv::imdecode(cv::Mat(1, int(data.size()), CV_8UC1, src), cv::IMREAD_COLOR);
            if (bgr.empty())
                return makeError("MJPEG frame of {} bytes does not decode", data.size());
            if (bgr.cols != w || bgr.rows != h)
                return makeError("MJPEG frame decodes to {}x{}, the stream is {}x{}", bgr.cols,
                                 bgr.rows, width, height);
            cv::cvtColor(bgr, dst, cv::COLOR_BGR2RGB);
            return {};
        }
        case V4L2_PIX_FMT_RGB24:
        case V4L2_PIX_FMT_BGR24: {
            if (Status s = need(size_t(stride) * (height - 1) + size_t(width) * 3); !s) return s;
            cv::Mat in(h, w, CV_8UC3, src, stride);
            if (fourcc == V4L2_PIX_FMT_RGB24)
                in.copyTo(dst);
            else
                cv::cvtColor(in, dst, cv::COLOR_BGR2RGB);
            return {};
        }
        // libcamera's XRGB8888/XBGR8888 (ISP viewfinder outputs) under their V4L2 names: bytes
        // B,G,R,X and R,G,B,X; the padding byte is ignored.
        case V4L2_PIX_FMT_XBGR32:
        case V4L2_PIX_FMT_RGBX32: {
            if (Status s = need(size_t(stride) * (height - 1) + size_t(width) * 4); !s) return s;
            cv::cvtColor(cv::Mat(h, w, CV_8UC4, src, stride), dst,
                         fourcc == V4L2_PIX_FMT_XBGR32 ? cv::COLOR_BGRA2RGB : cv::COLOR_RGBA2RGB);
            return {};
        }
        case V4L2_PIX_FMT_GREY: {
            if (Status s = need(size_t(stride) * (height - 1) + width); !s) return s;
            cv::cvtColor(cv::Mat(h, w, CV_8UC1, src, stride), dst, cv::COLOR_GRAY2RGB);
            return {};
        }
        default:
            return makeError("pixel format {} is not supported (supported: {})",
                             fourccToString(fourcc), supportedFormatList());
    }
}

}  // namespace

std::string fourccToString(uint32_t fourcc) {
    std::string s(4, ' ');
    for (int i = 0; i < 4; ++i) {
        const char c = char((fourcc >> (8 * i)) & 0xff);
        s[i] = (c >= 0x20 && c < 0x7f) ? c : '?';
    }
    // V4L2 marks big-endian variants with the top bit; say so rather than print a '?'.
    const bool bigEndian = fourcc & (1u << 31);
    if (bigEndian) s[3] = char((fourcc >> 24) & 0x7f);
    while (!s.empty() && s.back() == ' ') s.pop_back();
    return bigEndian ? s + "-BE" : s;
}

uint32_t fourccFromString(const std::string& name) {
    if (name.empty() || name.size() > 4) return 0;
    uint32_t v = 0;
    for (size_t i = 0; i < 4; ++i)
        v |= uint32_t(uint8_t(i < name.size() ? name[i] : ' ')) << (8 * i);
    return v;
}

bool isSupportedFormat(uint32_t fourcc) { return findFormat(fourcc) != nullptr; }

std::string supportedFormatList() {
    std::string out;
    for (const FormatInfo& f : kFormats)
        out += (out.empty() ? "" : ", ") + fourccToString(f.fourcc);
    return out;
}

bool isJpegFourcc(uint32_t fourcc) {
    return fourcc == V4L2_PIX_FMT_MJPEG || fourcc == V4L2_PIX_FMT_JPEG;
}

uint32_t packedStride(uint32_t fourcc, uint32_t width) {
    const FormatInfo* f = findFormat(fourcc);
    return f ? f->bytesPerPixel * width : 0;
}

std::vector<uint8_t> packedFrameBytes(uint32_t fourcc, std::span<const uint8_t> data,
                                      uint32_t width, uint32_t height, uint32_t stride) {
    if (isJpegFourcc(fourcc)) return {data.begin(), data.end()};
    const uint32_t row = packedStride(fourcc, width);
    // Planar 4:2:0 formats: the chroma rows follow the luma rows at the same pitch.
    const bool planar =
        fourcc == V4L2_PIX_FMT_NV12 || fourcc == V4L2_PIX_FMT_NV21 || fourcc == V4L2_PIX_FMT_YUV420;
    const size_t rows = planar ? size_t(height) * 3 / 2 : height;
    if (row == 0 || stride < row || rows == 0 || data.size() < size_t(stride) * (rows - 1) + row)
        return {};
    if (fourcc == V4L2_PIX_FMT_YUV420 && stride != row) return {};
    std::vector<uint8_t> out(size_t(row) * rows);
    for (size_t y = 0; y < rows; ++y)
        std::copy_n(data.data() + y * stride, row, out.data() + y * row);
    return out;
}

Status convertToRgb(uint32_t fourcc, std::span<const uint8_t> data, uint32_t width, uint32_t height,
                    uint32_t stride, std::vector<uint8_t>& rgb) {
    const FormatInfo* info = findFormat(fourcc);
    if (!info)
        return makeError("pixel format {} is not supported (supported: {})", fourccToString(fourcc),
                         supportedFormatList());
    if (width == 0 || height == 0 || width > 16384 || height > 16384)
        return makeError("frame size {}x{} is out of range", width, height);
    if (stride == 0) stride = width * info->bytesPerPixel;
    if (info->bytesPerPixel && stride < width * info->bytesPerPixel)
        return makeError("{} line pitch {} is shorter than a {}-pixel line", fourccToString(fourcc),
                         stride, width);

    rgb.resize(size_t(width) * height * 3);
    // Converting straight into the frame's storage: cvtColor keeps a destination that already
    // has the right size and type, so there is no second copy.
    cv::Mat dst(int(height), int(width), CV_8UC3, rgb.data());
    // OpenCV reports failures by throwing; they stop at this function (STYLE.md errors).
    try {
        Status s = convert(fourcc, data, width, height, stride, dst);
        if (!s) return s;
    } catch (const cv::Exception& e) {
        return makeError("{} frame {}x{}: conversion failed: {}", fourccToString(fourcc), width,
                         height, e.what());
    }
    if (dst.data != rgb.data()) {
        // Only if OpenCV reallocated (it does not for a destination of the right size and
        // type): copy so the caller's buffer holds the pixels either way.
        cv::Mat target(int(height), int(width), CV_8UC3, rgb.data());
        dst.copyTo(target);
    }
    return {};
}

}  // namespace previs
