// The image writers that go through a descriptor or memory (for base/atomic_file.h) write the
// very bytes the by-name writers do, and fail with one line on a full disk.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <unistd.h>

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

std::vector<uint8_t> readBytes(const fs::path& p) {
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
    EXPECT_EQ(readBytes(dir / "by_fd.bin"), readBytes(dir / "by_name.exr"));
    Result<ImageF> back = readExrLayer((dir / "by_name.exr").string(), "depth");
    ASSERT_TRUE(back.ok()) << back.message();
    EXPECT_EQ(back->pixels, depth.pixels);
}

TEST(ImageWrite, PngInMemoryIsTheSameFile) {
    const fs::path dir = testing::scratchDir("image_write");
    std::vector<uint8_t> rgb(size_t(31) * 17 * 3);
    for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = uint8_t(i * 7 % 251);
    ASSERT_TRUE(writePng((dir / "by_name.png").string(), 31, 17, rgb));
    Result<std::vector<uint8_t>> encoded = encodePng(31, 17, rgb, "frame");
    ASSERT_TRUE(encoded.ok()) << encoded.message();
    EXPECT_EQ(*encoded, readBytes(dir / "by_name.png"));
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
