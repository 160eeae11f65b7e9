#include "tests/support/temp_dir.h"
#include "image/image.h"

#include <cstring>
#include <filesystem>
#include <limits>

#include <unistd.h>

#include <gtest/gtest.h>

namespace previs {
namespace {

std::filesystem::path tempDir() { return previs::testing::scratchDir("previs_image_test"); }

TEST(Image, ExrFloatRoundTripIsBitExact) {
    for (uint32_t channels : {1u, 3u, 4u}) {
        ImageF image;
        image.width = 7;
        image.height = 5;
        image.channels = channels;
        image.pixels.resize(7 * 5 * channels);
        for (size_t i = 0; i < image.pixels.size(); ++i)
            image.pixels[i] = float(i) * 0.1234567f + 1e-3f;
        // Values half floats cannot hold: a sun, a denormal-ish tiny value, a value needing 24
        // mantissa bits.
        image.pixels[0] = 1e5f;
        image.pixels[1] = 1e-30f;
        image.pixels[2] = 1.0f + std::numeric_limits<float>::epsilon();
        image.pixels[3] = std::numeric_limits<float>::denorm_min();
        const std::string path = (tempDir() / ("rt" + std::to_string(channels) + ".exr")).string();
        ASSERT_TRUE(writeExr(path, image).ok());
        Result<ImageF> back = readImage(path);
        ASSERT_TRUE(back.ok()) << back.message();
        EXPECT_EQ(back->width, 7u);
        EXPECT_EQ(back->height, 5u);
        EXPECT_EQ(back->channels, channels);
        EXPECT_FALSE(back->ldrSrgb);
        ASSERT_EQ(back->pixels.size(), image.pixels.size());
        EXPECT_EQ(std::memcmp(back->pixels.data(), image.pixels.data(),
                              image.pixels.size() * sizeof(float)),
                  0);
    }
}

TEST(Image, PngRoundTrip) {
    const uint32_t w = 4;
    const uint32_t h = 3;
    std::vector<uint8_t> rgb(w * h * 3);
    for (size_t i = 0; i < rgb.size(); ++i) rgb[i] = uint8_t(i * 21);
    const std::string path = (tempDir() / "rt.png").string();
    ASSERT_TRUE(writePng(path, w, h, rgb).ok());
    Result<ImageF> back = readImage(path);
    ASSERT_TRUE(back.ok()) << back.message();
    EXPECT_TRUE(back->ldrSrgb);
    ASSERT_EQ(back->channels, 3u);
    ASSERT_EQ(back->width, w);
    ASSERT_EQ(back->height, h);
    for (size_t i = 0; i < rgb.size(); ++i) EXPECT_EQ(back->pixels[i], rgb[i] / 255.0f);
    // Row 0 is the top: pixel (1, 2) is bytes at (2 * w + 1) * 3.
    EXPECT_EQ(back->at(1, 2, 0), rgb[(2 * w + 1) * 3] / 255.0f);
}

TEST(Image, ErrorsNameTheFileAndProblem) {
    const auto dir = tempDir();
    Result<ImageF> missing = readImage((dir / "nope.exr").string());
    ASSERT_FALSE(missing.ok());
    EXPECT_NE(missing.message().find("nope.exr"), std::string::npos);
    EXPECT_NE(missing.message().find("no such file"), std::string::npos);

    const std::string tga = (dir / "x.tga").string();
    { FILE* f = std::fopen(tga.c_str(), "wb"); std::fputs("x", f); std::fclose(f); }
    Result<ImageF> unsupported = readImage(tga);
    ASSERT_FALSE(unsupported.ok());
    EXPECT_NE(unsupported.message().find("x.tga"), std::string::npos);
    EXPECT_NE(unsupported.message().find("unsupported extension"), std::string::npos);

    for (const char* name : {"garbage.exr", "garbage.png", "garbage.hdr"}) {
        const std::string p = (dir / name).string();
        FILE* f = std::fopen(p.c_str(), "wb");
        std::fputs("this is not an image at all", f);
        std::fclose(f);
        Result<ImageF> bad = readImage(p);
        ASSERT_FALSE(bad.ok()) << name;
        EXPECT_NE(bad.message().find(name), std::string::npos) << bad.message();
    }

    ImageF image{2, 2, 3, std::vector<float>(12, 1.0f), false};
    Status noFolder = writeExr((dir / "no_such_dir" / "out.exr").string(), image);
    ASSERT_FALSE(noFolder.ok());
    EXPECT_NE(noFolder.message().find("out.exr"), std::string::npos);
    EXPECT_NE(noFolder.message().find("does not exist"), std::string::npos);

    Status pngNoFolder =
        writePng((dir / "no_such_dir" / "out.png").string(), 1, 1, {1, 2, 3});
    ASSERT_FALSE(pngNoFolder.ok());
    EXPECT_NE(pngNoFolder.message().find("out.png"), std::string::npos);

    Status badSize = writePng((dir / "s.png").string(), 2, 2, {1, 2, 3});
    ASSERT_FALSE(badSize.ok());
    EXPECT_NE(badSize.message().find("s.png"), std::string::npos);

    Status wrongExt = writeExr((dir / "out.png").string(), image);
    ASSERT_FALSE(wrongExt.ok());

    if (::geteuid() != 0) {
        const auto ro = dir / "readonly";
        std::filesystem::create_directories(ro);
        std::filesystem::permissions(ro, std::filesystem::perms::owner_read |
                                             std::filesystem::perms::owner_exec);
        Status denied = writeExr((ro / "x.exr").string(), image);
        ASSERT_FALSE(denied.ok());
        EXPECT_NE(denied.message().find("x.exr"), std::string::npos) << denied.message();
        Status deniedPng = writePng((ro / "x.png").string(), 1, 1, {1, 2, 3});
        ASSERT_FALSE(deniedPng.ok());
        EXPECT_NE(deniedPng.message().find("x.png"), std::string::npos) << deniedPng.message();
        std::filesystem::permissions(ro, std::filesystem::perms::owner_all);
    }
}

}  // namespace
}  // namespace previs
