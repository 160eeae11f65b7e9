// Capture without a device: pixel conversion against known colours and OpenCV's reference, the
// latest-value slot, the capture thread's recovery (with a scripted reader), and the messages
// for a missing or wrong device node.
#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <chrono>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>
#include <thread>

#include "base/latest_value_slot.h"
#include "base/unique_fd.h"
#include "capture/camera_source.h"
#include "capture/pixel_format.h"
#include "capture/recorded_source.h"
#include "capture/v4l2_device.h"
#include "io/session.h"

namespace previs {
namespace {

std::vector<uint8_t> randomBytes(size_t n, uint32_t seed) {
    std::mt19937 rng(seed);
    std::vector<uint8_t> v(n);
    for (uint8_t& b : v) b = uint8_t(rng());
    return v;
}

int maxAbsDiff(const std::vector<uint8_t>& a, const cv::Mat& b) {
    EXPECT_EQ(a.size(), b.total() * b.elemSize());
    int worst = 0;
    for (size_t i = 0; i < a.size() && i < b.total() * b.elemSize(); ++i)
        worst = std::max(worst, std::abs(int(a[i]) - int(b.data[i])));
    return worst;
}

// How OpenCV reads a format: `rows` lines of `width` elements of `type`, converted by `code`.
struct OpenCvLayout {
    uint32_t rows = 0;
    int type = 0;
    int code = 0;
};

// convertToRgb of `buf` (lines `stride` bytes apart) gives OpenCV's RGB of the same lines packed
// tight, to the code.
void expectSameAsOpenCv(uint32_t fourcc, const std::vector<uint8_t>& buf, uint32_t w, uint32_t h,
                        uint32_t stride, OpenCvLayout layout) {
    cv::Mat packed(int(layout.rows), int(w), layout.type);
    for (uint32_t y = 0; y < layout.rows; ++y)
        std::memcpy(packed.ptr(int(y)), buf.data() + size_t(y) * stride, w * packed.elemSize());
    cv::Mat ref;
    cv::cvtColor(packed, ref, layout.code);
    std::vector<uint8_t> rgb;
    ASSERT_TRUE(convertToRgb(fourcc, buf, w, h, stride, rgb));
    EXPECT_EQ(maxAbsDiff(rgb, ref), 0);
}

// BT.601 limited range: Y 16..235, chroma 16..240 around 128.
TEST(PixelFormat, YuyvKnownColours) {
    struct Case {
        uint8_t y, u, v, r, g, b;
    };
    // White, black, and the 100% primaries' BT.601 codes (ITU-R BT.601 colour bars).
    const Case cases[] = {{235, 128, 128, 255, 255, 255},
                          {16, 128, 128, 0, 0, 0},
                          {81, 90, 240, 255, 0, 0},
                          {145, 54, 34, 0, 255, 0},
                          {41, 240, 110, 0, 0, 255}};
    for (const Case& c : cases) {
        const std::vector<uint8_t> yuyv = {c.y, c.u, c.y, c.v};
        std::vector<uint8_t> rgb;
        ASSERT_TRUE(convertToRgb(V4L2_PIX_FMT_YUYV, yuyv, 2, 1, 0, rgb));
        ASSERT_EQ(rgb.size(), 6u);
        for (int px = 0; px < 2; ++px) {
            EXPECT_NEAR(rgb[px * 3 + 0], c.r, 3) << int(c.y) << "," << int(c.u) << "," << int(c.v);
            EXPECT_NEAR(rgb[px * 3 + 1], c.g, 3);
            EXPECT_NEAR(rgb[px * 3 + 2], c.b, 3);
        }
    }
}

TEST(PixelFormat, YuyvWithPaddedStrideMatchesOpenCv) {
    const uint32_t w = 64, h = 16, stride = w * 2 + 32;
    std::vector<uint8_t> buf = randomBytes(size_t(stride) * h, 1);
    expectSameAsOpenCv(V4L2_PIX_FMT_YUYV, buf, w, h, stride, {h, CV_8UC2, cv::COLOR_YUV2RGB_YUYV});
}

TEST(PixelFormat, Nv12WithPaddedStrideMatchesOpenCv) {
    const uint32_t w = 48, h = 32, stride = 64;
    std::vector<uint8_t> buf = randomBytes(size_t(stride) * h * 3 / 2, 2);
    expectSameAsOpenCv(V4L2_PIX_FMT_NV12, buf, w, h, stride,
                       {h * 3 / 2, CV_8UC1, cv::COLOR_YUV2RGB_NV12});
}

// A take keeps raw frames as the camera sent them, without line padding, and replays them to the
// very pixels the live capture converted (YUYV and NV12 with padded lines, as drivers deliver).
TEST(PixelFormat, ATakeKeepsRawFramesAndReplaysThePixelsCaptureConverted) {
    const std::string dir =
        (std::filesystem::temp_directory_path() / fmt::format("previs_raw_take_{}", ::getpid()))
            .string();
    std::filesystem::remove_all(dir);
    auto writer = SessionWriter::create(dir);
    ASSERT_TRUE(writer) << writer.message();
    struct Case {
        uint32_t fourcc, stride;
        size_t bytes;
    };
    const uint32_t w = 48, h = 32;
    const Case cases[] = {{V4L2_PIX_FMT_YUYV, w * 2 + 32, size_t(w * 2 + 32) * h},
                          {V4L2_PIX_FMT_NV12, 64, size_t(64) * h * 3 / 2}};
    std::vector<std::vector<uint8_t>> live;
    for (size_t i = 0; i < std::size(cases); ++i) {
        const Case& c = cases[i];
        const std::vector<uint8_t> buffer = randomBytes(c.bytes, 10 + uint32_t(i));
        std::vector<uint8_t> rgb;
        ASSERT_TRUE(convertToRgb(c.fourcc, buffer, w, h, c.stride, rgb));
        live.push_back(rgb);
        const std::vector<uint8_t> packed = packedFrameBytes(c.fourcc, buffer, w, h, c.stride);
        ASSERT_EQ(packed.size(), size_t(packedStride(c.fourcc, w)) *
                                     (c.fourcc == V4L2_PIX_FMT_NV12 ? h * 3 / 2 : h));
        std::string ext = fourccToString(c.fourcc);
        for (char& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
        ASSERT_TRUE(writer->writeFrame("scene", i, 100 + i, packed, ext, w, h));
    }
    ASSERT_TRUE(writer->flush());
    auto entries = loadCameraIndex(dir + "/cameras/scene");
    ASSERT_TRUE(entries) << entries.message();
    ASSERT_EQ(entries->size(), std::size(cases));
    for (size_t i = 0; i < std::size(cases); ++i) {
        Result<Frame> replayed = readRecordedFrame((*entries)[i]);
        ASSERT_TRUE(replayed) << replayed.message();
        EXPECT_EQ(replayed->rgb, live[i]) << fourccToString(cases[i].fourcc);
        EXPECT_EQ(replayed->capturedFourcc, cases[i].fourcc);
        ASSERT_TRUE(replayed->captured) << "a replayed take can be recorded again, as it came";
    }
    // A short raw file is a bad frame with its name, never a read past the end.
    std::ofstream((*entries)[0].file, std::ios::trunc) << "short";
    Result<Frame> cut = readRecordedFrame((*entries)[0]);
    ASSERT_FALSE(cut);
    EXPECT_NE(cut.message().find((*entries)[0].file), std::string::npos) << cut.message();
    std::filesystem::remove_all(dir);
}

// Issue 52: a 38 KB JPEG declaring 30000 x 30000 cost 2.7 GB and 108 s before its size was
// compared with the index. The header is read first: refused at once, naming the file and both
// sizes (a PNG likewise; an index line is at most 16384 a side, loadCameraIndex).
TEST(RecordedFrame, ADeclaredSizeUnlikeTheIndexIsRefusedBeforeDecoding) {
    const std::filesystem::path dir =
        std::filesystem::temp_directory_path() / fmt::format("previs_huge_jpeg_{}", ::getpid());
    std::filesystem::create_directories(dir);
    std::vector<uchar> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", cv::Mat(36, 64, CV_8UC3, cv::Scalar(1, 2, 3)), jpeg));
    // The baseline frame header (SOF0: FF C0, length, precision, height, width), its size raised.
    size_t sof = 2;
    while (sof + 9 < jpeg.size() && !(jpeg[sof] == 0xff && jpeg[sof + 1] == 0xc0))
        sof += 2 + (size_t(jpeg[sof + 2]) << 8 | jpeg[sof + 3]);
    ASSERT_LT(sof + 9, jpeg.size());
    for (size_t at : {sof + 5, sof + 7}) {
        jpeg[at] = uchar(30000 >> 8);
        jpeg[at + 1] = uchar(30000 & 0xff);
    }
    RecordedFrameEntry entry;
    entry.file = (dir / "000000000000.jpg").string();
    entry.width = 64;
    entry.height = 36;
    std::ofstream(entry.file, std::ios::binary)
        .write(reinterpret_cast<const char*>(jpeg.data()), std::streamsize(jpeg.size()));
    const auto start = std::chrono::steady_clock::now();
    Result<Frame> frame = readRecordedFrame(entry);
    ASSERT_FALSE(frame);
    EXPECT_NE(frame.message().find("declares 30000x30000"), std::string::npos) << frame.message();
    EXPECT_NE(frame.message().find(entry.file), std::string::npos) << frame.message();
    std::printf("refused in %.3f s\n",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    std::filesystem::remove_all(dir);
}

TEST(PixelFormat, Nv12KnownColour) {
    // 2x2 pure red: four Y samples, one interleaved Cb/Cr pair.
    const std::vector<uint8_t> nv12 = {81, 81, 81, 81, 90, 240};
    std::vector<uint8_t> rgb;
    ASSERT_TRUE(convertToRgb(V4L2_PIX_FMT_NV12, nv12, 2, 2, 0, rgb));
    for (int px = 0; px < 4; ++px) {
        EXPECT_NEAR(rgb[px * 3 + 0], 255, 3);
        EXPECT_NEAR(rgb[px * 3 + 1], 0, 3);
        EXPECT_NEAR(rgb[px * 3 + 2], 0, 3);
    }
}

TEST(PixelFormat, MjpegDecodesToRgb) {
    // A smooth image so JPEG's error stays small and the channel order is unambiguous.
    const int w = 64, h = 48;
    cv::Mat rgbRef(h, w, CV_8UC3);
    for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
            rgbRef.at<cv::Vec3b>(y, x) = {uint8_t(200), uint8_t(x * 2), uint8_t(y * 3)};
    cv::Mat bgr;
    cv::cvtColor(rgbRef, bgr, cv::COLOR_RGB2BGR);
    std::vector<uint8_t> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95}));
    std::vector<uint8_t> rgb;
    ASSERT_TRUE(convertToRgb(V4L2_PIX_FMT_MJPEG, jpeg, w, h, 0, rgb));
    EXPECT_LE(maxAbsDiff(rgb, rgbRef), 12);
    EXPECT_NEAR(rgb[0], 200, 6);  // red channel first

    // Zero padding after the end marker (as some UVC cameras send) is fine...
    std::vector<uint8_t> padded = jpeg;
    padded.resize(jpeg.size() + 4096, 0);
    EXPECT_TRUE(convertToRgb(V4L2_PIX_FMT_MJPEG, padded, w, h, 0, rgb));
    // ...a frame cut short is not, although libjpeg would decode it (grey below the cut).
    std::vector<uint8_t> cut(jpeg.begin(), jpeg.begin() + std::ptrdiff_t(jpeg.size() * 2 / 3));
    Status s = convertToRgb(V4L2_PIX_FMT_MJPEG, cut, w, h, 0, rgb);
    ASSERT_FALSE(s);
    EXPECT_NE(s.message().find("end marker"), std::string::npos) << s.message();
}

TEST(PixelFormat, BadBuffersAreErrorsNotCrashes) {
    std::vector<uint8_t> rgb;
    const std::vector<uint8_t> shortYuyv(100);
    Status s = convertToRgb(V4L2_PIX_FMT_YUYV, shortYuyv, 640, 480, 0, rgb);
    ASSERT_FALSE(s);
    EXPECT_NE(s.message().find("truncated"), std::string::npos) << s.message();

    const std::vector<uint8_t> garbage = randomBytes(5000, 3);
    s = convertToRgb(V4L2_PIX_FMT_MJPEG, garbage, 64, 48, 0, rgb);
    ASSERT_FALSE(s);
    EXPECT_NE(s.message().find("MJPEG"), std::string::npos) << s.message();

    // A JPEG of the wrong size: the stream's size is what consumers rely on.
    std::vector<uint8_t> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", cv::Mat(8, 8, CV_8UC3, cv::Scalar(1, 2, 3)), jpeg));
    s = convertToRgb(V4L2_PIX_FMT_MJPEG, jpeg, 64, 48, 0, rgb);
    ASSERT_FALSE(s);
    EXPECT_NE(s.message().find("8x8"), std::string::npos) << s.message();

    s = convertToRgb(V4L2_PIX_FMT_SBGGR8, garbage, 16, 16, 0, rgb);
    ASSERT_FALSE(s);
    EXPECT_NE(s.message().find("BA81"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("YUYV"), std::string::npos) << s.message();
}

TEST(PixelFormat, FourccNames) {
    EXPECT_EQ(fourccToString(V4L2_PIX_FMT_YUYV), "YUYV");
    EXPECT_EQ(fourccToString(V4L2_PIX_FMT_MJPEG), "MJPG");
    EXPECT_EQ(fourccToString(V4L2_PIX_FMT_Y16_BE), "Y16-BE");
    EXPECT_EQ(fourccFromString("NV12"), uint32_t(V4L2_PIX_FMT_NV12));
    EXPECT_EQ(fourccFromString("GREY"), uint32_t(V4L2_PIX_FMT_GREY));
    EXPECT_EQ(fourccFromString("TOOLONG"), 0u);
}

TEST(UniqueFd, ClosesOnceAndMoves) {
    int fds[2];
    ASSERT_EQ(::pipe(fds), 0);
    ::close(fds[1]);
    UniqueFD a(fds[0]);
    UniqueFD b(std::move(a));
    EXPECT_FALSE(a.isValid());
    EXPECT_EQ(b.get(), fds[0]);
    b.reset();
    EXPECT_EQ(::fcntl(fds[0], F_GETFD), -1);  // closed
}

TEST(FrameSlot, SlowConsumerDropsAndCounts) {
    FrameSlot slot;
    EXPECT_EQ(slot.take(), nullptr);
    for (uint64_t i = 0; i < 10; ++i) {
        auto f = std::make_shared<Frame>();
        f->sequence = i;
        slot.publish(std::move(f));
    }
    EXPECT_EQ(slot.published(), 10u);
    EXPECT_EQ(slot.dropped(), 9u);
    auto got = slot.take();
    ASSERT_NE(got, nullptr);
    EXPECT_EQ(got->sequence, 9u);
    EXPECT_EQ(slot.take(), nullptr);
    ASSERT_NE(slot.latest(), nullptr);  // latest() survives take()
    EXPECT_EQ(slot.waitTakeFor(std::chrono::milliseconds(5)), nullptr);
    slot.publish(std::make_shared<Frame>());
    EXPECT_EQ(slot.dropped(), 9u);  // the previous one was taken: no drop
}

TEST(V4L2Device, MissingDeviceSaysSo) {
    V4L2Config config;
    config.device = "/dev/video-previs-missing";
    auto dev = V4L2Device::create(config);
    ASSERT_FALSE(dev);
    EXPECT_NE(dev.message().find("/dev/video-previs-missing"), std::string::npos);
    EXPECT_NE(dev.message().find("no such device"), std::string::npos) << dev.message();
}

TEST(V4L2Device, NonVideoNodeSaysSo) {
    V4L2Config config;
    config.device = "/dev/null";
    auto dev = V4L2Device::create(config);
    ASSERT_FALSE(dev);
    EXPECT_NE(dev.message().find("not a V4L2 device"), std::string::npos) << dev.message();
}

// A reader whose behaviour is scripted per call, standing in for a device that comes and goes.
struct Script {
    std::atomic<int> opensToFail{0};        // factory failures before the next successful open
    std::atomic<int> framesBeforeLoss{-1};  // -1: never lost
    std::atomic<int> opens{0};
    std::atomic<uint64_t> timestampNs{1000};
};

class ScriptedReader : public FrameReader {
public:
    explicit ScriptedReader(Script& s) : s_(s) {}
    Status start() override { return {}; }
    Result<bool> read(int, Frame& frame) override {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        if (s_.framesBeforeLoss.load() == 0) {
            s_.framesBeforeLoss = -1;
            return makeError("scripted device vanished");
        }
        if (s_.framesBeforeLoss.load() > 0) --s_.framesBeforeLoss;
        frame.width = 2;
        frame.height = 1;
        frame.rgb.assign(6, 7);
        frame.timestampNs = s_.timestampNs += 1000;
        frame.deviceSequence = seq_++;
        return true;
    }

private:
    Script& s_;
    uint32_t seq_ = 0;
};

FrameReaderFactory scriptedFactory(Script& s) {
    return [&s]() -> Result<std::unique_ptr<FrameReader>> {
        if (s.opensToFail.load() > 0) {
            --s.opensToFail;
            return makeError("scripted camera: no such device");
        }
        ++s.opens;
        return std::unique_ptr<FrameReader>(new ScriptedReader(s));
    };
}

template <typename Pred>
bool waitFor(Pred pred, int ms = 5000) {
    for (int i = 0; i < ms / 5; ++i) {
        if (pred()) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return pred();
}

TEST(CaptureThread, WaitsForAbsentDeviceThenRecoversFromLoss) {
    Script script;
    script.opensToFail = 3;
    script.framesBeforeLoss = 20;
    CaptureOptions options;
    options.name = "scripted";
    options.retryIntervalMs = 10;
    CaptureThread capture(scriptedFactory(script), options);
    ASSERT_TRUE(capture.start());

    // Absent at start: the thread keeps trying, then streams; then the device is lost once and
    // comes back on the next open, without anyone restarting the thread.
    ASSERT_TRUE(waitFor([&] { return capture.stats().reconnects >= 1; }));
    ASSERT_TRUE(waitFor([&] { return capture.stats().delivered >= 40; }));
    EXPECT_EQ(script.opens.load(), 2);
    EXPECT_EQ(capture.state(), CaptureState::Streaming);

    uint64_t lastSeq = 0, lastTs = 0;
    for (int i = 0; i < 5; ++i) {
        auto f = capture.frames().waitTakeFor(std::chrono::milliseconds(500));
        ASSERT_NE(f, nullptr);
        if (i > 0) {
            EXPECT_GT(f->sequence, lastSeq);
            EXPECT_GT(f->timestampNs, lastTs);
        }
        lastSeq = f->sequence;
        lastTs = f->timestampNs;
    }
    capture.stop();
    EXPECT_EQ(capture.state(), CaptureState::Stopped);
}

// A reader that throws (a library bug, an allocation failure) does not end the capture thread:
// it counts as losing the device, logged in one line, and the device is reopened.
class ThrowingReader : public FrameReader {
public:
    explicit ThrowingReader(std::atomic<int>& throwsLeft) : throwsLeft_(throwsLeft) {}
    Status start() override { return {}; }
    Result<bool> read(int, Frame& frame) override {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
        if (++reads_ == 5 && throwsLeft_.fetch_sub(1) > 0)
            throw std::runtime_error("scripted exception inside the driver wrapper");
        frame.width = 2;
        frame.height = 1;
        frame.rgb.assign(6, 7);
        frame.timestampNs = reads_ * 1000;
        frame.deviceSequence = uint32_t(reads_);
        return true;
    }

private:
    std::atomic<int>& throwsLeft_;
    int reads_ = 0;
};

TEST(CaptureThread, ExceptionInAReaderIsALossNotACrash) {
    std::atomic<int> throwsLeft{2};
    std::atomic<int> opens{0};
    CaptureOptions options;
    options.name = "throwing";
    options.retryIntervalMs = 5;
    CaptureThread capture(
        [&]() -> Result<std::unique_ptr<FrameReader>> {
            ++opens;
            return std::unique_ptr<FrameReader>(new ThrowingReader(throwsLeft));
        },
        options);
    ASSERT_TRUE(capture.start());
    ASSERT_TRUE(waitFor([&] { return throwsLeft.load() <= 0 && capture.stats().delivered >= 20; }));
    EXPECT_EQ(capture.state(), CaptureState::Streaming);
    EXPECT_GE(opens.load(), 3);  // reopened after each of the two exceptions
    capture.stop();
    EXPECT_EQ(capture.state(), CaptureState::Stopped);
}

// A camera that stays open but delivers nothing is treated as lost and reopened.
class SilentReader : public FrameReader {
public:
    Status start() override { return {}; }
    Result<bool> read(int timeoutMs, Frame&) override {
        std::this_thread::sleep_for(std::chrono::milliseconds(timeoutMs));
        return false;
    }
};

TEST(CaptureThread, SilentDeviceIsReopened) {
    std::atomic<int> opens{0};
    CaptureOptions options;
    options.name = "silent";
    options.readTimeoutMs = 5;
    options.retryIntervalMs = 5;
    options.stallTimeoutMs = 30;
    CaptureThread capture(
        [&]() -> Result<std::unique_ptr<FrameReader>> {
            ++opens;
            return std::unique_ptr<FrameReader>(new SilentReader);
        },
        options);
    ASSERT_TRUE(capture.start());
    EXPECT_TRUE(waitFor([&] { return opens.load() >= 3; }));
    capture.stop();
    EXPECT_EQ(capture.stats().delivered, 0u);
}

TEST(CaptureThread, SlowConsumerNeverStallsCapture) {
    Script script;
    CaptureOptions options;
    options.name = "fast";
    CaptureThread capture(scriptedFactory(script), options);
    ASSERT_TRUE(capture.start());
    uint64_t taken = 0;
    for (int i = 0; i < 10; ++i) {
        // A consumer 20x slower than the source.
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        if (capture.frames().take()) ++taken;
    }
    capture.stop();
    const CaptureStats s = capture.stats();
    EXPECT_GE(s.delivered, 50u);  // capture kept its own pace
    EXPECT_GT(s.dropped, 0u);
    // Every delivered frame was either taken, dropped, or is still waiting in the slot.
    const uint64_t pending = capture.frames().take() ? 1 : 0;
    EXPECT_EQ(s.delivered, taken + s.dropped + pending);
}

// A session camera folder as the recorder leaves it after a crash: N complete frames and a cut-off
// last index line (docs/session-format.md).
std::string writeRecordedCamera(const std::string& name, int frames, uint64_t periodNs) {
    const auto dir = std::filesystem::temp_directory_path() /
                     ("previs_capture_test_" + name + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    std::ofstream index(dir / "index.csv");
    index << "# previs-session camera index v1: sequence,timestampNs,file,width,height\n";
    for (int i = 0; i < frames; ++i) {
        cv::Mat bgr(12, 16, CV_8UC3, cv::Scalar(10 * i, 100, 200));  // B, G, R
        const std::string file = fmt::format("{:012}.png", i * 2);
        EXPECT_TRUE(cv::imwrite((dir / file).string(), bgr));
        index << i * 2 << "," << 5'000'000'000ull + i * periodNs << "," << file << ",16,12\n";
    }
    index << frames * 2 << ",99999";  // the crash: no newline, never counted
    return dir.string();
}

TEST(RecordedSource, ReplaysAsFastAsPossibleAndFinishes) {
    const std::string dir = writeRecordedCamera("fast", 5, 1'000'000'000ull);
    CaptureOptions options;
    options.name = "recorded";
    auto source = makeRecordedSource(dir, ReplayTiming::AsFastAsPossible, options);
    ASSERT_TRUE(source->start());
    std::vector<std::shared_ptr<const Frame>> got;
    // A consumer that keeps up (the slot keeps only the newest, so poll fast).
    ASSERT_TRUE(waitFor([&] {
        if (auto f = source->frames().take()) got.push_back(f);
        return source->stats().state == CaptureState::Finished;
    }));
    source->stop();
    EXPECT_EQ(source->stats().delivered, 5u);
    ASSERT_FALSE(got.empty());
    const Frame& last = *source->frames().latest();
    EXPECT_EQ(last.timestampNs, 5'000'000'000ull + 4'000'000'000ull);  // recorded, not now
    EXPECT_EQ(last.deviceSequence, 8u);
    ASSERT_EQ(last.rgb.size(), 16u * 12 * 3);
    EXPECT_EQ(last.rgb[0], 200);  // R
    EXPECT_EQ(last.rgb[1], 100);  // G
    EXPECT_EQ(last.rgb[2], 40);   // B
    std::filesystem::remove_all(dir);
}

TEST(RecordedSource, ReplaysAtRecordedTiming) {
    const uint64_t periodNs = 40'000'000;  // 25 fps
    const std::string dir = writeRecordedCamera("timed", 6, periodNs);
    auto reader = RecordedReader::create(dir, ReplayTiming::Recorded);
    ASSERT_TRUE(reader) << reader.message();
    ASSERT_TRUE((*reader)->start());
    const auto t0 = std::chrono::steady_clock::now();
    int frames = 0;
    while (!(*reader)->finished()) {
        Frame f;
        Result<bool> got = (*reader)->read(100, f);
        ASSERT_TRUE(got);
        frames += *got ? 1 : 0;
    }
    const double elapsedMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(frames, 6);
    EXPECT_GE(elapsedMs, 5 * 40 - 2);  // the last frame is due 200 ms after the first
    // Generous: only "not replayed as fast as possible, not stuck"; a loaded CI machine is slow.
    EXPECT_LT(elapsedMs, 5 * 40 + 2000);
    std::filesystem::remove_all(dir);
}

// Timestamps 190 years apart (a broken clock, a hand-edited index): the replay pauses at most
// kMaxReplayGap per gap instead of waiting for centuries, and no duration overflows.
TEST(RecordedSource, AbsurdGapsAreCappedNotWaitedFor) {
    const uint64_t periodNs = 6'000'000'000'000'000'000ull;
    const std::string dir = writeRecordedCamera("absurd", 3, periodNs);
    auto reader = RecordedReader::create(dir, ReplayTiming::Recorded);
    ASSERT_TRUE(reader) << reader.message();
    ASSERT_TRUE((*reader)->start());
    const auto t0 = std::chrono::steady_clock::now();
    const auto limit = t0 + 2 * kMaxReplayGap + std::chrono::seconds(20);
    int frames = 0;
    while (!(*reader)->finished() && std::chrono::steady_clock::now() < limit) {
        Frame f;
        Result<bool> got = (*reader)->read(100, f);
        ASSERT_TRUE(got);
        if (*got) {
            ++frames;
            EXPECT_EQ(f.timestampNs, 5'000'000'000ull + uint64_t(frames - 1) * periodNs);
        }
    }
    const auto elapsed = std::chrono::steady_clock::now() - t0;
    EXPECT_EQ(frames, 3);
    EXPECT_GE(elapsed, 2 * kMaxReplayGap - std::chrono::milliseconds(5));
    std::filesystem::remove_all(dir);
}

TEST(RecordedSource, BadIndexAndFramesAreReported) {
    auto missing = RecordedReader::create("/nonexistent/session/cameras/scene",
                                          ReplayTiming::AsFastAsPossible);
    ASSERT_FALSE(missing);
    EXPECT_NE(missing.message().find("/nonexistent/session/cameras/scene/index.csv"),
              std::string::npos);

    const std::string dir = writeRecordedCamera("bad", 3, 1000);
    {
        std::ofstream(dir + "/000000000002.png") << "not a png";  // frame 1 corrupt
    }
    auto reader = RecordedReader::create(dir, ReplayTiming::AsFastAsPossible);
    ASSERT_TRUE(reader);
    ASSERT_TRUE((*reader)->start());
    int frames = 0;
    while (!(*reader)->finished()) {
        Frame f;
        Result<bool> got = (*reader)->read(10, f);
        ASSERT_TRUE(got);
        frames += *got ? 1 : 0;
    }
    EXPECT_EQ(frames, 2);
    EXPECT_EQ((*reader)->badFrames(), 1u);

    {
        std::ofstream index(dir + "/index.csv");
        index << "# previs-session camera index v99: a future layout\n0,1,x.png,16,12\n";
    }
    auto future = loadCameraIndex(dir);
    ASSERT_FALSE(future);
    EXPECT_NE(future.message().find("version 99 is newer"), std::string::npos) << future.message();

    std::ofstream(dir + "/index.csv") << "0,1,a.png,16,12\nx,2,b.png,16,12\n";
    auto corrupt = loadCameraIndex(dir);
    ASSERT_FALSE(corrupt);
    EXPECT_NE(corrupt.message().find("index.csv:2: malformed"), std::string::npos)
        << corrupt.message();
    std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace previs
