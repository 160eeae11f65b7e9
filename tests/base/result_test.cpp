// Result: the value of a failed result is a checked programming error, reported with the
// error's own message (issue 11: never a bare bad_variant_access); an error's kind goes with it.
#include "base/result.h"

#include <gtest/gtest.h>

namespace previs {
namespace {

Result<int> parseDigit(char c) {
    if (c < '0' || c > '9') return makeError("'{}' is not a digit", c);
    return c - '0';
}

TEST(Result, HoldsValueOrError) {
    auto good = parseDigit('7');
    ASSERT_TRUE(good.ok());
    EXPECT_EQ(*good, 7);
    auto bad = parseDigit('x');
    ASSERT_FALSE(bad.ok());
    EXPECT_EQ(bad.message(), "'x' is not a digit");
}

// A config file that names a missing scene: the config's error, whoever passes it on.
Status loadScene(bool sceneExists) {
    if (!sceneExists)
        return makeError(Error::Kind::Config, "scene 'set.gltf' not found; fix [scene] path");
    return {};
}

Result<int> startService(bool sceneExists, bool gpuWorks) {
    if (Status s = loadScene(sceneExists); !s) return s.error();
    if (!gpuWorks) return withKind(makeError("no Vulkan device found"), Error::Kind::Device);
    return 0;
}

TEST(Result, AnErrorsKindTravelsWithItThroughStatusAndResult) {
    EXPECT_EQ(parseDigit('x').error().kind, Error::Kind::Runtime);  // the default
    Result<int> config = startService(false, true);
    ASSERT_FALSE(config.ok());
    EXPECT_EQ(config.error().kind, Error::Kind::Config);
    EXPECT_EQ(config.message(), "scene 'set.gltf' not found; fix [scene] path");
    Result<int> device = startService(true, false);
    ASSERT_FALSE(device.ok());
    EXPECT_EQ(device.error().kind, Error::Kind::Device);
    EXPECT_EQ(device.message(), "no Vulkan device found");
    // Moved on as a Status and back into a Result, the kind stays.
    Status passedOn = config.error();
    Result<std::string> again = passedOn.error();
    EXPECT_EQ(again.error().kind, Error::Kind::Config);
    EXPECT_TRUE(startService(true, true).ok());
}

TEST(ResultDeathTest, ValueOfAnErrorStopsWithTheErrorsMessage) {
    GTEST_FLAG_SET(death_test_style, "threadsafe");
    EXPECT_DEATH((void)parseDigit('x').value(), "value of a failed result.*'x' is not a digit");
    EXPECT_DEATH((void)*parseDigit('y'), "'y' is not a digit");
    EXPECT_DEATH((void)parseDigit('3').error(), "error\\(\\) of a result that holds a value");
}

}  // namespace
}  // namespace previs
