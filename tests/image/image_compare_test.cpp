// `previs compare`'s measure (image/image_compare.h): the RMSE and means it reports, on images
// whose answer is known in closed form, and its refusals.
#include "image/image_compare.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>
#include <random>

#include "image/image.h"

namespace previs {
namespace {

ImageF constant(uint32_t w, uint32_t h, uint32_t channels, float v) {
    ImageF img;
    img.width = w;
    img.height = h;
    img.channels = channels;
    img.pixels.assign(size_t(w) * h * channels, v);
    return img;
}

TEST(CompareImages, IdenticalImagesHaveZeroError) {
    ImageF a = constant(5, 3, 3, 0.25f);
    auto d = compareImages(a, a);
    ASSERT_TRUE(d) << d.message();
    EXPECT_EQ(d->rmse, 0.0);
    EXPECT_DOUBLE_EQ(d->meanA, 0.25);
    EXPECT_EQ(d->values, 45u);
}

TEST(CompareImages, RmseOfAKnownDifference) {
    // b = a except one channel per pixel offset by ±δ alternately: the squared error is δ² on a
    // third of the values, so RMSE = δ/√3, and the offsets cancel in the mean.
    const float delta = 0.5f;
    ImageF a = constant(4, 4, 3, 1.0f);
    ImageF b = a;
    for (size_t p = 0; p < 16; ++p) b.pixels[p * 3 + 1] += p % 2 ? delta : -delta;
    auto d = compareImages(b, a);
    ASSERT_TRUE(d) << d.message();
    EXPECT_NEAR(d->rmse, delta / std::sqrt(3.0), 1e-12);
    EXPECT_NEAR(d->meanA, 1.0, 1e-12);
    EXPECT_NEAR(d->meanB, 1.0, 1e-12);
}

TEST(CompareImages, EveryChannelCounts) {
    // A difference only in alpha is still a difference.
    ImageF a = constant(2, 2, 4, 0.0f);
    ImageF b = a;
    for (size_t p = 0; p < 4; ++p) b.pixels[p * 4 + 3] = 2.0f;
    auto d = compareImages(a, b);
    ASSERT_TRUE(d) << d.message();
    EXPECT_NEAR(d->rmse, 1.0, 1e-12);  // sqrt(4 · 2² / 16)
    EXPECT_NEAR(d->meanB, 0.5, 1e-12);
}

TEST(CompareImages, TheTrimmedRelMseLeavesOutTheLargestThousandth) {
    // 100×100 pixels, each off by 0.1 in one channel against a reference of 0 (relative term
    // 0.01/0.01 = 1), and ten fireflies of 100 (term 10⁶): relMse is dominated by the ten; the
    // trimmed figure leaves out the 10 largest of 10,000 pixels and sees only the 1s.
    ImageF reference = constant(100, 100, 3, 0.0f);
    ImageF image = reference;
    for (size_t p = 0; p < 10000; ++p) image.pixels[p * 3] = p % 1000 == 7 ? 100.0f : 0.1f;
    auto d = compareImages(image, reference);
    ASSERT_TRUE(d) << d.message();
    // (0.1f)² / 0.01 is 1 to float's precision, 1e-7.
    EXPECT_NEAR(d->relMse, (9990.0 * 1.0 + 10.0 * 1e6) / 30000.0, 1e-6 * d->relMse);
    EXPECT_NEAR(d->relMseTrimmed, 9990.0 / (9990.0 * 3.0), 1e-6);
    // Without fireflies the two differ only by the thousandth left out.
    for (size_t p = 0; p < 10000; ++p) image.pixels[p * 3] = 0.1f;
    d = compareImages(image, reference);
    ASSERT_TRUE(d) << d.message();
    EXPECT_NEAR(d->relMseTrimmed, d->relMse, 1e-9);
}

TEST(CompareImages, RegionCountsOnlyItsPixels) {
    // A 6x4 image differing by 1 only in pixels x in [2, 4), y in [1, 3): inside that region the
    // RMSE is 1, over the whole image sqrt(4·3/72); a region off it sees no difference.
    ImageF a = constant(6, 4, 3, 0.0f);
    ImageF b = a;
    for (uint32_t y = 1; y < 3; ++y)
        for (uint32_t x = 2; x < 4; ++x)
            for (uint32_t c = 0; c < 3; ++c) b.pixels[(y * 6 + x) * 3 + c] = 1.0f;
    auto inside = compareImages(b, a, PixelRegion{2, 1, 4, 3});
    ASSERT_TRUE(inside) << inside.message();
    EXPECT_NEAR(inside->rmse, 1.0, 1e-12);
    EXPECT_EQ(inside->values, 12u);
    auto whole = compareImages(b, a);
    ASSERT_TRUE(whole);
    EXPECT_NEAR(whole->rmse, std::sqrt(12.0 / 72.0), 1e-12);
    auto outside = compareImages(b, a, PixelRegion{0, 0, 2, 4});
    ASSERT_TRUE(outside);
    EXPECT_EQ(outside->rmse, 0.0);
    EXPECT_FALSE(compareImages(b, a, PixelRegion{4, 0, 4, 4}));  // empty
    EXPECT_FALSE(compareImages(b, a, PixelRegion{0, 0, 7, 4}));  // outside
}

TEST(CompareImages, RefusesMismatchedOrNonFiniteImages) {
    EXPECT_FALSE(compareImages(constant(4, 4, 3, 0), constant(4, 3, 3, 0)));
    EXPECT_FALSE(compareImages(constant(4, 4, 3, 0), constant(4, 4, 4, 0)));
    EXPECT_FALSE(compareImages(ImageF{}, ImageF{}));
    ImageF nan = constant(2, 2, 3, 0);
    nan.pixels[7] = std::numeric_limits<float>::quiet_NaN();
    auto d = compareImages(nan, constant(2, 2, 3, 0));
    ASSERT_FALSE(d);
    EXPECT_NE(d.message().find("pixel 2, channel 1"), std::string::npos) << d.message();
}

TEST(CompareImages, ExrRoundTripKeepsTheError) {
    // What the benchmark does: both images go through OpenEXR files (float32, lossless).
    auto dir = std::filesystem::temp_directory_path() / "previs_compare_test";
    std::filesystem::create_directories(dir);
    ImageF a = constant(8, 6, 3, 0.0f);
    ImageF b = a;
    for (size_t i = 0; i < a.pixels.size(); ++i) {
        a.pixels[i] = 0.01f * float(i);
        b.pixels[i] = a.pixels[i] + (i % 3 == 0 ? 0.125f : 0.0f);
    }
    ASSERT_TRUE(writeExr((dir / "a.exr").string(), a));
    ASSERT_TRUE(writeExr((dir / "b.exr").string(), b));
    auto ra = readImage((dir / "a.exr").string());
    auto rb = readImage((dir / "b.exr").string());
    ASSERT_TRUE(ra && rb);
    auto d = compareImages(*ra, *rb);
    ASSERT_TRUE(d) << d.message();
    EXPECT_NEAR(d->rmse, 0.125 / std::sqrt(3.0), 1e-7);
    std::filesystem::remove_all(dir);
}

// Two references with independent noise of σ = 0.2 around a truth of 1; the image under test
// is the truth plus a bias of 0.1 (relMSE against the truth 0.01/1.01). The net estimate
// recovers it within five standard errors (over 3·10⁴ values the per-value term's spread is
// about 0.05: a standard error of 0.0003); relMSE against either reference is dominated by the
// reference's noise (0.04/1.01).
TEST(CompareWithPairedReference, TakesTheReferencesNoiseOut) {
    ImageF truth = constant(100, 100, 3, 1.0f);
    ImageF b = truth, twin = truth, a = truth;
    std::mt19937 rng(7);
    std::normal_distribution<float> noise(0.0f, 0.2f);
    for (size_t i = 0; i < truth.pixels.size(); ++i) {
        b.pixels[i] += noise(rng);
        twin.pixels[i] += noise(rng);
        a.pixels[i] += 0.1f;
    }
    auto d = compareWithPairedReference(a, b, twin);
    ASSERT_TRUE(d) << d.message();
    EXPECT_NEAR(d->netRelMse, 0.01 / 1.01, 5 * 0.0003);
    EXPECT_GT(compareImages(a, b)->relMse, 4 * d->netRelMse);
    // The truth itself scores about 0 (never below it).
    auto perfect = compareWithPairedReference(truth, b, twin);
    ASSERT_TRUE(perfect);
    EXPECT_LT(perfect->netRelMse, 5 * 0.0003);
    EXPECT_GE(perfect->netRelMse, 0.0);
}

// A firefly in one reference is the pixel where the two disagree most: the trimmed figure leaves
// it out, so it is the bias' alone (0.05² over 0.5² + 0.01), but for the 24 pixels around whose
// 5×5 mean it raises (0.24 % of the image, within 1 %). Untrimmed, the firefly's own term is
// weighed by that raised mean too, so one firefly does not swamp the figure either.
TEST(CompareWithPairedReference, AFireflyInOneReferenceDoesNotSwampIt) {
    ImageF truth = constant(100, 100, 3, 0.5f);
    ImageF a = truth, b = truth, twin = truth;
    for (float& v : a.pixels) v += 0.05f;
    for (int c = 0; c < 3; ++c) b.pixels[size_t(4321) * 3 + c] = 500.0f;
    auto d = compareWithPairedReference(a, b, twin);
    ASSERT_TRUE(d) << d.message();
    EXPECT_NEAR(d->netRelMseTrimmed, 0.0025 / 0.26, 0.01 * 0.0025 / 0.26);
    EXPECT_NEAR(d->netRelMse, 0.0025 / 0.26, 0.01 * 0.0025 / 0.26);
}

TEST(CompareWithPairedReference, RefusesReferencesOfAnotherSize) {
    ImageF a = constant(4, 4, 3, 1.0f);
    EXPECT_FALSE(compareWithPairedReference(a, a, constant(4, 5, 3, 1.0f)));
    EXPECT_FALSE(compareWithPairedReference(a, constant(5, 4, 3, 1.0f), a));
}

}  // namespace
}  // namespace previs
