// The image writers that go through a descriptor or memory (for base/atomic_file.h) write the
// very bytes the by-name writers do, and fail with one line on a full disk.

#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfStandardAttributes.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "base/unique_fd.h"
#include "image/image.h"
#include "tests/support/temp_dir.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

std::vector<uint8_t> writtenBytes(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), {}};
}

ImageF gradient(uint32_t w, uint32_t h, int channels, float scale) {
    ImageF image;
    image.width = w;
    image.height = h;
    image.channels = channels;
    for (size_t i = 0; i < size_t(w) * h * size_t(channels); ++i)
        image.pixels.push_back(scale * float(i % 97) - 3.0f);
    return image;
}

TEST(ImageWrite, ExrThroughADescriptorIsTheSameFile) {
    const fs::path dir = testing::scratchDir("image_write");
    const ImageF rgba = gradient(37, 21, 4, 0.25f);
    const ImageF depth = gradient(37, 21, 1, 7.5f);
    const std::vector<ExrLayer> layers{{"", &rgba}, {"depth", &depth}};
    ASSERT_TRUE(writeExrLayers((dir / "by_name.exr").string(), layers));
    {
        UniqueFD fd(
            ::open((dir / "by_fd.bin").c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
        ASSERT_TRUE(fd.isValid());
        ASSERT_TRUE(writeExrLayers(fd.get(), "by_fd.bin", layers));
    }
    EXPECT_EQ(writtenBytes(dir / "by_fd.bin"), writtenBytes(dir / "by_name.exr"));
    Result<ImageF> back = readExrLayer((dir / "by_name.exr").string(), "depth");
    ASSERT_TRUE(back.ok()) << back.message();
    EXPECT_EQ(back->pixels, depth.pixels);
}

// A rendered frame's standard attributes for post (issue 54), read back by OpenEXR itself as a
// compositor reads them.
TEST(ImageWrite, ExrFrameAttributesAreOpenExrsStandardOnes) {
    const fs::path dir = testing::scratchDir("image_write");
    const ImageF rgba = gradient(8, 4, 4, 0.5f);
    ExrFrameAttributes a;
    a.timeCode = "10:11:12;13";
    a.fpsNum = 30000;
    a.fpsDen = 1001;
    a.worldToCamera = std::array<float, 16>{1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 0, 0.5f, 2, 3, 1};
    a.worldToNDC = std::array<float, 16>{2, 0, 0, 0, 0, 3, 0, 0, 0.5f, 0.5f, 0, 1, 0, 0, 1, 0};
    a.capDate = "2026:12:06 09:08:07";
    a.utcOffset = -3600.0f;
    a.strings.emplace_back("take", "20261206-090807-scene12");
    const fs::path path = dir / "attributes.exr";
    {
        UniqueFD fd(::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
        ASSERT_TRUE(fd.isValid());
        Status s = writeExrLayers(fd.get(), path.string(), {{"", &rgba}}, a);
        ASSERT_TRUE(s) << s.message();
    }
    Imf::InputFile file(path.c_str());
    const Imf::Header& h = file.header();
    ASSERT_TRUE(Imf::hasTimeCode(h));
    const Imf::TimeCode tc = Imf::timeCode(h);
    EXPECT_EQ(tc.hours(), 10);
    EXPECT_EQ(tc.minutes(), 11);
    EXPECT_EQ(tc.seconds(), 12);
    EXPECT_EQ(tc.frame(), 13);
    EXPECT_TRUE(tc.dropFrame());
    ASSERT_TRUE(Imf::hasFramesPerSecond(h));
    EXPECT_EQ(Imf::framesPerSecond(h).n, 30000);
    EXPECT_EQ(Imf::framesPerSecond(h).d, 1001u);
    ASSERT_TRUE(Imf::hasWorldToCamera(h));
    EXPECT_EQ(Imf::worldToCamera(h)[3][0], 0.5f) << "the translation is the last row";
    EXPECT_EQ(Imf::worldToCamera(h)[1][1], -1.0f);
    ASSERT_TRUE(Imf::hasWorldToNDC(h));
    EXPECT_EQ(Imf::worldToNDC(h)[2][0], 0.5f);
    EXPECT_EQ(Imf::worldToNDC(h)[3][2], 1.0f);
    ASSERT_TRUE(Imf::hasCapDate(h));
    EXPECT_EQ(Imf::capDate(h), "2026:12:06 09:08:07");
    ASSERT_TRUE(Imf::hasUtcOffset(h));
    EXPECT_EQ(Imf::utcOffset(h), -3600.0f);
    const auto* take = h.findTypedAttribute<Imf::StringAttribute>("take");
    ASSERT_NE(take, nullptr);
    EXPECT_EQ(take->value(), "20261206-090807-scene12");
    // Nothing set, nothing written: the plain writer's file has none of them.
    const fs::path plain = dir / "plain.exr";
    ASSERT_TRUE(writeExrLayers(plain.string(), {{"", &rgba}}));
    Imf::InputFile plainFile(plain.c_str());
    EXPECT_FALSE(Imf::hasTimeCode(plainFile.header()));
    EXPECT_FALSE(Imf::hasWorldToCamera(plainFile.header()));
}

TEST(ImageWrite, AnExrTimecodeThatIsNotOneIsRefusedNamingIt) {
    const fs::path dir = testing::scratchDir("image_write");
    const ImageF rgba = gradient(8, 4, 4, 0.5f);
    for (const char* bad : {"25:00:00:00", "10:61:00:00", "10:00:00", "1a:00:00:00"}) {
        const fs::path path = dir / "bad_timecode.exr";
        UniqueFD fd(::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
        ASSERT_TRUE(fd.isValid());
        ExrFrameAttributes a;
        a.timeCode = bad;
        Status s = writeExrLayers(fd.get(), "frame_000007.exr", {{"", &rgba}}, a);
        ASSERT_FALSE(s) << bad;
        EXPECT_NE(s.message().find("frame_000007.exr"), std::string::npos) << s.message();
        EXPECT_NE(s.message().find(bad), std::string::npos) << s.message();
    }
}

TEST(ImageWrite, PngInMemoryIsTheSameFile) {
    const fs::path dir = testing::scratchDir("image_write");
    std::vector<uint8_t> rgb(size_t(31) * 17 * 3);
    for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = uint8_t(i * 7 % 251);
    ASSERT_TRUE(writePng((dir / "by_name.png").string(), 31, 17, rgb));
    Result<std::vector<uint8_t>> encoded = encodePng(31, 17, rgb, "frame");
    ASSERT_TRUE(encoded.ok()) << encoded.message();
    EXPECT_EQ(*encoded, writtenBytes(dir / "by_name.png"));
    Result<std::vector<uint8_t>> wrong = encodePng(31, 17, {1, 2, 3}, "frame 7");
    ASSERT_FALSE(wrong.ok());
    EXPECT_NE(wrong.message().find("frame 7"), std::string::npos) << wrong.message();
}

TEST(ImageWrite, AFullDiskIsOneLineNotACrash) {
    UniqueFD full(::open("/dev/full", O_WRONLY | O_CLOEXEC));
    if (!full.isValid()) GTEST_SKIP() << "no /dev/full here";
    const ImageF image = gradient(64, 64, 3, 1.0f);
    Status s = writeExr(full.get(), "lighting/000001.exr", image);
    ASSERT_FALSE(s);
    EXPECT_NE(s.message().find("lighting/000001.exr"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("disk full"), std::string::npos) << s.message();
    EXPECT_EQ(s.message().find('\n'), std::string::npos) << s.message();
}

}  // namespace
}  // namespace previs
