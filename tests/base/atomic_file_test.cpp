// The one writer of whole files (base/atomic_file.h): a target is the old file or the whole new
// one, the temporary is a new file of its own (never something already at a name), and what is
// not committed leaves nothing behind.

#include "base/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>

#include "tests/support/temp_dir.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

fs::path freshDir(const std::string& name) {
    const fs::path dir = testing::emptyScratchDir("atomic_file", name);
    fs::create_directories(dir);
    return dir;
}

std::string readText(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

void writeText(const fs::path& p, const std::string& text) { std::ofstream(p) << text; }

std::span<const uint8_t> bytesOf(const std::string& s) {
    return {reinterpret_cast<const uint8_t*>(s.data()), s.size()};
}

std::set<std::string> names(const fs::path& dir) {
    std::set<std::string> out;
    for (const auto& e : fs::directory_iterator(dir)) out.insert(e.path().filename().string());
    return out;
}

TEST(AtomicFile, ReplacesTheTargetWholeAndLeavesNoTemporary) {
    const fs::path dir = freshDir("whole");
    writeText(dir / "a.txt", "old");
    ASSERT_TRUE(writeFileAtomic((dir / "a.txt").string(), bytesOf("new contents")));
    EXPECT_EQ(readText(dir / "a.txt"), "new contents");
    EXPECT_EQ(names(dir), std::set<std::string>{"a.txt"});
    struct stat st {};
    ASSERT_EQ(::stat((dir / "a.txt").c_str(), &st), 0);
    EXPECT_TRUE(S_ISREG(st.st_mode));
}

TEST(AtomicFile, TemporaryIsANewFileBesideTheTarget) {
    const fs::path dir = freshDir("names");
    auto file =
        AtomicFile::create((dir / "frame.png").string(), {.durable = false, .hidden = true});
    ASSERT_TRUE(file.ok()) << file.message();
    const fs::path temporary = file->temporaryPath();
    EXPECT_EQ(temporary.parent_path(), dir);
    EXPECT_TRUE(temporary.filename().string().starts_with(".frame.png."));
    EXPECT_TRUE(temporary.string().ends_with(".tmp"));
    auto other =
        AtomicFile::create((dir / "frame.png").string(), {.durable = false, .hidden = true});
    ASSERT_TRUE(other.ok()) << other.message();
    EXPECT_NE(other->temporaryPath(), file->temporaryPath()) << "two writers never share one";
    auto visible = AtomicFile::create((dir / "index.csv").string());
    ASSERT_TRUE(visible.ok()) << visible.message();
    EXPECT_TRUE(visible->temporaryPath().starts_with((dir / "index.csv.").string()));
}

TEST(AtomicFile, WhatIsAlreadyThereIsNeverOpenedFollowedOrRemoved) {
    // What an attacker or a killed writer could leave at the names earlier versions used: a
    // link to a file the service may write, a FIFO (opening it would block), a leftover.
    const fs::path dir = freshDir("planted");
    writeText(dir / "victim", "keep me");
    fs::create_symlink(dir / "victim", dir / "out.bin.tmp");
    fs::create_symlink(dir / "victim", dir / ".out.bin.tmp");
    ASSERT_EQ(::mkfifo((dir / "out.bin.tmp.exr").c_str(), 0644), 0);
    writeText(dir / "out.bin.0000000000000000.tmp", "leftover");
    ASSERT_TRUE(writeFileAtomic((dir / "out.bin").string(), bytesOf("payload")));
    ASSERT_TRUE(writeFileAtomic((dir / "out.bin").string(), bytesOf("payload"), {.hidden = true}));
    EXPECT_EQ(readText(dir / "out.bin"), "payload");
    EXPECT_EQ(readText(dir / "victim"), "keep me");
    EXPECT_TRUE(fs::is_symlink(dir / "out.bin.tmp"));
    EXPECT_TRUE(fs::is_fifo(dir / "out.bin.tmp.exr"));
    EXPECT_EQ(readText(dir / "out.bin.0000000000000000.tmp"), "leftover");
    EXPECT_EQ(names(dir).size(), 6u) << "nothing else was left";
}

TEST(AtomicFile, ALinkAtTheTargetIsReplacedNotWrittenThrough) {
    const fs::path dir = freshDir("target_link");
    writeText(dir / "victim", "keep me");
    fs::create_symlink(dir / "victim", dir / "out.txt");
    ASSERT_TRUE(writeFileAtomic((dir / "out.txt").string(), bytesOf("new")));
    EXPECT_FALSE(fs::is_symlink(dir / "out.txt"));
    EXPECT_EQ(readText(dir / "out.txt"), "new");
    EXPECT_EQ(readText(dir / "victim"), "keep me");
}

TEST(AtomicFile, NotCommittedLeavesTheTargetAndNoTemporary) {
    const fs::path dir = freshDir("abandoned");
    writeText(dir / "a.txt", "old");
    {
        auto file = AtomicFile::create((dir / "a.txt").string());
        ASSERT_TRUE(file.ok()) << file.message();
        ASSERT_TRUE(file->write(bytesOf("half")));
        AtomicFile moved = std::move(*file);  // the owner moves; only it removes
        EXPECT_TRUE(fs::exists(moved.temporaryPath()));
    }
    EXPECT_EQ(readText(dir / "a.txt"), "old");
    EXPECT_EQ(names(dir), std::set<std::string>{"a.txt"});
}

TEST(AtomicFile, ErrorsNameTheFileAndWhy) {
    const fs::path dir = freshDir("errors");
    Status missing = writeFileAtomic((dir / "no_such_folder" / "x").string(), bytesOf("x"));
    ASSERT_FALSE(missing);
    EXPECT_NE(missing.message().find("no_such_folder/x."), std::string::npos) << missing.message();
    EXPECT_NE(missing.message().find("No such file"), std::string::npos) << missing.message();
    // A folder at the target: the rename fails, the target stays, the temporary goes.
    fs::create_directories(dir / "taken" / "inside");
    Status folder = writeFileAtomic((dir / "taken").string(), bytesOf("x"));
    ASSERT_FALSE(folder);
    EXPECT_NE(folder.message().find("cannot rename"), std::string::npos) << folder.message();
    EXPECT_TRUE(fs::is_directory(dir / "taken" / "inside"));
    EXPECT_EQ(names(dir), std::set<std::string>{"taken"});
}

}  // namespace
}  // namespace previs
