// KMS output on vkms inside vmtest (Virtual-1, 1024×768 preferred, 60 Hz vblank): what is
// scanned out is read back from the same process through a second, non-master fd
// (readScanout: GETFB2 + MAP_DUMB), as the daemon's VM test reads previsd's screen.
// Exits 77 (skipped) outside the VM.

#include <fcntl.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <thread>

#include "base/unique_fd.h"
#include "display/compose.h"
#include "display/drm_readback.h"
#include "display/kms_output.h"
#include "tests/display/pattern.h"
#include "tests/support/vm_test_main.h"

namespace previs {
namespace {

std::string card() {
    const char* c = std::getenv("VMTEST_DRM_CARD");
    return c && *c ? c : "/dev/dri/card0";
}

std::unique_ptr<KmsOutput> open(OutputSettings s) {
    s.kind = "kms";
    if (s.card.empty()) s.card = card();
    auto out = KmsOutput::create(s);
    EXPECT_TRUE(out.ok()) << out.message();
    if (!out.ok()) return nullptr;
    EXPECT_EQ((*out)->kind(), "kms") << (*out)->describe();
    return std::move(*out);
}

struct Screen {
    std::vector<uint32_t> pixels;
    uint32_t width = 0, height = 0;
    uint32_t at(uint32_t x, uint32_t y) const { return pixels[size_t(y) * width + x] & 0xffffff; }
};

// The pending flip completes at the next vblank. KmsOutput waits 100 ms for it (the service
// drops a frame rather than stall), but an emulated CPU the host deschedules can see its vblank
// later than that; the test waits up to 5 s (waitIdle may be called again while a flip is
// pending).
bool flipDone(KmsOutput& out) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (!out.waitIdle())
        if (std::chrono::steady_clock::now() > deadline) return false;
    return true;
}

Screen readBack() {
    Screen s;
    auto r = readScanout(card(), &s.width, &s.height);
    EXPECT_TRUE(r.ok()) << r.message();
    if (r.ok()) s.pixels = std::move(*r);
    return s;
}

// Shows a 320×180 block frame with a status line and checks the screen: bars black, block
// centres in their colours, the status band dark with white text, and every pixel as composed.
void showAndCheck(KmsOutput& out, uint32_t modeW, uint32_t modeH, int salt) {
    ASSERT_EQ(out.modeWidth(), modeW);
    ASSERT_EQ(out.modeHeight(), modeH);
    DisplayFrame f = test::blockFrame(320, 180, salt);
    f.status = "PREVIEW 1 spp 60.0 fps";
    f.index = uint64_t(salt);
    ASSERT_TRUE(out.show(f).ok());
    ASSERT_TRUE(flipDone(out)) << "page flip event did not arrive";
    const Screen s = readBack();
    ASSERT_EQ(s.width, modeW);
    ASSERT_EQ(s.height, modeH);

    const LetterboxRect r = letterboxRect(320, 180, modeW, modeH);
    const uint32_t band = statusBandHeight(modeH);
    ASSERT_GT(r.y, 0u);
    for (uint32_t y = 0; y < modeH - band; ++y) {
        if (y >= r.y && y < r.y + r.height) continue;
        for (uint32_t x = 0; x < modeW; ++x)
            ASSERT_EQ(s.at(x, y), 0u) << "bar not black at " << x << "," << y;
    }
    for (int by = 0; by < 4; ++by)
        for (int bx = 0; bx < 4; ++bx) {
            const uint32_t x = r.x + (2 * bx + 1) * r.width / 8;
            const uint32_t y = r.y + (2 * by + 1) * r.height / 8;
            const uint32_t got = s.at(x, y), want = test::blockColour(bx, by, salt);
            for (int shift : {0, 8, 16})
                EXPECT_NEAR(int((got >> shift) & 0xff), int((want >> shift) & 0xff), 2)
                    << "block " << bx << "," << by;
        }
    uint32_t white = 0, dark = 0;
    for (uint32_t y = modeH - band; y < modeH; ++y)
        for (uint32_t x = 0; x < modeW; ++x) {
            const uint32_t v = s.at(x, y) & 0xff;
            white += v >= 200;
            dark += v < 40;
        }
    EXPECT_GT(white, 50u) << "no status text";
    EXPECT_GT(dark, band * modeW / 2) << "no status band";

    std::vector<uint32_t> expected(size_t(modeW) * modeH);
    composeFrame(f, modeW, modeH, expected.data(), modeW * 4);
    size_t mismatched = 0;
    for (size_t i = 0; i < expected.size(); ++i)
        mismatched += (expected[i] & 0xffffff) != (s.pixels[i] & 0xffffff);
    EXPECT_EQ(mismatched, 0u) << "screen differs from the composed frame";
}

// N frames shown back to back: each flip waits for the previous one's vblank, so C completed
// flips advance the vblank counter by at least C and take at least (C−1) periods of 60 Hz
// (10% slack for clock granularity).
void checkPacing(KmsOutput& out, int frames) {
    const KmsCounters before = out.counters();
    const auto t0 = std::chrono::steady_clock::now();
    for (int i = 0; i < frames; ++i) {
        DisplayFrame f = test::blockFrame(64, 36, i);
        f.index = uint64_t(i);
        ASSERT_TRUE(out.show(f).ok());
    }
    ASSERT_TRUE(flipDone(out));
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const KmsCounters after = out.counters();
    const uint64_t flips = after.flipsCompleted - before.flipsCompleted;
    const uint64_t dropped = after.framesDropped - before.framesDropped;
    std::printf("%d frames: %llu flips, %llu dropped, %.2f s (%.1f flips/s)\n", frames,
                (unsigned long long)flips, (unsigned long long)dropped, seconds, flips / seconds);
    EXPECT_EQ(flips + dropped, uint64_t(frames));
    EXPECT_GE(flips, uint64_t(frames) / 2) << "most frames should flip";
    // Each completed flip at a later vblank than the one before: never two flips per refresh.
    EXPECT_GE(after.lastVblank - before.lastVblank, flips) << "two flips in one vblank";
    EXPECT_GE(seconds, 0.9 * double(flips - 1) / 60.0) << "flips faster than vblank";
    EXPECT_LT(seconds, 0.2 * frames + 5.0);
}

TEST(KmsVm, AtomicPreferredMode) {
    auto out = open({});
    ASSERT_TRUE(out);
    EXPECT_NE(out->describe().find("Virtual-1"), std::string::npos) << out->describe();
    EXPECT_NE(out->describe().find("atomic"), std::string::npos) << out->describe();
    showAndCheck(*out, 1024, 768, 0);
    showAndCheck(*out, 1024, 768, 1);  // the other buffer
    checkPacing(*out, 40);
    showAndCheck(*out, 1024, 768, 2);  // still showing the newest after many flips
}

TEST(KmsVm, LegacyPath) {
    auto out = open({.connector = "Virtual-1", .forceLegacy = true});
    ASSERT_TRUE(out);
    EXPECT_NE(out->describe().find("legacy"), std::string::npos) << out->describe();
    showAndCheck(*out, 1024, 768, 3);
    checkPacing(*out, 30);
    showAndCheck(*out, 1024, 768, 4);
}

TEST(KmsVm, ConfiguredMode) {
    auto out = open({.mode = "640x480"});
    ASSERT_TRUE(out);
    showAndCheck(*out, 640, 480, 5);
    out.reset();
    out = open({.mode = "800x600@60", .forceLegacy = true});
    ASSERT_TRUE(out);
    showAndCheck(*out, 800, 600, 6);
}

// Another DRM master (a desktop, a second previsd) makes the output "lost" without failing;
// when it goes, show() takes the display back on a later retry (every 2 s).
TEST(KmsVm, LostWhileAnotherMasterThenBack) {
    auto other = std::make_unique<UniqueFD>(::open(card().c_str(), O_RDWR | O_CLOEXEC));
    ASSERT_TRUE(other->isValid());  // first opener: the kernel makes it master
    auto made = KmsOutput::create({.kind = "kms", .card = card()});
    ASSERT_TRUE(made.ok()) << made.message();
    KmsOutput& out = **made;
    EXPECT_EQ(out.kind(), "lost");
    const DisplayFrame f = test::blockFrame(32, 18);
    EXPECT_TRUE(out.show(f).ok());
    EXPECT_EQ(out.kind(), "lost");
    other.reset();
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (out.kind() == "lost" && std::chrono::steady_clock::now() < deadline) {
        EXPECT_TRUE(out.show(f).ok());
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    ASSERT_EQ(out.kind(), "kms");
    showAndCheck(out, 1024, 768, 7);
}

TEST(KmsVm, AutomaticCard) {
    auto out = makeFrameOutput({.kind = "kms"});
    ASSERT_TRUE(out.ok()) << out.message();
    EXPECT_EQ((*out)->kind(), "kms");
}

TEST(KmsVm, UserErrorsListWhatExists) {
    auto out = makeFrameOutput({.kind = "kms", .card = card(), .connector = "HDMI-A-9"});
    ASSERT_FALSE(out.ok());
    EXPECT_NE(out.message().find("HDMI-A-9"), std::string::npos) << out.message();
    EXPECT_NE(out.message().find("Virtual-1"), std::string::npos) << out.message();
    out = makeFrameOutput({.kind = "kms", .connector = "HDMI-A-9"});  // any card
    ASSERT_FALSE(out.ok());
    EXPECT_NE(out.message().find("Virtual-1"), std::string::npos) << out.message();
    out = makeFrameOutput({.kind = "kms", .card = card(), .mode = "1234x567"});
    ASSERT_FALSE(out.ok());
    EXPECT_NE(out.message().find("1234x567"), std::string::npos) << out.message();
    EXPECT_NE(out.message().find("1024x768@60"), std::string::npos) << out.message();
    out = makeFrameOutput({.kind = "kms", .card = card(), .mode = "640x480@75"});
    ASSERT_FALSE(out.ok()) << "vkms has no 75 Hz modes";
}

}  // namespace
}  // namespace previs

int main(int argc, char** argv) {
    return previs::testing::runVmTests(argc, argv, "test_display_vm");
}
