// Issue 52: the files output (display/files_output.h) keeps a ring of its newest frames, bounded
// in count and bytes, never writes below its free-space floor, and never writes through what
// lies at its temporary names.

#include "display/files_output.h"

#include <gtest/gtest.h>
#include <sys/statvfs.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>

#include "tests/display/pattern.h"
#include "tests/support/temp_dir.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

fs::path freshDir(const std::string& name) {
    return testing::emptyScratchDir("files_output_test", name);
}

std::set<std::string> names(const fs::path& dir) {
    std::set<std::string> out;
    for (const auto& e : fs::directory_iterator(dir)) out.insert(e.path().filename().string());
    return out;
}

Status showFrame(FrameOutput& out, uint64_t index) {
    DisplayFrame f = test::blockFrame(64, 36, int(index));
    f.index = index;
    return out.show(f);
}

FilesOutputLimits ring(uint64_t frames, uint64_t bytes = uint64_t(1) << 30) {
    return {.keepFrames = frames, .maxBytes = bytes, .minFreeBytes = 0};
}

TEST(FilesOutputRing, KeepsTheNewestFramesOnly) {
    const fs::path dir = freshDir("ring");
    auto out = FilesOutput::create(dir.string(), ring(3));
    ASSERT_TRUE(out.ok()) << out.message();
    for (uint64_t i = 0; i < 10; ++i) ASSERT_TRUE(showFrame(**out, i));
    EXPECT_EQ(names(dir),
              (std::set<std::string>{"frame_000007.png", "frame_000008.png", "frame_000009.png"}));
}

TEST(FilesOutputRing, KeepsUnderItsByteCap) {
    const fs::path dir = freshDir("bytes");
    auto probe = FilesOutput::create((dir / "probe").string(), ring(100));
    ASSERT_TRUE(probe.ok()) << probe.message();
    ASSERT_TRUE(showFrame(**probe, 0));
    const uint64_t frameBytes = fs::file_size(dir / "probe" / "frame_000000.png");
    // Room for two and a half frames of this size: the two newest stay.
    auto out = FilesOutput::create((dir / "capped").string(), ring(100, frameBytes * 5 / 2));
    ASSERT_TRUE(out.ok()) << out.message();
    for (uint64_t i = 0; i < 8; ++i) ASSERT_TRUE(showFrame(**out, i));
    const std::set<std::string> left = names(dir / "capped");
    EXPECT_LE(left.size(), 3u);
    EXPECT_GE(left.size(), 1u);
    EXPECT_TRUE(left.count("frame_000007.png")) << "the newest frame always stays";
    uint64_t total = 0;
    for (const std::string& n : left) total += fs::file_size(dir / "capped" / n);
    EXPECT_LE(total, frameBytes * 5 / 2 + frameBytes / 4) << "a frame differs a little in size";
}

TEST(FilesOutputRing, APreviousRunsFramesCountAndItsTemporariesGo) {
    const fs::path dir = freshDir("restart");
    {
        auto first = FilesOutput::create(dir.string(), ring(4));
        ASSERT_TRUE(first.ok()) << first.message();
        for (uint64_t i = 0; i < 20; ++i) ASSERT_TRUE(showFrame(**first, i));
    }
    std::ofstream(dir / ".frame_000020.png.0123456789abcdef.tmp") << "a killed run's half frame";
    std::ofstream(dir / "notes.txt") << "not ours";
    // A new run counts from 0 again: the old run's frames go first, the folder stays bounded.
    auto second = FilesOutput::create(dir.string(), ring(4));
    ASSERT_TRUE(second.ok()) << second.message();
    EXPECT_FALSE(fs::exists(dir / ".frame_000020.png.0123456789abcdef.tmp"));
    for (uint64_t i = 0; i < 3; ++i) ASSERT_TRUE(showFrame(**second, i));
    EXPECT_EQ(names(dir),
              (std::set<std::string>{"frame_000000.png", "frame_000001.png", "frame_000002.png",
                                     "frame_000019.png", "notes.txt"}));
}

TEST(FilesOutputRing, AFrameWrittenAgainCountsOnceAndAsItsNewestWrite) {
    // Indices that come round again (a new run, a looping source): the ring holds the files
    // written last, each once.
    const fs::path dir = freshDir("again");
    auto out = FilesOutput::create(dir.string(), ring(3));
    ASSERT_TRUE(out.ok()) << out.message();
    for (uint64_t i = 0; i < 300; ++i) ASSERT_TRUE(showFrame(**out, i % 5));
    EXPECT_EQ(names(dir),
              (std::set<std::string>{"frame_000002.png", "frame_000003.png", "frame_000004.png"}));
}

TEST(FilesOutputRing, BelowTheFreeSpaceFloorNothingIsWritten) {
    const fs::path dir = freshDir("floor");
    fs::create_directories(dir);
    struct statvfs st {};
    ASSERT_EQ(::statvfs(dir.c_str(), &st), 0);
    const uint64_t free = uint64_t(st.f_bavail) * st.f_frsize;
    // A floor above what the disk has: as if the partition were full.
    auto out = FilesOutput::create(
        dir.string(), {.keepFrames = 10, .maxBytes = 1 << 30, .minFreeBytes = free + (1ull << 40)});
    ASSERT_TRUE(out.ok()) << out.message();
    ::testing::internal::CaptureStderr();
    for (uint64_t i = 0; i < 5; ++i) {
        ASSERT_TRUE(showFrame(**out, i)) << "not an error: the service goes on";
        EXPECT_TRUE((*out)->lastFrameDropped()) << "counted as a display drop";
    }
    const std::string log = ::testing::internal::GetCapturedStderr();
    EXPECT_TRUE(names(dir).empty());
    size_t warnings = 0;
    for (size_t at = 0; (at = log.find("min_free_mb", at)) != std::string::npos; ++at) ++warnings;
    EXPECT_EQ(warnings, 1u) << "one warning, not one a frame: " << log;
    EXPECT_NE(log.find(dir.string()), std::string::npos) << log;
}

TEST(FilesOutputRing, ALinkAtTheOldTemporaryNameIsNotWrittenThrough) {
    const fs::path dir = freshDir("planted");
    fs::create_directories(dir);
    std::ofstream(dir / "victim") << "keep me";
    fs::create_symlink(dir / "victim", dir / ".frame_000000.png.tmp");
    auto out = FilesOutput::create(dir.string(), ring(10));
    ASSERT_TRUE(out.ok()) << out.message();
    ASSERT_TRUE(showFrame(**out, 0));
    std::ifstream in(dir / "victim");
    EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), "keep me");
    EXPECT_TRUE(fs::is_regular_file(fs::symlink_status(dir / "frame_000000.png")));
}

}  // namespace
}  // namespace previs
