// TomlReader::integerIn: a config integer read in its range and narrowed to the field's type in
// one call; a value out of range or of the wrong type is one message naming the file, the line
// and the dotted key, and leaves the field as it was.
#include "base/toml_reader.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <utility>

#include "tests/support/temp_dir.h"

namespace previs {
namespace {

struct Parsed {
    std::string path;
    toml::table root;
};

Parsed parse(const std::string& name, const std::string& text) {
    const std::string path = (testing::scratchDir("toml_reader_test") / name).string();
    std::ofstream(path) << text;
    Result<toml::table> root = parseTomlFile(path, "test config");
    EXPECT_TRUE(root.ok()) << root.message();
    // Moved, not copied: a copy of a toml++ node does not keep its source line.
    return {path, root.ok() ? std::move(*root) : toml::table{}};
}

TEST(TomlReader, IntegerInNarrowsToTheFieldsType) {
    Parsed p = parse("good.toml", "[freed]\ncamera_id = 200\nttl = 64\n");
    TomlReader r(p.path, "test config");
    const toml::table& freed = *p.root["freed"].as_table();
    uint8_t cameraId = 1;
    int ttl = 1;
    uint64_t absent = 7;
    ASSERT_TRUE(r.integerIn(freed, "freed", "camera_id", cameraId, 0, 255).ok());
    ASSERT_TRUE(r.integerIn(freed, "freed", "ttl", ttl, 1, 255).ok());
    ASSERT_TRUE(r.integerIn(freed, "freed", "max_mb", absent, 1, 1 << 24).ok());
    EXPECT_EQ(cameraId, 200);
    EXPECT_EQ(ttl, 64);
    EXPECT_EQ(absent, 7u);  // absent: left as it was
}

TEST(TomlReader, IntegerInOutOfRangeOrOfTheWrongTypeNamesTheKeyAndTheFile) {
    Parsed p = parse("bad.toml", "[web]\nmax_viewers = 65\njpeg_quality = \"high\"\n");
    TomlReader r(p.path, "test config");
    const toml::table& web = *p.root["web"].as_table();
    int maxViewers = 12;
    Status range = r.integerIn(web, "web", "max_viewers", maxViewers, 1, 64);
    ASSERT_FALSE(range.ok());
    EXPECT_NE(range.message().find(p.path), std::string::npos) << range.message();
    EXPECT_NE(range.message().find("line 2"), std::string::npos) << range.message();
    EXPECT_NE(range.message().find("'web.max_viewers' is 65; it must be an integer in [1, 64]"),
              std::string::npos)
        << range.message();
    EXPECT_EQ(maxViewers, 12);
    uint32_t quality = 85;
    Status type = r.integerIn(web, "web", "jpeg_quality", quality, 1, 100);
    ASSERT_FALSE(type.ok());
    EXPECT_NE(type.message().find(p.path), std::string::npos) << type.message();
    EXPECT_NE(type.message().find("'web.jpeg_quality' must be an integer, not a string"),
              std::string::npos)
        << type.message();
    EXPECT_EQ(quality, 85u);
}

}  // namespace
}  // namespace previs
