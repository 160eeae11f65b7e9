#include "web/stream_encoder.h"

#include <gtest/gtest.h>

#include <chrono>
#include <opencv2/imgcodecs.hpp>
#include <thread>

#include "tests/web/synthetic_frames.h"

namespace previs {
namespace {

using namespace std::chrono_literals;

TEST(StreamEncoder, DownscalesToTheStreamWidthKeepingTheAspect) {
    const WebFrame frame = test::syntheticFrame(1280, 720, 3);
    int w = 0, h = 0;
    Result<std::string> jpeg = encodeJpeg(frame, 640, 80, &w, &h);
    ASSERT_TRUE(jpeg.ok()) << jpeg.message();
    EXPECT_EQ(w, 640);
    EXPECT_EQ(h, 360);
    const std::vector<uint8_t> bytes(jpeg->begin(), jpeg->end());
    const cv::Mat decoded = cv::imdecode(bytes, cv::IMREAD_COLOR);
    ASSERT_EQ(decoded.cols, 640);
    ASSERT_EQ(decoded.rows, 360);
    // Colour order survives (RGB in, BGR for OpenCV): the background's blue is 255 − 3·5 = 240,
    // its red 21; a pixel far from the bar, within JPEG's error.
    const cv::Vec3b bgr = decoded.at<cv::Vec3b>(300, 600);
    EXPECT_NEAR(bgr[0], 240, 12);
    EXPECT_NEAR(bgr[2], 21, 12);
}

TEST(StreamEncoder, NeverUpscalesAndRejectsEmptyFrames) {
    int w = 0, h = 0;
    ASSERT_TRUE(encodeJpeg(test::syntheticFrame(320, 200, 0), 640, 80, &w, &h).ok());
    EXPECT_EQ(w, 320);
    EXPECT_EQ(h, 200);
    EXPECT_FALSE(encodeJpeg(WebFrame{}, 640, 80).ok());
}

TEST(StreamEncoder, RejectsBadSettings) {
    EXPECT_FALSE(StreamEncoder::create({.fps = 0.0}).ok());
    EXPECT_FALSE(StreamEncoder::create({.width = 2}).ok());
    EXPECT_FALSE(StreamEncoder::create({.jpegQuality = 101}).ok());
}

TEST(StreamEncoder, EncodesNothingWithoutViewers) {
    auto encoder = StreamEncoder::create({.fps = 50.0});
    ASSERT_TRUE(encoder.ok()) << encoder.message();
    for (uint64_t i = 0; i < 10; ++i) {
        (*encoder)->submit(test::syntheticFrame(64, 36, i));
        std::this_thread::sleep_for(10ms);
    }
    EXPECT_EQ((*encoder)->stats().submitted, 10u);
    EXPECT_EQ((*encoder)->stats().encoded, 0u);
}

// Input at ~100 fps, stream at 10 fps: the encoder takes only the newest frame each period.
TEST(StreamEncoder, EncodesAtTheStreamRateWhateverTheInputRate) {
    auto encoder = StreamEncoder::create({.fps = 10.0, .width = 64});
    ASSERT_TRUE(encoder.ok()) << encoder.message();
    (*encoder)->addViewer();
    const auto start = std::chrono::steady_clock::now();
    uint64_t i = 0;
    while (std::chrono::steady_clock::now() - start < 1500ms) {
        (*encoder)->submit(test::syntheticFrame(128, 72, i++));
        std::this_thread::sleep_for(10ms);
    }
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const EncoderStats s = (*encoder)->stats();
    EXPECT_LE(double(s.encoded), seconds * 10.0 + 2.0);
    // A loaded machine may delay the encoder, never make it encode more.
    EXPECT_GE(double(s.encoded), seconds * 10.0 * 0.5);
    EXPECT_LT(s.encoded, s.submitted);
    std::shared_ptr<const EncodedFrame> latest = (*encoder)->waitNewer(0, 0ms);
    ASSERT_TRUE(latest);
    EXPECT_EQ(latest->sequence, s.encoded);
    (*encoder)->removeViewer();
}

TEST(StreamEncoder, WaitNewerReturnsOnStop) {
    auto encoder = StreamEncoder::create({});
    ASSERT_TRUE(encoder.ok());
    std::thread stopper([&] {
        std::this_thread::sleep_for(50ms);
        (*encoder)->stop();
    });
    const auto start = std::chrono::steady_clock::now();
    EXPECT_FALSE((*encoder)->waitNewer(0, 10s));
    EXPECT_LT(std::chrono::steady_clock::now() - start, 5s);
    stopper.join();
}

}  // namespace
}  // namespace previs
