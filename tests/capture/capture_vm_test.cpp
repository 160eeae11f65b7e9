// Capture against real kernel drivers, run inside the test VM (../shared/vmtest): vivid's two
// cameras, and v4l2loopback as an MJPEG camera (vivid has no compressed formats). Outside the
// VM the binary exits 77, which CTest reports as skipped.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <thread>

#include "base/unique_fd.h"
#include "capture/camera_source.h"
#include "capture/pixel_format.h"
#include "capture/v4l2_device.h"
#include "tests/support/vm_test_main.h"
#include "vision/hdr_bracket.h"

namespace previs {
namespace {

// Generous: the VM runs code 3–20x slower than the host, and vivid's frame thread with it.
constexpr int kFrameTimeoutMs = 4000;

// vivid's "100% Colorbar" pattern (control value 1): eight equal vertical bars.
const cv::Vec3b kColorbar[8] = {{255, 255, 255}, {255, 255, 0}, {0, 255, 255}, {0, 255, 0},
                                {255, 0, 255},   {255, 0, 0},   {0, 0, 255},   {0, 0, 0}};

// Checks the bar colours along a row below vivid's text overlay area.
void expectColorbar(const Frame& f, int tolerance) {
    ASSERT_EQ(f.rgb.size(), size_t(f.width) * f.height * 3);
    const uint32_t y = f.height * 3 / 4;
    for (int bar = 0; bar < 8; ++bar) {
        const uint32_t x = uint32_t((bar + 0.5) * f.width / 8);
        const uint8_t* p = &f.rgb[(size_t(y) * f.width + x) * 3];
        for (int c = 0; c < 3; ++c)
            EXPECT_NEAR(int(p[c]), int(kColorbar[bar][c]), tolerance)
                << "bar " << bar << " channel " << c << " at (" << x << "," << y << ")";
    }
}

// The device at `path` opened for w×h frames of `fourcc` (0: YUYV).
Result<std::unique_ptr<V4L2Device>> openDevice(const std::string& path, uint32_t fourcc, uint32_t w,
                                               uint32_t h) {
    V4L2Config config;
    config.device = path;
    config.fourcc = fourcc;
    config.width = w;
    config.height = h;
    return V4L2Device::create(config);
}

Result<std::unique_ptr<V4L2Device>> openVivid(const std::string& path, uint32_t fourcc, uint32_t w,
                                              uint32_t h) {
    auto dev = openDevice(path, fourcc, w, h);
    if (!dev) return dev;
    // Deterministic frames: a fixed pattern and no timestamp text (vmtest README).
    if (Status s = (*dev)->setControl("Test Pattern", 1); !s) return s.error();
    if (Status s = (*dev)->setControl("osd_text_mode", 2); !s)
        return s.error();  // v4l2-ctl's name form
    return dev;
}

void streamAndCheck(uint32_t fourcc, uint32_t w, uint32_t h, int tolerance) {
    auto dev = openVivid("/dev/video0", fourcc, w, h);
    ASSERT_TRUE(dev) << dev.message();
    ASSERT_TRUE((*dev)->start());
    uint64_t lastTs = 0;
    uint32_t lastSeq = 0;
    for (int i = 0; i < 6; ++i) {
        Frame f;
        Result<bool> got = (*dev)->read(kFrameTimeoutMs, f);
        ASSERT_TRUE(got) << got.message();
        ASSERT_TRUE(*got) << "no frame within " << kFrameTimeoutMs << " ms";
        EXPECT_EQ(f.width, w);
        EXPECT_EQ(f.height, h);
        if (i > 0) {
            EXPECT_GT(f.deviceSequence, lastSeq);
            EXPECT_GT(f.timestampNs, lastTs);
        }
        lastSeq = f.deviceSequence;
        lastTs = f.timestampNs;
        // The first frames may predate the control change.
        if (i >= 3) expectColorbar(f, tolerance);
    }
    // A driver may flag a frame as corrupt (vivid does now and then on a loaded VM); such a
    // frame is skipped and counted, never delivered, and must stay the exception.
    EXPECT_LE((*dev)->badFrames(), 2u);
    timespec now{};
    clock_gettime(CLOCK_MONOTONIC, &now);
    const uint64_t nowNs = uint64_t(now.tv_sec) * 1000000000ull + uint64_t(now.tv_nsec);
    // Kernel timestamps are on CLOCK_MONOTONIC. vivid stamps the nominal time of each frame
    // (stream start + sequence x period), which on the slow VM may run ahead of the clock, so
    // only the clock domain is checked: within seconds of now, not 0 and not wall time.
    const int64_t skewNs = int64_t(lastTs) - int64_t(nowNs);
    EXPECT_LT(std::abs(skewNs), 5'000'000'000ll) << "timestamp " << lastTs << ", now " << nowNs;
}

TEST(Vivid, StreamsYuyv) { streamAndCheck(V4L2_PIX_FMT_YUYV, 640, 360, 6); }

TEST(Vivid, StreamsNv12) { streamAndCheck(V4L2_PIX_FMT_NV12, 320, 180, 6); }

TEST(Vivid, FrameRateFromConfig) {
    V4L2Config config;
    config.device = "/dev/video0";
    config.width = 640;
    config.height = 480;
    config.fps = 25;
    auto dev = V4L2Device::create(config);
    ASSERT_TRUE(dev) << dev.message();
    EXPECT_NEAR((*dev)->fps(), 25.0, 0.01);
}

TEST(Vivid, UnsupportedFormatListsWhatTheDeviceOffers) {
    V4L2Config config;
    config.device = "/dev/video0";
    config.fourcc = V4L2_PIX_FMT_MJPEG;
    auto dev = V4L2Device::create(config);
    ASSERT_FALSE(dev);
    EXPECT_NE(dev.message().find("does not offer pixel format MJPG"), std::string::npos)
        << dev.message();
    EXPECT_NE(dev.message().find("YUYV"), std::string::npos) << dev.message();

    config.fourcc = V4L2_PIX_FMT_YUYV;
    config.width = 1000;
    config.height = 1000;
    dev = V4L2Device::create(config);
    ASSERT_FALSE(dev);
    EXPECT_NE(dev.message().find("1000x1000 is not available"), std::string::npos) << dev.message();

    config.width = 640;
    config.height = 480;
    dev = V4L2Device::create(config);
    ASSERT_TRUE(dev);
    Status s = (*dev)->setControl("No Such Control", 1);
    ASSERT_FALSE(s);
    EXPECT_NE(s.message().find("Test Pattern"), std::string::npos) << s.message();
}

// MJPEG through v4l2loopback: a writer thread plays a JPEG-encoded colour bar, the device
// captures it. Needs `--modprobe 'v4l2loopback video_nr=10 ...'` (see CMakeLists.txt).
TEST(Loopback, StreamsMjpeg) {
    const char* node = "/dev/video10";
    if (::access(node, F_OK) != 0) GTEST_SKIP() << node << " absent: v4l2loopback not loaded";
    const int w = 320, h = 240;
    cv::Mat rgb(h, w, CV_8UC3);
    for (int x = 0; x < w; ++x)
        rgb.col(x).setTo(
            cv::Scalar(kColorbar[x * 8 / w][0], kColorbar[x * 8 / w][1], kColorbar[x * 8 / w][2]));
    cv::Mat bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    std::vector<uint8_t> jpeg;
    ASSERT_TRUE(cv::imencode(".jpg", bgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95}));

    UniqueFD out(::open(node, O_RDWR | O_CLOEXEC));
    ASSERT_TRUE(out.isValid()) << strerror(errno);
    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_OUTPUT;
    fmt.fmt.pix.width = w;
    fmt.fmt.pix.height = h;
    fmt.fmt.pix.pixelformat = V4L2_PIX_FMT_MJPEG;
    fmt.fmt.pix.sizeimage = uint32_t(jpeg.size());
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    ASSERT_EQ(::ioctl(out.get(), VIDIOC_S_FMT, &fmt), 0) << strerror(errno);
    ASSERT_EQ(::write(out.get(), jpeg.data(), jpeg.size()), ssize_t(jpeg.size()));

    // Paced (v4l2loopback does not throttle its writer). Every third frame is garbage (a camera
    // sending corrupt data): it must cost that frame, counted, and never the stream.
    std::vector<uint8_t> garbage(jpeg.size(), 0x5a);
    std::atomic<bool> stop{false};
    std::thread writer([&] {
        for (int n = 0; !stop; ++n) {
            const std::vector<uint8_t>& data = n % 3 == 2 ? garbage : jpeg;
            if (::write(out.get(), data.data(), data.size()) < 0) break;
            std::this_thread::sleep_for(std::chrono::milliseconds(40));
        }
    });
    // Joins the writer on every exit path, ASSERT's early returns included.
    struct Joiner {
        std::atomic<bool>& stop;
        std::thread& thread;
        ~Joiner() {
            stop = true;
            thread.join();
        }
    } joiner{stop, writer};

    auto dev = openDevice(node, V4L2_PIX_FMT_MJPEG, w, h);
    ASSERT_TRUE(dev) << dev.message();
    ASSERT_TRUE((*dev)->start());
    int frames = 0;
    for (int i = 0; i < 12 && frames < 4; ++i) {
        Frame f;
        Result<bool> got = (*dev)->read(kFrameTimeoutMs, f);
        ASSERT_TRUE(got) << got.message();
        if (!*got) continue;
        ++frames;
        expectColorbar(f, 16);
    }
    EXPECT_EQ(frames, 4);
    EXPECT_GE((*dev)->badFrames(), 1u);
}

FrameReaderFactory vividFactory(const std::string& path, uint32_t w, uint32_t h) {
    return [=]() -> Result<std::unique_ptr<FrameReader>> {
        auto dev = openDevice(path, 0, w, h);
        if (!dev) return dev.error();
        return std::unique_ptr<FrameReader>(std::move(*dev));
    };
}

CaptureOptions vmOptions(const std::string& name) {
    CaptureOptions o;
    o.name = name;
    o.retryIntervalMs = 100;
    o.stallTimeoutMs = 8000;  // the VM's vivid can be slow, never this slow
    return o;
}

template <typename Pred>
bool waitFor(Pred pred, int ms) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
    while (std::chrono::steady_clock::now() < end) {
        if (pred()) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return pred();
}

TEST(Vivid, TwoCamerasEachOnItsOwnThread) {
    CaptureThread scene(vividFactory("/dev/video0", 640, 360), vmOptions("scene /dev/video0"));
    CaptureThread fisheye(vividFactory("/dev/video1", 320, 180), vmOptions("fisheye /dev/video1"));
    ASSERT_TRUE(scene.start());
    ASSERT_TRUE(fisheye.start());
    EXPECT_TRUE(waitFor([&] { return scene.stats().delivered >= 5; }, 20000));
    EXPECT_TRUE(waitFor([&] { return fisheye.stats().delivered >= 5; }, 20000));
    auto a = scene.frames().latest();
    auto b = fisheye.frames().latest();
    ASSERT_NE(a, nullptr);
    ASSERT_NE(b, nullptr);
    EXPECT_EQ(a->width, 640u);
    EXPECT_EQ(b->width, 320u);
    scene.stop();
    fisheye.stop();
    EXPECT_EQ(scene.stats().reconnects, 0u);
    EXPECT_EQ(fisheye.stats().reconnects, 0u);
    std::printf("scene: %lu delivered, %lu dropped; fisheye: %lu delivered, %lu dropped\n",
                (unsigned long)scene.stats().delivered, (unsigned long)scene.stats().dropped,
                (unsigned long)fisheye.stats().delivered, (unsigned long)fisheye.stats().dropped);
}

// Live bracketing on a real driver (capture/exposure_bracket.h). vivid has no exposure control:
// its Gain changes nothing in the picture, and its Contrast scales the 8-bit codes, not the
// light (about 2.2 stops of light per stop of contrast through the sRGB curve). Neither is a
// true exposure, so every bracket must reach the assembler labelled as cycled and leave it
// dropped as mismatched: never merged on the labels alone.

// The delivered (labelled) frames of a bracketing device; withheld frames are read() == false.
std::vector<Frame> readBracketFrames(V4L2Device& dev, int count) {
    std::vector<Frame> frames;
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (int(frames.size()) < count && std::chrono::steady_clock::now() < end) {
        Frame f;
        Result<bool> got = dev.read(kFrameTimeoutMs, f);
        EXPECT_TRUE(got) << got.message();
        if (!got) break;
        if (*got) frames.push_back(std::move(f));
    }
    return frames;
}

double meanCode(const Frame& f) {
    double sum = 0.0;
    for (uint8_t v : f.rgb) sum += v;
    return sum / double(f.rgb.size());
}

// Feeds `frames` (consecutive, as the capture thread numbers them) to an assembler for `stops`.
BracketCounts assemble(const std::vector<Frame>& frames, const std::vector<float>& stops) {
    Result<BracketAssembler> assembler =
        BracketAssembler::create({.stops = stops}, InverseToneMapSettings{});
    EXPECT_TRUE(assembler) << assembler.message();
    for (size_t i = 0; i < frames.size(); ++i) {
        const Frame& f = frames[i];
        const cv::Mat rgb(int(f.height), int(f.width), CV_8UC3, const_cast<uint8_t*>(f.rgb.data()));
        EXPECT_FALSE(assembler->add(rgb, i, f.timestampNs, f.exposureStops).has_value())
            << "merged a bracket whose pictures do not match its labels";
    }
    std::printf("assembler: %s\n", assembler->lastDrop().c_str());
    return assembler->counts();
}

ExposureBracketConfig cycling(std::vector<float> stops, int framesPerStep, std::string control) {
    return {std::move(stops), framesPerStep, std::move(control)};
}

V4L2Config bracketConfig(std::vector<std::pair<std::string, int32_t>> controls,
                         std::optional<ExposureBracketConfig> bracket) {
    V4L2Config config;
    config.device = "/dev/video1";
    config.width = 320;
    config.height = 180;
    // 75 % colour bars: the white bar's pixels lie within the assembler's check range.
    config.controls = {{"test_pattern", 0}, {"osd_text_mode", 2}};
    config.controls.insert(config.controls.end(), controls.begin(), controls.end());
    config.bracket = std::move(bracket);
    return config;
}

TEST(VividBracket, CyclesTheControlAndDeliversOnlyEachStepsLastFrameLabelled) {
    const int framesPerStep = 2;
    auto dev = V4L2Device::create(
        bracketConfig({{"contrast", 128}}, cycling({0.0f, -1.0f}, framesPerStep, "contrast")));
    ASSERT_TRUE(dev) << dev.message();
    ASSERT_TRUE((*dev)->start());
    const std::vector<Frame> frames = readBracketFrames(**dev, 8);
    ASSERT_EQ(frames.size(), 8u);
    const ExposureCycle& cycle = *(*dev)->exposureCycle();
    std::printf("cycle: %lu withheld, %lu restarts, %lu extended\n",
                (unsigned long)cycle.settleFrames(), (unsigned long)cycle.restarts(),
                (unsigned long)cycle.extended());
    // vivid sets a control on the frame after: every delivered frame shows its label, so the
    // pictures fall in two groups by label, the −1 ones (contrast 64) the darker.
    double mean[2] = {0.0, 0.0};
    for (size_t i = 0; i < frames.size(); ++i) {
        ASSERT_TRUE(frames[i].exposureStops);
        const int step = *frames[i].exposureStops == 0.0f ? 0 : 1;
        if (cycle.restarts() == 0) {
            EXPECT_EQ(step, int(i % 2)) << "frame " << i;
            if (i > 0) {
                EXPECT_EQ(frames[i].deviceSequence, frames[i - 1].deviceSequence + framesPerStep)
                    << "settling frames are withheld";
            }
        }
        if (i < 2) {
            mean[step] = meanCode(frames[i]);
        } else {
            EXPECT_NEAR(meanCode(frames[i]), mean[step], 0.5) << "frame " << i;
        }
    }
    EXPECT_LT(mean[1], 0.7 * mean[0]);
    // Contrast is no exposure: the picture says about −2.2 stops where the label says −1.
    const BracketCounts counts = assemble(frames, {0.0f, -1.0f});
    EXPECT_EQ(counts.merged, 0u);
    EXPECT_GE(counts.droppedMismatch, 3u);
    dev->reset();  // closed before the next open: vivid streams to one owner
    dev = V4L2Device::create(
        bracketConfig({{"contrast", 128}}, std::nullopt));  // as the other tests expect
    ASSERT_TRUE(dev) << dev.message();
}

TEST(VividBracket, AControlThatDoesNotChangeThePictureIsNeverMerged) {
    // vivid has no exposure_time_absolute: refused at open, naming the device.
    auto dev =
        V4L2Device::create(bracketConfig({}, cycling({0.0f, -4.0f}, 2, "exposure_time_absolute")));
    ASSERT_FALSE(dev);
    EXPECT_NE(dev.message().find("/dev/video1"), std::string::npos) << dev.message();
    EXPECT_NE(dev.message().find("no such control"), std::string::npos) << dev.message();
    // Gain while automatic gain owns it: inactive, refused.
    dev = V4L2Device::create(
        bracketConfig({{"gain_automatic", 1}, {"gain", 128}}, cycling({0.0f, -4.0f}, 2, "gain")));
    ASSERT_FALSE(dev);
    EXPECT_NE(dev.message().find("inactive"), std::string::npos) << dev.message();
    // A stop the control cannot reach: 128 × 2^-8 = 0.5 of a range starting at 0.
    dev = V4L2Device::create(
        bracketConfig({{"gain_automatic", 0}, {"gain", 128}}, cycling({0.0f, -8.0f}, 2, "gain")));
    ASSERT_FALSE(dev);
    EXPECT_NE(dev.message().find("0 to 255"), std::string::npos) << dev.message();

    // In manual gain it cycles 128 → 8, which vivid ignores: labelled −4, the same picture.
    dev = V4L2Device::create(
        bracketConfig({{"gain_automatic", 0}, {"gain", 128}}, cycling({0.0f, -4.0f}, 2, "gain")));
    ASSERT_TRUE(dev) << dev.message();
    ASSERT_TRUE((*dev)->start());
    const std::vector<Frame> frames = readBracketFrames(**dev, 6);
    ASSERT_EQ(frames.size(), 6u);
    const BracketCounts counts = assemble(frames, {0.0f, -4.0f});
    EXPECT_EQ(counts.merged, 0u);
    EXPECT_GE(counts.droppedMismatch, 2u);
    dev->reset();  // closed before the next open: vivid streams to one owner
    dev = V4L2Device::create(bracketConfig({{"gain_automatic", 1}}, std::nullopt));
    ASSERT_TRUE(dev) << dev.message();
}

bool writeSysfs(const char* path, const char* value) {
    std::ofstream f(path);
    f << value;
    f.flush();
    return bool(f);
}

// Last: it unplugs both vivid cameras (one platform device) and plugs them back.
// A control the config names that does not apply (here: one vivid does not have) would leave
// the camera's pictures other than its radiometry promises: the camera is in error, with the
// reason in its stats (previsd's status and display), not streaming.
TEST(Vivid, AControlThatDoesNotApplyIsAnErrorNotAStream) {
    V4L2Config config;
    config.device = "/dev/video0";
    config.width = 320;
    config.height = 180;
    config.controls = {{"Test Pattern", 1}, {"No Such Control", 100}};
    auto dev = V4L2Device::create(config);
    ASSERT_FALSE(dev);
    EXPECT_NE(dev.message().find("control 'No Such Control' = 100 not applied"), std::string::npos)
        << dev.message();
    CaptureThread capture(
        [config]() -> Result<std::unique_ptr<FrameReader>> {
            auto d = V4L2Device::create(config);
            if (!d) return d.error();
            return std::unique_ptr<FrameReader>(std::move(*d));
        },
        vmOptions("scene /dev/video0"));
    ASSERT_TRUE(capture.start());
    ASSERT_TRUE(waitFor([&] { return capture.state() == CaptureState::Lost; }, 10000));
    EXPECT_NE(capture.stats().problem.find("No Such Control"), std::string::npos)
        << capture.stats().problem;
    EXPECT_EQ(capture.stats().delivered, 0u);
    capture.stop();
    // The controls it has apply, and it streams.
    config.controls = {{"Test Pattern", 1}};
    EXPECT_TRUE(V4L2Device::create(config)) << "vivid's own control";
}

TEST(Vivid, UnplugAndReplugResumeWithoutRestart) {
    CaptureThread capture(vividFactory("/dev/video0", 320, 180), vmOptions("scene /dev/video0"));
    ASSERT_TRUE(capture.start());
    ASSERT_TRUE(waitFor([&] { return capture.stats().delivered >= 3; }, 20000));

    ASSERT_TRUE(writeSysfs("/sys/bus/platform/drivers/vivid/unbind", "vivid.0"));
    ASSERT_TRUE(waitFor([&] { return capture.state() == CaptureState::Lost; }, 10000))
        << "state " << toString(capture.state());
    const uint64_t before = capture.stats().delivered;
    const uint64_t lastSeq = capture.frames().latest()->sequence;
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // several failed reopens
    EXPECT_EQ(capture.state(), CaptureState::Lost);

    ASSERT_TRUE(writeSysfs("/sys/bus/platform/drivers/vivid/bind", "vivid.0"));
    EXPECT_TRUE(waitFor([&] { return capture.stats().delivered >= before + 3; }, 30000))
        << "state " << toString(capture.state()) << ", delivered " << capture.stats().delivered;
    EXPECT_EQ(capture.state(), CaptureState::Streaming);
    EXPECT_EQ(capture.stats().reconnects, 1u);
    auto f = capture.frames().latest();
    ASSERT_NE(f, nullptr);
    EXPECT_GT(f->sequence, lastSeq);  // one sequence across the reconnect
    EXPECT_EQ(f->width, 320u);
    capture.stop();
}

}  // namespace
}  // namespace previs

int main(int argc, char** argv) {
    return previs::testing::runVmTests(argc, argv, "test_capture_vm");
}
