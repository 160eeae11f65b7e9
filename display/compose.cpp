#include "display/compose.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace previs {

namespace {

// Band colour: dark enough for white text on any picture, not pure black so the band is told
// apart from letterbox bars.
constexpr int kBandLevel = 24;

// Draws the band into a 3- or 4-channel 8-bit image; the same pixels in either (RGB channels are
// set alike), so the files output and the screen agree.
void drawStatus(cv::Mat& image, const std::string& status) {
    if (status.empty() || image.rows <= 0 || image.cols <= 0) return;
    const int band = static_cast<int>(statusBandHeight(static_cast<uint32_t>(image.rows)));
    const cv::Rect bandRect(0, image.rows - band, image.cols, band);
    image(bandRect).setTo(cv::Scalar(kBandLevel, kBandLevel, kBandLevel, 255));

    const int font = cv::FONT_HERSHEY_SIMPLEX;
    const int margin = std::max(2, band / 5);
    int baseline = 0;
    // Text height: cap height ~60% of the band; shrunk further if the line is too wide.
    const cv::Size unit = cv::getTextSize(status, font, 1.0, 1, &baseline);
    double scale = 0.6 * band / std::max(1, unit.height);
    const int maxWidth = image.cols - 2 * margin;
    if (unit.width * scale > maxWidth) scale = static_cast<double>(maxWidth) / unit.width;
    const int thickness = std::max(1, static_cast<int>(std::lround(band / 20.0)));
    const cv::Size text = cv::getTextSize(status, font, scale, thickness, &baseline);
    const int y = image.rows - band + (band + text.height) / 2;
    cv::putText(image, status, cv::Point(margin, y), font, scale, cv::Scalar(255, 255, 255, 255),
                thickness, cv::LINE_AA);
}

}  // namespace

LetterboxRect letterboxRect(uint32_t srcW, uint32_t srcH, uint32_t outW, uint32_t outH) {
    if (srcW == 0 || srcH == 0 || outW == 0 || outH == 0) return {};
    // Compare srcW/srcH with outW/outH in integers: the limiting side fills the screen exactly.
    LetterboxRect r;
    if (uint64_t(srcW) * outH >= uint64_t(outW) * srcH) {
        r.width = outW;
        r.height = static_cast<uint32_t>((uint64_t(srcH) * outW + srcW / 2) / srcW);
    } else {
        r.height = outH;
        r.width = static_cast<uint32_t>((uint64_t(srcW) * outH + srcH / 2) / srcH);
    }
    r.width = std::clamp<uint32_t>(r.width, 1, outW);
    r.height = std::clamp<uint32_t>(r.height, 1, outH);
    r.x = (outW - r.width) / 2;
    r.y = (outH - r.height) / 2;
    return r;
}

uint32_t statusBandHeight(uint32_t imageHeight) {
    // 1/24 of the height (90 rows at 2160), at least 14 rows so the font stays legible at 180.
    return std::min(imageHeight, std::max<uint32_t>(14, imageHeight / 24));
}

void composeFrame(const DisplayFrame& frame, uint32_t outW, uint32_t outH, uint32_t* xrgbOut,
                  uint32_t strideBytes) {
    cv::Mat out(static_cast<int>(outH), static_cast<int>(outW), CV_8UC4, xrgbOut, strideBytes);
    const bool valid = frame.width > 0 && frame.height > 0 &&
                       frame.rgb.size() == size_t(frame.width) * frame.height * 3;
    const LetterboxRect r =
        valid ? letterboxRect(frame.width, frame.height, outW, outH) : LetterboxRect{};
    if (r.width == 0) {
        out.setTo(cv::Scalar(0, 0, 0, 255));
        drawStatus(out, frame.status);
        return;
    }
    // Only the bars are cleared: the picture rectangle is overwritten below.
    const cv::Scalar black(0, 0, 0, 255);
    out(cv::Rect(0, 0, int(outW), int(r.y))).setTo(black);
    out(cv::Rect(0, int(r.y + r.height), int(outW), int(outH - r.y - r.height))).setTo(black);
    out(cv::Rect(0, int(r.y), int(r.x), int(r.height))).setTo(black);
    out(cv::Rect(int(r.x + r.width), int(r.y), int(outW - r.x - r.width), int(r.height)))
        .setTo(black);

    const cv::Mat src(static_cast<int>(frame.height), static_cast<int>(frame.width), CV_8UC3,
                      const_cast<uint8_t*>(frame.rgb.data()));
    cv::Mat dst = out(cv::Rect(int(r.x), int(r.y), int(r.width), int(r.height)));
    // RGB → BGRA lays bytes out B,G,R,A: a little-endian 0xAARRGGBB word, i.e. XRGB8888.
    if (r.width == frame.width && r.height == frame.height) {
        cv::cvtColor(src, dst, cv::COLOR_RGB2BGRA);
    } else {
        // INTER_AREA averages when shrinking (no aliasing); bilinear when enlarging.
        const int interp = r.width < frame.width ? cv::INTER_AREA : cv::INTER_LINEAR;
        cv::Mat scaled;
        cv::resize(src, scaled, cv::Size(int(r.width), int(r.height)), 0, 0, interp);
        cv::cvtColor(scaled, dst, cv::COLOR_RGB2BGRA);
    }
    drawStatus(out, frame.status);
}

void drawStatusRgb(uint8_t* rgb, uint32_t width, uint32_t height, const std::string& status) {
    cv::Mat image(static_cast<int>(height), static_cast<int>(width), CV_8UC3, rgb);
    drawStatus(image, status);
}

}  // namespace previs
