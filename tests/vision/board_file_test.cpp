#include "vision/board_file.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

std::string writeBoard(const std::string& name, const std::string& text) {
    const auto path = previs::testing::scratchDir("previs_board_test") / name;
    std::ofstream(path) << text;
    return path.string();
}

// A refusal is one line naming the file and the key.
void expectOneLine(const Result<TagBoard>& board, const std::string& path, const std::string& key,
                   const std::string& what) {
    ASSERT_FALSE(board.ok());
    const std::string& m = board.message();
    EXPECT_NE(m.find("'" + path + "'"), std::string::npos) << m;
    EXPECT_NE(m.find(key), std::string::npos) << m;
    EXPECT_NE(m.find(what), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
}

constexpr const char* kTag = "[[tag]]\nid = 1\nposition_m = [0.0, 0.0, 0.0]\n";

TEST(BoardFile, ReadsTheDemoBoard) {
    Result<TagBoard> board = loadTagBoard(testing::sourcePath("examples/demo/board.toml"));
    ASSERT_TRUE(board.ok()) << board.message();
    EXPECT_EQ(board->tags().size(), 6u);
    EXPECT_EQ(board->family(), "tag36h11");
    ASSERT_NE(board->find(4), nullptr);
    EXPECT_DOUBLE_EQ(board->find(4)->sizeM, 0.08);
    EXPECT_DOUBLE_EQ(board->find(4)->worldFromTag(2, 3), 0.055);
}

TEST(BoardFile, UnknownKeysAreErrors) {
    const std::string top = writeBoard("typo_top.toml", "tag_size = 0.1\n" + std::string(kTag));
    expectOneLine(loadTagBoard(top), top, "'tag_size'", "unknown key");
    const std::string inTag =
        writeBoard("typo_tag.toml", "tag_size_m = 0.1\n[[tag]]\nid = 1\nposition = [0, 0, 0]\n");
    Result<TagBoard> b = loadTagBoard(inTag);
    expectOneLine(b, inTag, "'position'", "unknown key");
    EXPECT_NE(b.message().find("line 4"), std::string::npos) << b.message();
}

TEST(BoardFile, ValuesOutOfRangeAreErrors) {
    const std::string size = writeBoard("size.toml", "tag_size_m = 95.5\n" + std::string(kTag));
    expectOneLine(loadTagBoard(size), size, "'tag_size_m'", "must be in (0, 10]");
    const std::string negative = writeBoard("negative.toml",
                                            "tag_size_m = 0.1\n[[tag]]\nid = 2\nsize_m = -0.1\n"
                                            "position_m = [0.0, 0.0, 0.0]\n");
    expectOneLine(loadTagBoard(negative), negative, "'tag[0].size_m'", "must be in (0, 10]");
    const std::string id = writeBoard(
        "id.toml", "tag_size_m = 0.1\n[[tag]]\nid = 4294967297\nposition_m = [0, 0, 0]\n");
    expectOneLine(loadTagBoard(id), id, "'tag[0].id'", "must be an integer in [0, 65535]");
    const std::string far =
        writeBoard("far.toml", "tag_size_m = 0.1\n[[tag]]\nid = 1\nposition_m = [0, 55000.0, 0]\n");
    expectOneLine(loadTagBoard(far), far, "'tag[0].position_m[1]'", "must be in [-1000, 1000]");
    const std::string family =
        writeBoard("family.toml", "family = \"tag99h99\"\ntag_size_m = 0.1\n" + std::string(kTag));
    expectOneLine(loadTagBoard(family), family, "'family'", "supported:");
}

TEST(BoardFile, GeometryErrorsNameTheFile) {
    const std::string dup =
        writeBoard("dup.toml", "tag_size_m = 0.1\n" + std::string(kTag) + std::string(kTag));
    expectOneLine(loadTagBoard(dup), dup, "tag id 1", "appears more than once");
    const std::string syntax = writeBoard("syntax.toml", "tag_size_m = [");
    expectOneLine(loadTagBoard(syntax), syntax, "line 1", "not valid TOML");
    const std::string missing = "/nonexistent/board.toml";
    expectOneLine(loadTagBoard(missing), missing, "no such file", "");
}

}  // namespace
}  // namespace previs
