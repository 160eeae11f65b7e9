// Inverse tone mapping (vision/inverse_tone_map.h) against the forward operators it inverts
// (render/tonemap.h): round trips over the whole 8-bit and float range, finiteness at the ends,
// monotonicity, and the Banterle inverse's bounded slope where the naive Reinhard inverse diverges.

#include "vision/inverse_tone_map.h"

#include <fmt/format.h>
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "render/tonemap.h"

namespace previs {
namespace {

constexpr float kEps = std::numeric_limits<float>::epsilon();

// One forward operator and its inverse, with the parameters they share.
struct OperatorPair {
    std::string name;
    ToneMapSettings forward;
    InverseToneMapSettings inverse;
    // Largest linear display luminance the inverse reproduces (Reinhard clamps above its
    // maxDisplayLuminance so that its radiance stays finite).
    float maxInvertibleDisplay;
};

OperatorPair makePair(const std::string& name, float exposureStops, float maxRadiance = 16.0f,
                      float whiteLuminance = 16.0f) {
    OperatorPair p{name, {}, {}, 1.0f};
    p.forward.op = *parseToneMapOperator(name);
    p.inverse.op = *parseInverseToneMapOperator(name);
    p.forward.exposureStops = p.inverse.exposureStops = exposureStops;
    p.forward.maxRadiance = p.inverse.maxRadiance = maxRadiance;
    p.forward.whiteLuminance = p.inverse.whiteLuminance = whiteLuminance;
    if (p.inverse.op == InverseToneMapOperator::Reinhard)
        p.maxInvertibleDisplay = p.inverse.maxDisplayLuminance;
    return p;
}

// Every operator, at exposures 0 and ±2 stops, and Banterle at non-default shapes (expanding,
// linear, strongly compressing).
std::vector<OperatorPair> allPairs() {
    std::vector<OperatorPair> pairs;
    for (float e : {0.0f, 2.0f, -2.0f}) {
        pairs.push_back(makePair("clamp", e));
        pairs.push_back(makePair("reinhard", e));
        pairs.push_back(makePair("reinhard-extended", e));
    }
    pairs.push_back(makePair("reinhard-extended", 0.0f, 100.0f, 4.0f));
    pairs.push_back(makePair("reinhard-extended", 0.0f, 8.0f, 1.0f));
    pairs.push_back(makePair("reinhard-extended", 0.0f, 2.0f, 0.5f));
    pairs.push_back(makePair("reinhard-extended", 0.0f, 1000.0f, 64.0f));
    return pairs;
}

std::string describe(const OperatorPair& p) {
    return fmt::format("{} exposure {} Lmax {} Lwhite {}", p.name, p.forward.exposureStops,
                       p.forward.maxRadiance, p.forward.whiteLuminance);
}

float luminance(const std::array<float, 3>& c) {
    return 0.2126f * c[0] + 0.7152f * c[1] + 0.0722f * c[2];
}

float relativeError(float value, float expected) {
    return std::abs(value - expected) / std::max(std::abs(expected), 1e-30f);
}

// d L_w / d L_d relative to L_w / L_d: how much the inverse magnifies a relative error of its
// input, analytically. radiance → display → radiance cannot be more accurate than this times the
// float rounding of the display value; display → radiance → display divides errors by it.
double inverseCondition(const OperatorPair& p, double ld) {
    switch (p.inverse.op) {
        case InverseToneMapOperator::Srgb:
            return 1.0;
        case InverseToneMapOperator::Reinhard:
            return 1.0 / (1.0 - ld);
        case InverseToneMapOperator::Banterle: {
            const double w = p.inverse.whiteLuminance;
            const double a = 1.0 - ld;
            const double l = 0.5 * w * w * (std::sqrt(a * a + 4.0 * ld / (w * w)) - a);
            const double slope =
                (1.0 + 2.0 * l / (w * w) + l * l / (w * w)) / ((1.0 + l) * (1.0 + l));
            return ld > 0.0 ? (ld / l) / slope : 1.0;
        }
    }
    return 1.0;
}

// The paper's formula as printed (Banterle et al. 2006), in long double, to check the conjugate
// rewrite the implementation uses.
long double banterlePaper(long double ld, long double lmax, long double lwhite) {
    return 0.5L * lmax * lwhite *
           (ld - 1.0L + std::sqrt((1.0L - ld) * (1.0L - ld) + 4.0L * ld / (lwhite * lwhite)));
}

std::array<float, 3> grey(float v) { return {v, v, v}; }

// ---- the curves --------------------------------------------------------------------------------

TEST(InverseToneMapCurves, BanterleMatchesThePaperAndInvertsReinhardExtended) {
    for (auto [lmax, lwhite] :
         {std::pair{16.0f, 16.0f}, {100.0f, 4.0f}, {8.0f, 1.0f}, {2.0f, 0.5f}, {1000.0f, 64.0f}}) {
        SCOPED_TRACE(fmt::format("Lmax {} Lwhite {}", lmax, lwhite));
        // Endpoints: black stays black, display white is exactly the peak radiance.
        EXPECT_EQ(banterleInverseCurve(0.0f, lmax, lwhite), 0.0f);
        EXPECT_FLOAT_EQ(banterleInverseCurve(1.0f, lmax, lwhite), lmax);
        EXPECT_FLOAT_EQ(reinhardExtendedCurve(lmax, lmax, lwhite), 1.0f);
        double worst = 0.0;
        for (int i = 1; i <= 100000; ++i) {
            const float ld = float(i) / 100000.0f;
            const float lw = banterleInverseCurve(ld, lmax, lwhite);
            // The conjugate form agrees with the paper's formula evaluated in long double.
            const long double paper = banterlePaper(ld, lmax, lwhite);
            worst = std::max(worst, double(std::abs(lw - paper) / paper));
            // display → radiance → display: the forward curve shrinks the inverse's error.
            EXPECT_LT(relativeError(reinhardExtendedCurve(lw, lmax, lwhite), ld), 1e-5f) << ld;
        }
        EXPECT_LT(worst, 1e-6) << "conjugate form vs paper";
        // Small display values, where the paper's form cancels catastrophically in float.
        for (float ld = 1e-8f; ld < 1e-2f; ld *= 1.5f) {
            const float lw = banterleInverseCurve(ld, lmax, lwhite);
            EXPECT_LT(double(std::abs(lw - banterlePaper(ld, lmax, lwhite)) /
                             banterlePaper(ld, lmax, lwhite)),
                      1e-6)
                << ld;
        }
    }
}

// The inverse's slope is finite everywhere, and bounded by L_max · max((1 + L_white)/2, 1/L_white)
// (the forward slope (1 + (L_white² − 1)/(1 + L)²)/L_white² · L_white/L_max is smallest at L_d = 1
// for L_white ≥ 1 and at L_d = 0 for L_white < 1). The naive inverse L_d/(1 − L_d) has slope
// 1/(1 − L_d)², unbounded, and is infinite at L_d = 1.
TEST(InverseToneMapCurves, BanterleSlopeIsBoundedWhereTheNaiveInverseDiverges) {
    auto naive = [](double ld) { return ld / (1.0 - ld); };
    EXPECT_TRUE(std::isinf(naive(1.0)));
    for (auto [lmax, lwhite] : {std::pair{16.0f, 16.0f}, {100.0f, 4.0f}, {2.0f, 0.5f}}) {
        SCOPED_TRACE(fmt::format("Lmax {} Lwhite {}", lmax, lwhite));
        const double bound = lmax * std::max((1.0 + lwhite) / 2.0, 1.0 / lwhite);
        const int n = 1 << 16;
        const double h = 1.0 / n;
        double maxSlope = 0.0;
        float previous = banterleInverseCurve(0.0f, lmax, lwhite);
        for (int i = 1; i <= n; ++i) {
            const float lw = banterleInverseCurve(float(i * h), lmax, lwhite);
            ASSERT_TRUE(std::isfinite(lw));
            maxSlope = std::max(maxSlope, (double(lw) - previous) / h);
            previous = lw;
        }
        // Finite differences of a float curve: allow the rounding of two values over h.
        EXPECT_LE(maxSlope, bound * (1.0 + 1e-3) + 4.0 * kEps * lmax / h);
        // The bound is attained (at L_d = 1 or 0), so it is the right one, not a loose one.
        EXPECT_GT(maxSlope, 0.99 * bound);
        // Over the last 8-bit step (linear display 0.991 → 1) the radiance rises by a bounded,
        // small fraction of L_max; the naive inverse goes from ~110 to infinity.
        const float d254 = srgbDecode(254.0f / 255.0f);
        const float step =
            banterleInverseCurve(1.0f, lmax, lwhite) - banterleInverseCurve(d254, lmax, lwhite);
        EXPECT_LE(step, bound * (1.0f - d254) * 1.001f);
        EXPECT_GT(naive(d254), 100.0);
        EXPECT_GT(naive(1.0 - 1e-6), 1e5);
        EXPECT_GT((naive(1.0 - 1e-6) - naive(1.0 - 2e-6)) / 1e-6, 1e11);  // slope blows up
    }
}

// ---- whole operators through the public API ----------------------------------------------------

// decode → inverse → forward → encode returns the same 8-bit code, for every grey code and a
// 52³ grid of colours (every 5th code per channel), for every operator. Reinhard only where
// its inverse is not clamped (linear display luminance ≤ 0.99: codes ≤ 253 for grey).
TEST(InverseToneMap, EightBitCodesRoundTripExactly) {
    for (const OperatorPair& p : allPairs()) {
        SCOPED_TRACE(describe(p));
        int failures = 0, tested = 0;
        auto check = [&](int r, int g, int b) {
            const std::array<float, 3> encoded{r / 255.0f, g / 255.0f, b / 255.0f};
            const float ld =
                luminance({srgbDecode(encoded[0]), srgbDecode(encoded[1]), srgbDecode(encoded[2])});
            if (ld > p.maxInvertibleDisplay) return;
            ++tested;
            const auto back = toneMapRgb(inverseToneMapRgb(encoded, p.inverse), p.forward);
            const std::array<int, 3> want{r, g, b};
            for (int c = 0; c < 3; ++c) {
                if (std::lround(back[c] * 255.0f) != want[c] && ++failures <= 5)
                    ADD_FAILURE() << fmt::format("code ({},{},{}) channel {} → {}", r, g, b, c,
                                                 back[c] * 255.0f);
            }
        };
        for (int v = 0; v < 256; ++v) check(v, v, v);
        for (int r = 0; r < 256; r += 5)
            for (int g = 0; g < 256; g += 5)
                for (int b = 0; b < 256; b += 5) check(r, g, b);
        EXPECT_EQ(failures, 0);
        // Reinhard's clamp excludes exactly the top grey codes; the others test the full range.
        EXPECT_GE(tested, p.inverse.op == InverseToneMapOperator::Reinhard
                              ? 256 + 52 * 52 * 52 - 100
                              : 256 + 52 * 52 * 52);
    }
}

// Floats, display side: encoded e → inverse → forward gives e back within relative 1e-5, for
// grey and coloured pixels over a dense sweep of [0, 1] plus a log sweep down to 1e-7.
TEST(InverseToneMap, DisplayValuesRoundTripInFloat) {
    std::vector<float> sweep;
    for (int i = 0; i <= 20000; ++i) sweep.push_back(float(i) / 20000.0f);
    for (float v = 1e-7f; v < 1e-3f; v *= 1.2f) sweep.push_back(v);
    for (const OperatorPair& p : allPairs()) {
        SCOPED_TRACE(describe(p));
        float worst = 0.0f;
        for (float v : sweep) {
            for (const std::array<float, 3>& encoded :
                 {grey(v), std::array<float, 3>{v, 0.5f * v, 0.1f * v},
                  std::array<float, 3>{0.2f * v, v, 0.7f * v}}) {
                const float ld = luminance(
                    {srgbDecode(encoded[0]), srgbDecode(encoded[1]), srgbDecode(encoded[2])});
                if (ld > p.maxInvertibleDisplay) continue;
                const auto back = toneMapRgb(inverseToneMapRgb(encoded, p.inverse), p.forward);
                for (int c = 0; c < 3; ++c) {
                    if (encoded[c] == 0.0f) {
                        EXPECT_EQ(back[c], 0.0f);
                        continue;
                    }
                    worst = std::max(worst, relativeError(back[c], encoded[c]));
                }
            }
        }
        EXPECT_LT(worst, 1e-5f);
    }
}

// Floats, radiance side: radiance → forward → inverse gives it back, over a log sweep from 1e-6
// to the largest radiance each operator keeps below display white (L_max for ReinhardExtended,
// 99 for Reinhard, 1 for Clamp). This direction multiplies the float rounding of the display
// value by the inverse's condition number (inverseCondition; (1 + L_white)/2 = 8.5 for Banterle's
// defaults at white, up to 100 for Reinhard at its clamp): the tolerance is 1e-5, or 32 ulp of
// that magnification where it is larger (two sRGB transfers and the curve, a few ulp each).
TEST(InverseToneMap, RadianceRoundTripsInFloat) {
    for (const OperatorPair& p : allPairs()) {
        SCOPED_TRACE(describe(p));
        const float exposure = std::exp2(p.forward.exposureStops);
        float top = 1.0f;
        if (p.forward.op == ToneMapOperator::Reinhard)
            top = p.inverse.maxDisplayLuminance / (1.0f - p.inverse.maxDisplayLuminance);
        if (p.forward.op == ToneMapOperator::ReinhardExtended) top = p.forward.maxRadiance;
        top = top / exposure * (1.0f - 1e-6f);
        int failures = 0;
        for (double x = 1e-6; x <= top; x *= 1.001) {
            const std::array<float, 3> radiance{float(x), float(x), float(x)};
            const auto display = toneMapRgb(radiance, p.forward);
            const auto back = inverseToneMapRgb(display, p.inverse);
            const double cond = inverseCondition(p, srgbDecode(display[1]));
            const float tol = float(std::max(1e-5, 32.0 * kEps * cond));
            if (relativeError(back[1], radiance[1]) >= tol && ++failures <= 5)
                ADD_FAILURE() << fmt::format("radiance {} → {} (tolerance {})", x, back[1], tol);
        }
        EXPECT_EQ(failures, 0);
        // Coloured: colour ratios survive (the curves act on luminance only) as long as no channel
        // leaves the display gamut. A saturated colour can clip a channel at 1 below L_max (its
        // display channel is rgb·L_d/L > L_d): that pixel does not round trip, by construction.
        std::array<float, 3> colour{0.5f * top, 0.33f * top, 0.08f * top};
        while (toneMapRgb(colour, p.forward)[0] > 0.95f)
            for (float& c : colour) c *= 0.5f;
        const auto back = inverseToneMapRgb(toneMapRgb(colour, p.forward), p.inverse);
        for (int c = 0; c < 3; ++c) EXPECT_LT(relativeError(back[c], colour[c]), 1e-5f);
    }
}

// Every grey code and every float in [0, 1], through all three entry points (one pixel, ImageF,
// 8-bit cv::Mat), gives finite, non-negative, non-decreasing radiance; Srgb and Banterle strictly
// increasing. Code 0 is black; code 255 is finite (Banterle: exactly L_max).
TEST(InverseToneMap, FiniteAndMonotonicOverTheWholeRange) {
    for (const OperatorPair& p : allPairs()) {
        SCOPED_TRACE(describe(p));
        const bool strict = p.inverse.op != InverseToneMapOperator::Reinhard;
        cv::Mat codes(1, 256, CV_8UC3);
        ImageF image;
        image.width = 256;
        image.height = 1;
        image.channels = 3;
        image.ldrSrgb = true;
        for (int v = 0; v < 256; ++v) {
            codes.at<cv::Vec3b>(0, v) = cv::Vec3b(v, v, v);
            for (int c = 0; c < 3; ++c) image.pixels.push_back(v / 255.0f);
        }
        const cv::Mat fromMat = inverseToneMapRgb8(codes, p.inverse);
        const ImageF fromImage = inverseToneMap(image, p.inverse);
        float previous = -1.0f;
        for (int v = 0; v < 256; ++v) {
            const auto px = inverseToneMapRgb(grey(v / 255.0f), p.inverse);
            for (int c = 0; c < 3; ++c) {
                ASSERT_TRUE(std::isfinite(px[c])) << v;
                EXPECT_GE(px[c], 0.0f);
                // The three entry points agree (the 8-bit table holds the same sRGB decode).
                EXPECT_FLOAT_EQ(fromMat.at<cv::Vec3f>(0, v)[c], px[c]) << v;
                EXPECT_FLOAT_EQ(fromImage.pixels[3 * v + c], px[c]) << v;
            }
            if (strict) {
                EXPECT_GT(px[1], previous) << v;
            } else {
                EXPECT_GE(px[1], previous) << v;
            }
            previous = px[1];
        }
        EXPECT_EQ(inverseToneMapRgb(grey(0.0f), p.inverse)[1], 0.0f);
        const float white = inverseToneMapRgb(grey(1.0f), p.inverse)[1];
        if (p.inverse.op == InverseToneMapOperator::Banterle) {
            EXPECT_FLOAT_EQ(white, p.inverse.maxRadiance / std::exp2(p.inverse.exposureStops));
        }
        // Dense float sweep, and inputs a broken decoder might produce.
        previous = -1.0f;
        for (int i = 0; i <= 100000; ++i) {
            const float v = inverseToneMapRgb(grey(float(i) / 100000.0f), p.inverse)[1];
            ASSERT_TRUE(std::isfinite(v)) << i;
            EXPECT_GE(v, previous) << i;
            previous = v;
        }
        for (float bad : {std::nanf(""), INFINITY, -INFINITY, -1.0f, 2.0f})
            for (float v : inverseToneMapRgb(grey(bad), p.inverse)) EXPECT_TRUE(std::isfinite(v));
        // The forward operator is monotonic too, and finite at 0 and for huge radiance. Reinhard's
        // rgb · 1/(1 + L), two roundings, can step back by an ulp or two where it flattens
        // (L ~ 1e5): allowed, 4 ulp, invisible after 8-bit quantisation.
        float previousDisplay = -1.0f;
        for (double x = 1e-6; x < 1e6; x *= 1.01) {
            const float d = toneMapRgb(grey(float(x)), p.forward)[1];
            ASSERT_TRUE(std::isfinite(d));
            EXPECT_GE(d, previousDisplay * (1.0f - 4.0f * kEps)) << x;
            previousDisplay = d;
        }
        EXPECT_EQ(toneMapRgb(grey(0.0f), p.forward)[1], 0.0f);
    }
}

TEST(InverseToneMap, OperatorNames) {
    EXPECT_EQ(parseInverseToneMapOperator("banterle"), InverseToneMapOperator::Banterle);
    EXPECT_EQ(parseInverseToneMapOperator("reinhard-extended"), InverseToneMapOperator::Banterle);
    EXPECT_EQ(parseInverseToneMapOperator("reinhard"), InverseToneMapOperator::Reinhard);
    EXPECT_EQ(parseInverseToneMapOperator("srgb"), InverseToneMapOperator::Srgb);
    EXPECT_FALSE(parseInverseToneMapOperator("Banterle"));
    EXPECT_EQ(parseToneMapOperator("reinhard-extended"), ToneMapOperator::ReinhardExtended);
    EXPECT_EQ(parseToneMapOperator("reinhard"), ToneMapOperator::Reinhard);
    // One curve name for both directions (--tone-curve): each inverse's name selects its forward
    // operator, and every forward name its inverse.
    EXPECT_EQ(parseToneMapOperator("banterle"), ToneMapOperator::ReinhardExtended);
    EXPECT_EQ(parseToneMapOperator("srgb"), ToneMapOperator::Clamp);
    EXPECT_EQ(parseInverseToneMapOperator("clamp"), InverseToneMapOperator::Srgb);
    EXPECT_FALSE(parseToneMapOperator("Banterle"));
    EXPECT_FALSE(parseToneMapOperator("aces"));
}

// toneMapToSrgb8 (the PNG writer's path) is toneMapRgb rounded, for the new operator too.
TEST(ToneMap, EightBitWriterMatchesTheFloatPath) {
    ImageF image;
    image.width = 64;
    image.height = 1;
    image.channels = 4;
    for (int i = 0; i < 64; ++i) {
        const float x = std::exp2(float(i) / 4.0f - 10.0f);
        for (float v : {x, 0.5f * x, 0.2f * x, 1.0f}) image.pixels.push_back(v);
    }
    ToneMapSettings s{.exposureStops = 1.0f, .op = ToneMapOperator::ReinhardExtended};
    const auto bytes = toneMapToSrgb8(image, s);
    for (int i = 0; i < 64; ++i) {
        const float* px = image.pixels.data() + 4 * i;
        const auto d = toneMapRgb({px[0], px[1], px[2]}, s);
        for (int c = 0; c < 3; ++c) EXPECT_EQ(bytes[3 * i + c], std::lround(d[c] * 255.0f));
    }
}

}  // namespace
}  // namespace previs
