#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <thread>
#include <vector>

#include "display/compose.h"
#include "display/display_thread.h"
#include "display/files_output.h"
#include "display/kms_output.h"
#include "tests/display/pattern.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

uint32_t rgbOf(uint32_t xrgb) { return xrgb & 0xffffffu; }

std::vector<uint32_t> compose(const DisplayFrame& f, uint32_t w, uint32_t h) {
    std::vector<uint32_t> out(size_t(w) * h, 0x12345678u);  // garbage: must all be overwritten
    composeFrame(f, w, h, out.data(), w * 4);
    return out;
}

fs::path makeTempDir() {
    fs::path dir = fs::temp_directory_path() /
                   fmt::format("previs_display_test_{}_{}", getpid(),
                               ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir);
    return dir;
}

TEST(Letterbox, Geometry) {
    auto r = letterboxRect(320, 180, 1024, 768);  // wider than the screen: bars top and bottom
    EXPECT_EQ(r.x, 0u);
    EXPECT_EQ(r.y, 96u);
    EXPECT_EQ(r.width, 1024u);
    EXPECT_EQ(r.height, 576u);
    r = letterboxRect(640, 480, 1920, 1080);  // narrower: bars left and right
    EXPECT_EQ(r.x, 240u);
    EXPECT_EQ(r.y, 0u);
    EXPECT_EQ(r.width, 1440u);
    EXPECT_EQ(r.height, 1080u);
    r = letterboxRect(1920, 1080, 3840, 2160);  // same aspect: fills the screen
    EXPECT_EQ(r.x, 0u);
    EXPECT_EQ(r.y, 0u);
    EXPECT_EQ(r.width, 3840u);
    EXPECT_EQ(r.height, 2160u);
    r = letterboxRect(4000, 10, 640, 480);  // extreme aspect: never below one row
    EXPECT_EQ(r.width, 640u);
    EXPECT_GE(r.height, 1u);
    EXPECT_EQ(letterboxRect(0, 10, 640, 480).width, 0u);
}

TEST(Compose, BarsBlackAndPictureScaled) {
    const DisplayFrame f = test::blockFrame(320, 180);
    const uint32_t w = 1024, h = 768;
    const auto out = compose(f, w, h);
    const LetterboxRect r = letterboxRect(320, 180, w, h);
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            const bool inside = y >= r.y && y < r.y + r.height;
            if (!inside) {
                ASSERT_EQ(rgbOf(out[y * w + x]), 0u) << x << "," << y;
            }
            ASSERT_EQ(out[y * w + x] >> 24, 0xffu);  // X byte written, no garbage left
        }
    // Block centres keep their colour; block edges are blends of neighbours only.
    for (int by = 0; by < 4; ++by)
        for (int bx = 0; bx < 4; ++bx) {
            const uint32_t x = r.x + (2 * bx + 1) * r.width / 8;
            const uint32_t y = r.y + (2 * by + 1) * r.height / 8;
            EXPECT_EQ(rgbOf(out[y * w + x]), test::blockColour(bx, by)) << bx << "," << by;
        }
}

TEST(Compose, PillarboxAndSameSize) {
    const DisplayFrame f = test::blockFrame(64, 64);
    auto out = compose(f, 200, 100);  // 100×100 picture at x = 50
    for (uint32_t y = 0; y < 100; ++y) {
        EXPECT_EQ(rgbOf(out[y * 200 + 49]), 0u);
        EXPECT_EQ(rgbOf(out[y * 200 + 150]), 0u);
    }
    EXPECT_EQ(rgbOf(out[12 * 200 + 50 + 12]), test::blockColour(0, 0));
    // At the render size the picture is copied exactly.
    out = compose(f, 64, 64);
    for (uint32_t y = 0; y < 64; ++y)
        for (uint32_t x = 0; x < 64; ++x) {
            const uint8_t* p = &f.rgb[(y * 64 + x) * 3];
            ASSERT_EQ(rgbOf(out[y * 64 + x]), uint32_t(p[0]) << 16 | uint32_t(p[1]) << 8 | p[2]);
        }
}

TEST(Compose, InvalidFrameDrawsBlack) {
    DisplayFrame f = test::blockFrame(32, 32);
    f.rgb.resize(10);
    const auto out = compose(f, 64, 48);
    for (uint32_t v : out) ASSERT_EQ(rgbOf(v), 0u);
}

// The overlay changes only the band, draws a dark background and white text, and its text is
// tall enough to read at 320×180 and scales up at 4K.
TEST(Compose, OverlayOnlyInBandAndScalesWithHeight) {
    struct Size {
        uint32_t w, h;
        uint32_t minTextRows;
    };
    for (const Size s : {Size{320, 180, 6}, Size{1024, 768, 14}, Size{3840, 2160, 40}}) {
        DisplayFrame f = test::blockFrame(s.w / 2, s.h / 2);
        const auto plain = compose(f, s.w, s.h);
        f.status = "PREVIEW 1 spp 9.8 fps";
        const auto overlaid = compose(f, s.w, s.h);
        const uint32_t band = statusBandHeight(s.h);
        EXPECT_LT(band, s.h / 8) << s.h;
        uint32_t textTop = s.h, textBottom = 0, textRight = 0, dark = 0;
        for (uint32_t y = 0; y < s.h; ++y)
            for (uint32_t x = 0; x < s.w; ++x) {
                const uint32_t a = plain[y * s.w + x], b = overlaid[y * s.w + x];
                if (y < s.h - band) {
                    ASSERT_EQ(a, b) << "outside the band at " << x << "," << y;
                    continue;
                }
                const uint32_t red = (b >> 16) & 0xff, green = (b >> 8) & 0xff, blue = b & 0xff;
                ASSERT_TRUE(red == green && green == blue) << "band pixels are grey";
                if (red >= 200) {
                    textTop = std::min(textTop, y);
                    textBottom = std::max(textBottom, y);
                    textRight = std::max(textRight, x);
                } else if (red < 40) {
                    ++dark;
                }
            }
        ASSERT_LE(textTop, textBottom) << "no white text at " << s.w << "x" << s.h;
        EXPECT_GE(textBottom - textTop + 1, s.minTextRows) << s.w << "x" << s.h;
        EXPECT_LT(textRight, s.w - 1) << "text cut at the right edge";
        EXPECT_GT(dark, band * s.w / 2) << "band mostly dark";
    }
}

TEST(Compose, LongStatusFitsTheWidth) {
    DisplayFrame f = test::blockFrame(32, 18);
    f.status = std::string(200, 'W');
    const auto out = compose(f, 320, 180);
    for (uint32_t y = 180 - statusBandHeight(180); y < 180; ++y)
        EXPECT_LT(rgbOf(out[y * 320 + 319]) & 0xff, 200u) << "white touches the right edge";
}

TEST(FilesOutput, RoundTripEqualsComposedFrame) {
    const fs::path dir = makeTempDir() / "nested" / "frames";
    auto out = makeFrameOutput({.kind = "files", .folder = dir.string()});
    ASSERT_TRUE(out.ok()) << out.message();
    EXPECT_EQ((*out)->kind(), "files");
    ASSERT_TRUE(fs::is_directory(dir));

    DisplayFrame f = test::blockFrame(97, 61);  // odd size: no stride assumptions
    for (size_t i = 0; i < f.rgb.size(); ++i) f.rgb[i] = uint8_t(f.rgb[i] ^ (i * 31));
    f.status = "REFINE 128 spp 2.0 fps";
    f.index = 7;
    ASSERT_TRUE((*out)->show(f).ok());
    f.index = 1234567;  // more than 6 digits still works
    ASSERT_TRUE((*out)->show(f).ok());

    const fs::path png = dir / "frame_000007.png";
    ASSERT_TRUE(fs::exists(png));
    EXPECT_TRUE(fs::exists(dir / "frame_1234567.png"));
    size_t files = 0;
    for (const auto& e : fs::directory_iterator(dir)) {
        ++files;
        EXPECT_EQ(e.path().extension(), ".png") << "temporary left behind: " << e.path();
    }
    EXPECT_EQ(files, 2u);

    const cv::Mat read = cv::imread(png.string(), cv::IMREAD_UNCHANGED);
    ASSERT_EQ(read.type(), CV_8UC3);
    ASSERT_EQ(read.cols, 97);
    ASSERT_EQ(read.rows, 61);
    const auto expected = compose(f, 97, 61);
    for (int y = 0; y < read.rows; ++y)
        for (int x = 0; x < read.cols; ++x) {
            const cv::Vec3b bgr = read.at<cv::Vec3b>(y, x);
            const uint32_t got = uint32_t(bgr[2]) << 16 | uint32_t(bgr[1]) << 8 | bgr[0];
            ASSERT_EQ(got, rgbOf(expected[size_t(y) * 97 + x])) << x << "," << y;
        }
    fs::remove_all(makeTempDir());
}

TEST(FilesOutput, ErrorsNameTheFolder) {
    const fs::path dir = makeTempDir();
    fs::create_directories(dir);
    std::ofstream(dir / "plain_file") << "x";
    auto out = makeFrameOutput({.kind = "files", .folder = (dir / "plain_file" / "sub").string()});
    ASSERT_FALSE(out.ok());
    EXPECT_NE(out.message().find("plain_file"), std::string::npos) << out.message();
    out = makeFrameOutput({.kind = "files"});
    ASSERT_FALSE(out.ok());
    EXPECT_NE(out.message().find("folder"), std::string::npos) << out.message();

    auto ok = FilesOutput::create(dir.string());
    ASSERT_TRUE(ok.ok());
    DisplayFrame bad;
    bad.width = 4;
    bad.height = 4;
    EXPECT_FALSE((*ok)->show(bad).ok());
    fs::remove_all(dir);
}

TEST(Outputs, NoneAndUnknownKind) {
    auto none = makeFrameOutput({});
    ASSERT_TRUE(none.ok());
    EXPECT_EQ((*none)->kind(), "none");
    EXPECT_TRUE((*none)->show(test::blockFrame(8, 8)).ok());
    auto bad = makeFrameOutput({.kind = "hdmi"});
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.message().find("hdmi"), std::string::npos);
}

TEST(KmsOutput, ModeStrings) {
    uint32_t w = 0, h = 0, hz = 0;
    EXPECT_TRUE(parseModeString("1920x1080", &w, &h, &hz));
    EXPECT_EQ(w, 1920u);
    EXPECT_EQ(h, 1080u);
    EXPECT_EQ(hz, 0u);
    EXPECT_TRUE(parseModeString("640x480@60", &w, &h, &hz));
    EXPECT_EQ(hz, 60u);
    for (const char* bad : {"", "1920", "1920x", "x1080", "1920x1080@", "1920x1080@0", "1920x1080p",
                            "0x480", "-640x480", " 640x480", "640x480@60x"})
        EXPECT_FALSE(parseModeString(bad, &w, &h, &hz)) << bad;
}

TEST(KmsOutput, MissingCardIsLostNotFatal) {
    auto out = makeFrameOutput({.kind = "kms", .card = "/dev/dri/card_does_not_exist"});
    ASSERT_TRUE(out.ok()) << out.message();
    EXPECT_EQ((*out)->kind(), "lost");
    const DisplayFrame f = test::blockFrame(16, 9);
    for (int i = 0; i < 3; ++i) {
        EXPECT_TRUE((*out)->show(f).ok());
        EXPECT_EQ((*out)->kind(), "lost");
    }
}

TEST(KmsOutput, BadModeStringIsAUserError) {
    auto out = makeFrameOutput(
        {.kind = "kms", .card = "/dev/dri/card_does_not_exist", .mode = "1920by1080"});
    ASSERT_FALSE(out.ok());
    EXPECT_NE(out.message().find("1920by1080"), std::string::npos) << out.message();
    EXPECT_NE(out.message().find("WIDTHxHEIGHT"), std::string::npos) << out.message();
}

// An output whose show() waits until the test opens the gate: the display thread is busy, so
// frames submitted meanwhile replace each other.
class GatedOutput : public FrameOutput {
public:
    Status show(const DisplayFrame& frame) override {
        std::unique_lock lock(mutex_);
        entered_ = true;
        changed_.notify_all();
        changed_.wait(lock, [&] { return open_; });
        shownIndices_.push_back(frame.index);
        return {};
    }
    std::string kind() const override { return "files"; }

    bool waitEntered() {
        std::unique_lock lock(mutex_);
        return changed_.wait_for(lock, std::chrono::seconds(30), [&] { return entered_; });
    }
    void open() {
        std::lock_guard lock(mutex_);
        open_ = true;
        changed_.notify_all();
    }
    std::vector<uint64_t> shown() {
        std::lock_guard lock(mutex_);
        return shownIndices_;
    }

private:
    std::mutex mutex_;
    std::condition_variable changed_;
    bool entered_ = false;
    bool open_ = false;
    std::vector<uint64_t> shownIndices_;
};

std::shared_ptr<const DisplayFrame> indexedFrame(uint64_t index) {
    auto f = std::make_shared<DisplayFrame>(test::blockFrame(4, 4));
    f->index = index;
    f->captureTimestampNs = int64_t(1000 + index);
    return f;
}

bool waitFor(const std::function<bool()>& done) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (!done()) {
        if (std::chrono::steady_clock::now() > deadline) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return true;
}

TEST(DisplayThread, ShowsNewestAndCountsDrops) {
    auto gated = std::make_unique<GatedOutput>();
    GatedOutput* output = gated.get();
    DisplayThread thread(std::move(gated));
    EXPECT_EQ(thread.stats().kind, "files");

    thread.submit(indexedFrame(0));
    ASSERT_TRUE(output->waitEntered());  // frame 0 taken, the thread is busy showing it
    const auto before = std::chrono::steady_clock::now();
    for (uint64_t i = 1; i <= 3; ++i) thread.submit(indexedFrame(i));  // never blocks
    EXPECT_LT(std::chrono::steady_clock::now() - before, std::chrono::seconds(5));
    output->open();

    ASSERT_TRUE(waitFor([&] { return thread.stats().shown == 2; }));
    const DisplayStats s = thread.stats();
    EXPECT_EQ(s.dropped, 2u);  // 1 and 2 were replaced before the thread took them
    EXPECT_EQ(s.failed, 0u);
    EXPECT_EQ(s.lastIndex, 3u);
    EXPECT_EQ(s.lastCaptureTimestampNs, 1003);
    const int64_t nowNs = std::chrono::duration_cast<std::chrono::nanoseconds>(
                              std::chrono::steady_clock::now().time_since_epoch())
                              .count();
    EXPECT_GT(s.lastShownNs, 0);
    EXPECT_LE(s.lastShownNs, nowNs);
    EXPECT_EQ(output->shown(), (std::vector<uint64_t>{0, 3}));
    thread.stop();
    thread.stop();                   // idempotent
    thread.submit(indexedFrame(9));  // after stop: kept, never shown, no crash
}

TEST(DisplayThread, StopsPromptlyWhenIdle) {
    DisplayThread thread(std::make_unique<NoneOutput>());
    const auto t0 = std::chrono::steady_clock::now();
    thread.stop();
    EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
    EXPECT_EQ(thread.stats().shown, 0u);
}

TEST(DisplayThread, LostDisplayCountsAsNotShown) {
    auto out = makeFrameOutput({.kind = "kms", .card = "/dev/dri/card_does_not_exist"});
    ASSERT_TRUE(out.ok());
    DisplayThread thread(std::move(*out));
    thread.submit(indexedFrame(0));
    ASSERT_TRUE(waitFor([&] { return thread.stats().failed == 1; }));
    EXPECT_EQ(thread.stats().shown, 0u);
    EXPECT_EQ(thread.stats().kind, "lost");
}

}  // namespace
}  // namespace previs
