#include "base/strings.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "base/luminance.h"

namespace previs {
namespace {

TEST(Strings, LowerExtensionKeepsTheDotAndOnlyTheLastSuffix) {
    EXPECT_EQ(lowerExtension("dir.v2/Plate.EXR"), ".exr");
    EXPECT_EQ(lowerExtension("take.tar.GZ"), ".gz");
    EXPECT_EQ(lowerExtension("README"), "");
    EXPECT_EQ(lowerExtension(".hidden"), "");  // a dot file has no extension
}

TEST(Strings, EndsWith) {
    EXPECT_TRUE(endsWith("out.png", ".png"));
    EXPECT_FALSE(endsWith("png", ".png"));
    EXPECT_TRUE(endsWith("x", ""));
}

TEST(Strings, Joined) {
    EXPECT_EQ(joined({"a", "b", "c"}), "a, b, c");
    EXPECT_EQ(joined(std::vector<std::string>{}), "");
    EXPECT_EQ(joined(std::vector<std::string>{"x", "y"}, " | "), "x | y");
}

TEST(Luminance, WeightsSumToOneSoGreyKeepsItsValue) {
    EXPECT_NEAR(luminance(0.5, 0.5, 0.5), 0.5, 1e-12);
    EXPECT_NEAR(luminance(1.0f, 0.0f, 0.0f), 0.2126f, 1e-7f);
}

}  // namespace
}  // namespace previs
