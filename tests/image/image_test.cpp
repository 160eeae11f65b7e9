#include "image/image.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>

#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

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
    {
        FILE* f = std::fopen(tga.c_str(), "wb");
        std::fputs("x", f);
        std::fclose(f);
    }
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

    Status pngNoFolder = writePng((dir / "no_such_dir" / "out.png").string(), 1, 1, {1, 2, 3});
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
        std::filesystem::permissions(
            ro, std::filesystem::perms::owner_read | std::filesystem::perms::owner_exec);
        Status denied = writeExr((ro / "x.exr").string(), image);
        ASSERT_FALSE(denied.ok());
        EXPECT_NE(denied.message().find("x.exr"), std::string::npos) << denied.message();
        Status deniedPng = writePng((ro / "x.png").string(), 1, 1, {1, 2, 3});
        ASSERT_FALSE(deniedPng.ok());
        EXPECT_NE(deniedPng.message().find("x.png"), std::string::npos) << deniedPng.message();
        std::filesystem::permissions(ro, std::filesystem::perms::owner_all);
    }
}

void writeBytes(const std::filesystem::path& path, const std::string& bytes) {
    std::ofstream out(path, std::ios::binary);
    out.write(bytes.data(), std::streamsize(bytes.size()));
}

std::string readBytes(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

// A refusal is one line naming the file.
void expectOneLineNaming(const Result<ImageF>& r, const std::string& name, const char* what) {
    ASSERT_FALSE(r.ok()) << name;
    EXPECT_NE(r.message().find(name), std::string::npos) << r.message();
    EXPECT_NE(r.message().find(what), std::string::npos) << r.message();
    EXPECT_EQ(r.message().find('\n'), std::string::npos) << r.message();
}

// A Radiance header for a W x H RLE image, as Photoshop and Poly Haven write it.
std::string hdrHeader(int w, int h) {
    return "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y " + std::to_string(h) + " +X " +
           std::to_string(w) + "\n";
}

// Issue 11: a half-copied .hdr made `previs lights` spin forever inside stb_image. Every
// truncation of a real map (checked in: its first 300 bytes) is an error naming the file,
// returned at once.
TEST(Image, TruncatedHdrIsRefusedNotAHang) {
    const auto start = std::chrono::steady_clock::now();
    const std::string checkedIn =
        testing::sourcePath("tests/image/data/truncated_studio_small_03.hdr");
    expectOneLineNaming(readImage(checkedIn), "truncated_studio_small_03.hdr", "ends early");

    // Cut the checked-in file at every byte past the header: each is refused.
    const std::string head = readBytes(checkedIn);
    ASSERT_EQ(head.size(), 300u);
    for (size_t cut = 110; cut < head.size(); ++cut) {
        const auto p = tempDir() / "cut.hdr";
        writeBytes(p, head.substr(0, cut));
        Result<ImageF> r = readImage(p.string());
        ASSERT_FALSE(r.ok()) << cut;
        EXPECT_NE(r.message().find("cut.hdr"), std::string::npos) << r.message();
    }
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
}

// The case issue 11 reports: the first 47 KB of a 1.5 MB map from the shared data.
TEST(Image, TruncatedSharedHdrMapIsRefused) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    const std::filesystem::path map =
        testing::sharedDataDir() + "envmaps/polyhaven_1k_hdr/studio_small_03_1k.hdr";
    const std::string whole = readBytes(map);
    Result<ImageF> full = readImage(map.string());
    ASSERT_TRUE(full.ok()) << full.message();
    EXPECT_EQ(full->width, 1024u);
    const auto p = tempDir() / "half_copied.hdr";
    writeBytes(p, whole.substr(0, 47000));
    expectOneLineNaming(readImage(p.string()), "half_copied.hdr", "ends early");
}

// A zero-length run never advances stb's scanline; it is refused as corrupt.
TEST(Image, HdrZeroLengthRunIsRefused) {
    std::string file = hdrHeader(8, 1);
    file += std::string("\x02\x02\x00\x08", 4);
    file += std::string(64, '\0');  // count 0, over and over
    const auto p = tempDir() / "zero_run.hdr";
    writeBytes(p, file);
    expectOneLineNaming(readImage(p.string()), "zero_run.hdr", "bad run length");
}

// A valid RLE file decodes to what it encodes (the validator accepts what stb reads).
TEST(Image, HdrRunLengthFileDecodes) {
    std::string file = hdrHeader(8, 2);
    for (int row = 0; row < 2; ++row) {
        file += std::string("\x02\x02\x00\x08", 4);
        // R: a run of 8 x 128; G: 8 literal values; B: two runs of 4; E: a run of 8 x 129.
        file += std::string("\x88\x80", 2);
        file += std::string("\x08", 1) + std::string("\x10\x20\x30\x40\x50\x60\x70\x80", 8);
        file += std::string("\x84\x40\x84\x00", 4);
        file += std::string("\x88\x81", 2);
    }
    const auto p = tempDir() / "rle.hdr";
    writeBytes(p, file);
    Result<ImageF> r = readImage(p.string());
    ASSERT_TRUE(r.ok()) << r.message();
    ASSERT_EQ(r->width, 8u);
    ASSERT_EQ(r->height, 2u);
    // RGBE: value = mantissa / 256 * 2^(E - 128); E = 129 gives mantissa / 128.
    EXPECT_FLOAT_EQ(r->at(0, 1, 0), 128.0f / 128.0f);
    EXPECT_FLOAT_EQ(r->at(2, 0, 1), 0x30 / 128.0f);
    EXPECT_FLOAT_EQ(r->at(5, 1, 2), 0.0f);
    EXPECT_FLOAT_EQ(r->at(1, 0, 2), 0x40 / 128.0f);
}

// Found by fuzz/fuzz_image: a Huffman table of more than 256 codes made stb_image write past
// its table. Refused before stb sees it, as a file and as a glTF texture.
TEST(Image, JpegWithOversizedHuffmanTableIsRefused) {
    const std::string path = testing::sourcePath("tests/image/data/jpeg_huffman_overflow.jpg");
    expectOneLineNaming(readImage(path), "jpeg_huffman_overflow.jpg",
                        "Huffman table of more than 256 codes");
    // The same in a table defined between the scans of a progressive JPEG.
    const std::string progressive =
        testing::sourcePath("tests/image/data/jpeg_progressive_huffman_overflow.jpg");
    expectOneLineNaming(readImage(progressive), "jpeg_progressive_huffman_overflow.jpg",
                        "Huffman table of more than 256 codes");
    // A table segment claiming more bytes than the file has (stb read the rest as zeros and
    // its counts past the table).
    const std::string cut =
        testing::sourcePath("tests/image/data/jpeg_cut_short_huffman_segment.jpg");
    expectOneLineNaming(readImage(cut), "jpeg_cut_short_huffman_segment.jpg", "segment cut short");
    const std::string bytes = readBytes(path);
    Result<ImageRgba8> texture = decodePngOrJpeg(
        std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()),
        "image 0");
    ASSERT_FALSE(texture.ok());
    EXPECT_NE(texture.message().find("more than 256 codes"), std::string::npos)
        << texture.message();
}

// Found by fuzz/fuzz_image (see tests/image/data/README.md): read without a crash.
TEST(Image, PngWithEmptyFirstIdatIsRead) {
    const std::string path = testing::sourcePath("tests/image/data/png_empty_first_idat.png");
    Result<ImageF> r = readImage(path);
    if (!r.ok()) {
        EXPECT_NE(r.message().find("png_empty_first_idat.png"), std::string::npos) << r.message();
        EXPECT_EQ(r.message().find('\n'), std::string::npos) << r.message();
    } else {
        EXPECT_EQ(r->pixels.size(), size_t(r->width) * r->height * r->channels);
    }
}

TEST(Image, ContentMustMatchTheExtension) {
    const auto dir = tempDir();
    ASSERT_TRUE(writePng((dir / "plate.png").string(), 2, 2, std::vector<uint8_t>(12, 7)).ok());
    std::filesystem::copy_file(dir / "plate.png", dir / "plate.exr",
                               std::filesystem::copy_options::overwrite_existing);
    Result<ImageF> r = readImage((dir / "plate.exr").string());
    expectOneLineNaming(r, "plate.exr", "is a PNG image");
    EXPECT_NE(r.message().find("rename it to .png"), std::string::npos) << r.message();

    ImageF image{2, 2, 3, std::vector<float>(12, 0.5f), false};
    ASSERT_TRUE(writeExr((dir / "env.exr").string(), image).ok());
    std::filesystem::copy_file(dir / "env.exr", dir / "env.hdr",
                               std::filesystem::copy_options::overwrite_existing);
    expectOneLineNaming(readImage((dir / "env.hdr").string()), "env.hdr", "is an OpenEXR image");

    writeBytes(dir / "photo.jpg", "GIF89a\x01\x00\x01\x00");
    expectOneLineNaming(readImage((dir / "photo.jpg").string()), "photo.jpg", "is a GIF image");
}

// Images larger than the limit are refused from their header, before any pixel is decoded: a
// header claiming 100000 x 100000 pixels (40 GB of float RGBA) costs nothing.
TEST(Image, OversizedImagesAreRefusedBeforeDecoding) {
    const auto dir = tempDir();
    ASSERT_TRUE(
        writePng((dir / "wide.png").string(), 64, 8, std::vector<uint8_t>(64 * 8 * 3, 9)).ok());
    ImageLimits small;
    small.maxWidth = 32;
    small.maxHeight = 32;
    expectOneLineNaming(readImage((dir / "wide.png").string(), small), "wide.png",
                        "64x8 pixels, larger than the limit 32x32");
    EXPECT_TRUE(readImage((dir / "wide.png").string()).ok());

    ImageF tall{4, 40, 1, std::vector<float>(160, 1.0f), false};
    ASSERT_TRUE(writeExr((dir / "tall.exr").string(), tall).ok());
    expectOneLineNaming(readImage((dir / "tall.exr").string(), small), "tall.exr",
                        "4x40 pixels, larger than the limit 32x32");

    // A PNG whose header (IHDR, bytes 16..23, big-endian) claims 100000 x 100000.
    std::string png = readBytes(dir / "wide.png");
    const char huge[8] = {0, 1, char(0x86), char(0xa0), 0, 1, char(0x86), char(0xa0)};
    png.replace(16, 8, huge, 8);
    writeBytes(dir / "huge.png", png);
    expectOneLineNaming(readImage((dir / "huge.png").string()), "huge.png",
                        "100000x100000 pixels, larger than the limit 16384x16384");

    writeBytes(dir / "huge.hdr", hdrHeader(100000, 50000));
    expectOneLineNaming(readImage((dir / "huge.hdr").string()), "huge.hdr",
                        "100000x50000 pixels, larger than the limit 16384x16384");

    // An EXR header's dataWindow (box2i: xMin yMin xMax yMax, little-endian) patched to
    // 0..99999 x 0..99999.
    std::string exr = readBytes(dir / "tall.exr");
    const std::string key = std::string("dataWindow\0box2i\0", 17);
    const size_t at = exr.find(key);
    ASSERT_NE(at, std::string::npos);
    const char window[16] = {0,          0,          0, 0, 0,          0,          0, 0,
                             char(0x9f), char(0x86), 1, 0, char(0x9f), char(0x86), 1, 0};
    exr.replace(at + key.size() + 4, 16, window, 16);
    writeBytes(dir / "huge.exr", exr);
    expectOneLineNaming(readImage((dir / "huge.exr").string()), "huge.exr",
                        "100000x100000 pixels, larger than the limit 16384x16384");
}

// glTF textures go through the same checks.
TEST(Image, DecodePngOrJpegChecksContentAndSize) {
    const auto dir = tempDir();
    ASSERT_TRUE(writePng((dir / "t.png").string(), 3, 2, std::vector<uint8_t>(18, 200)).ok());
    const std::string png = readBytes(dir / "t.png");
    const std::span<const uint8_t> bytes(reinterpret_cast<const uint8_t*>(png.data()), png.size());
    Result<ImageRgba8> ok = decodePngOrJpeg(bytes, "texture 0");
    ASSERT_TRUE(ok.ok()) << ok.message();
    EXPECT_EQ(ok->width, 3u);
    EXPECT_EQ(ok->pixels.size(), 3u * 2u * 4u);
    EXPECT_EQ(ok->pixels[3], 255);  // opaque alpha added
    Result<ImageRgba8> small = decodePngOrJpeg(bytes, "texture 0", ImageLimits{2, 2});
    ASSERT_FALSE(small.ok());
    EXPECT_NE(small.message().find("texture 0"), std::string::npos) << small.message();
    const std::string hdr = hdrHeader(8, 1);
    Result<ImageRgba8> notPng = decodePngOrJpeg(
        std::span<const uint8_t>(reinterpret_cast<const uint8_t*>(hdr.data()), hdr.size()),
        "texture 1");
    ASSERT_FALSE(notPng.ok());
    EXPECT_NE(notPng.message().find("Radiance HDR image, not PNG or JPEG"), std::string::npos)
        << notPng.message();
}

}  // namespace
}  // namespace previs
