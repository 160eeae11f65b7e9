// Joint bilateral upsampling (render/upsample.h) and the 8-bit encode table (render/tonemap.h):
// the cases that must be exact, and the edge-keeping the plate guide is there for.
#include "render/upsample.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "render/tonemap.h"
#include "tests/support/images.h"

namespace previs {
namespace {

using testing::filledImage;

ImageF randomGuide(uint32_t w, uint32_t h, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 4.0f);
    ImageF g = filledImage(w, h, 3);
    for (float& v : g.pixels) v = u(rng);
    return g;
}

struct Size {
    uint32_t lowW, lowH, w, h;
};
// Integer and fractional ratios (640×480 at 1/3 traces 213×160).
const Size kSizes[] = {{32, 24, 64, 48}, {21, 16, 64, 48}, {16, 12, 64, 48}, {23, 17, 50, 40}};

TEST(Upsample, ConstantIsReproducedExactlyWhateverTheGuide) {
    for (const Size& s : kSizes) {
        const ImageF low = filledImage(s.lowW, s.lowH, 4, 0.3f);
        const ImageF guide = randomGuide(s.w, s.h, 7);
        for (const ImageF* g : {&guide, static_cast<const ImageF*>(nullptr)}) {
            const ImageF up = jointBilateralUpsample(low, s.w, s.h, g);
            ASSERT_EQ(up.pixels.size(), size_t(s.w) * s.h * 4);
            // The weights are normalised in double: a constant comes back bit for bit.
            for (float v : up.pixels) ASSERT_EQ(v, 0.3f) << s.lowW << "x" << s.lowH;
        }
    }
}

TEST(Upsample, LinearRampIsReproducedUnderAConstantGuide) {
    for (const Size& s : kSizes) {
        // f(u, v) = a + b·u + c·v on the low grid (pixel centres at integers).
        const double a = 0.25, b = 0.05, c = -0.03;
        ImageF low = filledImage(s.lowW, s.lowH, 1);
        for (uint32_t j = 0; j < s.lowH; ++j)
            for (uint32_t i = 0; i < s.lowW; ++i)
                low.pixels[size_t(j) * s.lowW + i] = float(a + b * i + c * j);
        const ImageF guide = filledImage(s.w, s.h, 3, 0.7f);
        const ImageF up = jointBilateralUpsample(low, s.w, s.h, &guide);
        const double sx = double(s.lowW) / s.w, sy = double(s.lowH) / s.h;
        int checked = 0;
        for (uint32_t y = 0; y < s.h; ++y)
            for (uint32_t x = 0; x < s.w; ++x) {
                const double u = (x + 0.5) * sx - 0.5, v = (y + 0.5) * sy - 0.5;
                // The cubic B-spline reaches 2 low pixels out: only there is the ramp whole.
                if (u < 1.0 || v < 1.0 || u > s.lowW - 3.0 || v > s.lowH - 3.0) continue;
                const double expected = a + b * u + c * v;
                // The low values are floats: their rounding (≤ 2⁻²⁴ relative) is all that is left.
                ASSERT_NEAR(up.pixels[size_t(y) * s.w + x], expected, 1e-6)
                    << x << "," << y << " at " << s.lowW << "x" << s.lowH;
                ++checked;
            }
        EXPECT_GT(checked, int(s.w * s.h / 4));
    }
}

TEST(Upsample, StepEdgeInTheGuideDoesNotBleed) {
    // 64×48 output, 16×12 traced (1/4): the guide and the traced signal both step at output
    // column 32 = traced column 8. Dark floor on the left (0.05), bright on the right (1.0).
    const uint32_t w = 64, h = 48, lw = 16, lh = 12;
    ImageF guide = filledImage(w, h, 3);
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x)
            for (int c = 0; c < 3; ++c)
                guide.pixels[(size_t(y) * w + x) * 3 + c] = x < 32 ? 0.05f : 1.0f;
    const float left = -0.02f, right = -0.4f;  // a shadow's difference, proportional to albedo
    ImageF low = filledImage(lw, lh, 1);
    for (uint32_t j = 0; j < lh; ++j)
        for (uint32_t i = 0; i < lw; ++i) low.pixels[size_t(j) * lw + i] = i < 8 ? left : right;
    const ImageF up = jointBilateralUpsample(low, w, h, &guide);
    const ImageF spatial = jointBilateralUpsample(low, w, h, nullptr);
    const float step = std::abs(right - left);
    float worstSpatial = 0.0f;
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            const float expected = x < 32 ? left : right;
            // ln(1/0.05) = 3 per channel: e^(−3·3²/(2·0.5²)) = e^-54, below the table's cut.
            EXPECT_NEAR(up.pixels[size_t(y) * w + x], expected, 1e-4f * step) << x << "," << y;
            worstSpatial =
                std::max(worstSpatial, std::abs(spatial.pixels[size_t(y) * w + x] - expected));
        }
    // Without the guide the same step is smeared: the test above can fail.
    EXPECT_GT(worstSpatial, 0.1f * step);
}

TEST(Upsample, ZeroNeighbourhoodStaysExactlyZero) {
    const uint32_t w = 60, h = 45, lw = 20, lh = 15;
    ImageF low = filledImage(lw, lh, 4);
    // One non-zero traced pixel at (3, 3): it reaches output pixels within 2 traced pixels.
    for (int c = 0; c < 4; ++c) low.pixels[(size_t(3) * lw + 3) * 4 + c] = 0.5f;
    const ImageF guide = randomGuide(w, h, 11);
    const ImageF up = jointBilateralUpsample(low, w, h, &guide);
    int zeros = 0;
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
            const double u = (x + 0.5) / 3.0 - 0.5, v = (y + 0.5) / 3.0 - 0.5;
            if (std::abs(u - 3.0) < 2.0 && std::abs(v - 3.0) < 2.0) continue;
            for (int c = 0; c < 4; ++c) ASSERT_EQ(up.pixels[(size_t(y) * w + x) * 4 + c], 0.0f);
            ++zeros;
        }
    EXPECT_GT(zeros, int(w * h) / 2);
}

TEST(Upsample, MaskStaysInsideZeroOne) {
    // Non-negative weights: the upsampled mask is a convex combination of the traced masks.
    std::mt19937 rng(3);
    std::bernoulli_distribution coin(0.5);
    ImageF low = filledImage(21, 16, 1);
    for (float& v : low.pixels) v = coin(rng) ? 1.0f : 0.0f;
    const ImageF guide = randomGuide(64, 48, 5);
    for (float v : jointBilateralUpsample(low, 64, 48, &guide).pixels) {
        ASSERT_GE(v, 0.0f);
        ASSERT_LE(v, 1.0f);
    }
}

// A virtual object's coverage of the box [x0, x1) × [y0, y1) (output pixels) by 16 × 16
// samples: `inside(x, y)` says whether a point is on it.
template <typename Inside>
float coverage(double x0, double y0, double x1, double y1, Inside inside) {
    int n = 0;
    for (int j = 0; j < 16; ++j)
        for (int i = 0; i < 16; ++i)
            n += inside(x0 + (x1 - x0) * (i + 0.5) / 16.0, y0 + (y1 - y0) * (j + 0.5) / 16.0);
    return float(n) / 256.0f;
}

// Traced at lw × lh for a w × h output: per traced pixel the plate-free mean of an object of
// radiance `object` over a differential `real` (a shadow), and the mask, as the path tracer's
// means with converged coverage; and the box-filtered truth at the output's resolution.
template <typename Inside>
std::pair<ImageF, ImageF> tracedAndTruth(uint32_t lw, uint32_t lh, uint32_t w, uint32_t h,
                                         Inside inside) {
    const float object = 0.3f, real = -0.05f;
    ImageF low = filledImage(lw, lh, 4), truth = filledImage(w, h, 4);
    auto fill = [&](ImageF& img, uint32_t i, uint32_t j, float m) {
        float* px = &img.pixels[(size_t(j) * img.width + i) * 4];
        for (int c = 0; c < 3; ++c) px[c] = m * object + (1.0f - m) * real;
        px[3] = m;
    };
    const double sx = double(w) / lw, sy = double(h) / lh;
    for (uint32_t j = 0; j < lh; ++j)
        for (uint32_t i = 0; i < lw; ++i)
            fill(low, i, j, coverage(i * sx, j * sy, (i + 1) * sx, (j + 1) * sy, inside));
    for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) fill(truth, x, y, coverage(x, y, x + 1, y + 1, inside));
    return {low, truth};
}

// RMS over the output pixels where the truth or the result is neither 0 nor 1 (the outline).
double outlineRms(const ImageF& up, const ImageF& truth) {
    double sum = 0.0;
    size_t n = 0;
    for (size_t i = 0; i < truth.pixels.size(); i += 4) {
        const float t = truth.pixels[i + 3], u = up.pixels[i + 3];
        if ((t == 0.0f || t == 1.0f) && (u < 1e-3f || u > 1.0f - 1e-3f)) continue;
        for (int c = 0; c < 4; ++c) sum += std::pow(up.pixels[i + c] - truth.pixels[i + c], 2.0);
        n += 4;
    }
    return n ? std::sqrt(sum / double(n)) : 0.0;
}

TEST(Upsample, AVirtualObjectsOutlineIsAsSharpAsTheOutputs) {
    // A disc the plate does not show (a constant guide), traced at 1/3 and at 1/4, and at
    // 640×480's 213×160-like fraction.
    const Size sizes[] = {{64, 48, 192, 144}, {48, 36, 192, 144}, {71, 53, 213, 160}};
    for (const Size& s : sizes) {
        auto disc = [&](double x, double y) {
            return std::hypot(x - 0.52 * s.w, y - 0.47 * s.h) < 0.3 * s.h;
        };
        auto [low, truth] = tracedAndTruth(s.lowW, s.lowH, s.w, s.h, disc);
        const ImageF guide = filledImage(s.w, s.h, 3, 0.7f);
        UpsampleSettings blurred;
        blurred.outlineSharpening = 0.0f;
        const double sharp = outlineRms(jointBilateralUpsample(low, s.w, s.h, &guide), truth);
        const double before =
            outlineRms(jointBilateralUpsample(low, s.w, s.h, &guide, blurred), truth);
        std::printf("%ux%u from %ux%u: outline RMS %.4f sharpened, %.4f not\n", s.w, s.h, s.lowW,
                    s.lowH, sharp, before);
        EXPECT_LT(sharp, 0.5 * before) << s.lowW << "x" << s.lowH;
    }
}

TEST(Upsample, DetailFinerThanATracedPixelIsKept) {
    // A vertical wire one output pixel wide, traced at 1/3: no traced pixel is mostly on it, so
    // there is no outline to steepen and the wire comes out exactly as without sharpening.
    const uint32_t w = 192, h = 144, lw = 64, lh = 48;
    auto wire = [](double x, double) { return x >= 96.0 && x < 97.0; };
    auto [low, truth] = tracedAndTruth(lw, lh, w, h, wire);
    const ImageF guide = filledImage(w, h, 3, 0.7f);
    UpsampleSettings blurred;
    blurred.outlineSharpening = 0.0f;
    const ImageF up = jointBilateralUpsample(low, w, h, &guide);
    EXPECT_EQ(up.pixels, jointBilateralUpsample(low, w, h, &guide, blurred).pixels);
    double kept = 0.0;
    for (size_t i = 3; i < up.pixels.size(); i += 4) kept += up.pixels[i];
    EXPECT_GT(kept, 0.9 * h);  // the B-spline's sampling keeps about all of it
}

int referenceCode(float v) { return int(std::lround(srgbEncode(v) * 255.0f)); }

TEST(EncodeSrgb8, EqualsTheRoundedEncodeAtEveryStepAndElsewhere) {
    // Around every value where the code steps (found by scanning a dense grid), ±64 floats.
    int steps = 0;
    for (int k = 1; k < 4096 * 64; ++k) {
        const float a = float(k - 1) / (4096 * 64), b = float(k) / (4096 * 64);
        if (referenceCode(a) == referenceCode(b)) continue;
        ++steps;
        float v = b;
        for (int n = 0; n < 64; ++n) v = std::nextafter(v, 0.0f);
        for (int n = 0; n < 128; ++n, v = std::nextafter(v, 2.0f))
            ASSERT_EQ(encodeSrgb8(v), referenceCode(v)) << v;
    }
    EXPECT_EQ(steps, 255);
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> u(-0.5f, 1.5f);
    for (int i = 0; i < 1000000; ++i) {
        const float v = u(rng);
        ASSERT_EQ(encodeSrgb8(v), referenceCode(v)) << v;
    }
    for (float v : {0.0f, -0.0f, 1.0f, 1e-30f, std::nanf(""), INFINITY, -INFINITY})
        EXPECT_EQ(encodeSrgb8(v), referenceCode(v)) << v;
}

}  // namespace
}  // namespace previs
