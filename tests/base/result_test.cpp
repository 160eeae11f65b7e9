// Result: the value of a failed result is a checked programming error, reported with the
// error's own message (issue 11: never a bare bad_variant_access).
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

TEST(ResultDeathTest, ValueOfAnErrorStopsWithTheErrorsMessage) {
    GTEST_FLAG_SET(death_test_style, "threadsafe");
    EXPECT_DEATH((void)parseDigit('x').value(), "value of a failed result.*'x' is not a digit");
    EXPECT_DEATH((void)*parseDigit('y'), "'y' is not a digit");
    EXPECT_DEATH((void)parseDigit('3').error(), "error\\(\\) of a result that holds a value");
}

}  // namespace
}  // namespace previs
