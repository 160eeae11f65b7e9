#include "gpu/context.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <numeric>

#include "gpu/buffer.h"

namespace previs {
namespace {

TEST(GpuContextTest, PicksADeviceWithValidation) {
    auto ctx = GpuContext::create({.validation = true, .deviceOverride = ""});
    ASSERT_TRUE(ctx.ok()) << ctx.message();
    EXPECT_FALSE((*ctx)->deviceName().empty());
    EXPECT_TRUE((*ctx)->validationEnabled()) << "install vulkan-validationlayers";
}

TEST(GpuContextTest, OverrideByIndexAndName) {
    auto byIndex = GpuContext::create({.validation = false, .deviceOverride = "0"});
    ASSERT_TRUE(byIndex.ok()) << byIndex.message();
    std::string name = (*byIndex)->deviceName();
    // Any substring of the name, in any case, selects the same device.
    std::string part = name.substr(0, 4);
    for (char& c : part) c = char(std::toupper(c));
    auto byName = GpuContext::create({.validation = false, .deviceOverride = part});
    ASSERT_TRUE(byName.ok()) << byName.message();
    EXPECT_EQ((*byName)->deviceName(), name);
}

TEST(GpuContextTest, UnknownOverrideNamesTheDevices) {
    auto ctx = GpuContext::create({.validation = false, .deviceOverride = "no-such-gpu"});
    ASSERT_FALSE(ctx.ok());
    EXPECT_NE(ctx.message().find("PREVIS_VK_DEVICE 'no-such-gpu'"), std::string::npos)
        << ctx.message();
    EXPECT_NE(ctx.message().find("[0]"), std::string::npos) << ctx.message();
}

// A submission whose fence does not signal within GpuOptions::fenceTimeout is an error naming
// the device, never a wait forever (a hung GPU): here a 256 MiB fill against no time at all.
TEST(GpuContextTest, ASubmissionThatDoesNotFinishInTimeIsAnError) {
    auto ctx = GpuContext::create(
        {.validation = false, .deviceOverride = "", .fenceTimeout = std::chrono::milliseconds(0)});
    ASSERT_TRUE(ctx.ok()) << ctx.message();
    auto buffer = GpuBuffer::create(**ctx, size_t(256) << 20, "big");
    ASSERT_TRUE(buffer.ok()) << buffer.message();
    const Status s = buffer->fill(1);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("did not finish a submission"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find((*ctx)->deviceName()), std::string::npos) << s.message();
    EXPECT_TRUE((*ctx)->deviceLost());
    // The device is not really hung here: let the fill end before its buffer is destroyed.
    (*ctx)->device().waitIdle();
}

TEST(GpuBufferTest, RoundTripAndFill) {
    auto ctx = GpuContext::create({.validation = true, .deviceOverride = ""});
    ASSERT_TRUE(ctx.ok());
    std::vector<uint32_t> data(1000);
    std::iota(data.begin(), data.end(), 7u);
    auto buffer = GpuBuffer::createWith(**ctx, std::span<const uint32_t>(data), "test");
    ASSERT_TRUE(buffer.ok()) << buffer.message();
    std::vector<uint32_t> back(data.size());
    ASSERT_TRUE(buffer->download(back.data(), back.size() * 4).ok());
    EXPECT_EQ(back, data);
    ASSERT_TRUE(buffer->fill(0xdeadbeef).ok());
    ASSERT_TRUE(buffer->download(back.data(), back.size() * 4).ok());
    for (uint32_t v : back) ASSERT_EQ(v, 0xdeadbeefu);
    auto empty = GpuBuffer::create(**ctx, 0, "empty");
    EXPECT_TRUE(empty.ok());
    EXPECT_EQ((*ctx)->validationErrorCount(), 0u);
}

}  // namespace
}  // namespace previs
