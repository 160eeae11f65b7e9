// glTF sampler addressing (shared/texture_sampling.h, the code the shader runs) against the
// OpenGL definitions glTF refers to, computed here in 64-bit integers and doubles: REPEAT takes
// the texel index modulo the size, MIRRORED_REPEAT modulo twice the size and mirrored in the
// second half, CLAMP_TO_EDGE clamps it. Coordinates include negative ones and offsets up to 1e7;
// any coordinate, however huge or non-finite, must give an index inside the image.
#include "gpu/shaders/shared/texture_sampling.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <vector>

namespace previs::shader {
namespace {

const uint32_t kModes[] = {PV_WRAP_REPEAT, PV_WRAP_MIRRORED_REPEAT, PV_WRAP_CLAMP_TO_EDGE};

// OpenGL 4.6 §8.14.2, on the integer texel index i = floor(u · size).
int64_t referenceWrap(int64_t i, int64_t size, uint32_t mode) {
    auto mod = [](int64_t a, int64_t m) { return ((a % m) + m) % m; };
    if (mode == PV_WRAP_CLAMP_TO_EDGE) return std::min(std::max(i, int64_t(0)), size - 1);
    if (mode == PV_WRAP_MIRRORED_REPEAT) {
        const int64_t m = mod(i, 2 * size);
        return m < size ? m : 2 * size - 1 - m;
    }
    return mod(i, size);
}

// Coordinates inside texels (never within 1/(8·size) of a texel edge, where float rounding may
// legitimately pick either neighbour), offset by whole numbers up to ±4096 (where a float still
// holds the fraction exactly) and by the integers 1e7 and 1e7 + 1 themselves.
std::vector<double> testCoordinates(int size) {
    std::vector<double> out;
    for (double offset : {-4096.0, -3.0, -1.0, 0.0, 1.0, 2.0, 3.0, 4095.0}) {
        for (int j = 0; j < 8 * size; ++j) {
            const double u = offset + (j + 0.5) / (8.0 * size);
            if (double(float(u)) == u) out.push_back(u);
        }
    }
    return out;
}

TEST(TextureSampling, NearestMatchesOpenGlDefinitions) {
    for (int size : {1, 2, 3, 4, 7, 64}) {
        for (uint32_t mode : kModes) {
            for (double u : testCoordinates(size)) {
                const int got = nearestTexel(float(u), size, mode);
                const int64_t want = referenceWrap(int64_t(std::floor(u * size)), size, mode);
                ASSERT_EQ(got, want) << "u " << u << " size " << size << " mode " << mode;
            }
            // Whole-number coordinates far out: the left edge of a period (or of its mirror).
            for (double u : {1e7, 1e7 + 1.0, -1e7, -1e7 - 1.0, 16777216.0}) {
                ASSERT_EQ(double(float(u)), u);
                const int got = nearestTexel(float(u), size, mode);
                const int64_t want = referenceWrap(int64_t(std::floor(u * size)), size, mode);
                ASSERT_EQ(got, want) << "u " << u << " size " << size << " mode " << mode;
            }
        }
    }
}

TEST(TextureSampling, BilinearTexelsAndWeightsMatchOpenGl) {
    for (int size : {1, 2, 5, 16}) {
        for (uint32_t mode : kModes) {
            for (double u : testCoordinates(size)) {
                int i0 = -1, i1 = -1;
                float w1 = -1.0f;
                linearTexels(float(u), size, mode, i0, i1, w1);
                // Texel centres at (i + 0.5) / size; clamping first for CLAMP_TO_EDGE.
                const double c =
                    mode == PV_WRAP_CLAMP_TO_EDGE ? std::min(std::max(u, 0.0), 1.0) : u;
                const double p = c * size - 0.5;
                const int64_t i = int64_t(std::floor(p));
                EXPECT_EQ(i0, referenceWrap(i, size, mode)) << u;
                EXPECT_EQ(i1, referenceWrap(i + 1, size, mode)) << u;
                EXPECT_NEAR(w1, p - std::floor(p), 1e-4) << u;
            }
        }
    }
}

// GLSL's % is undefined for negative operands and int(u · size) overflows past 2^31: neither may
// reach the texel fetch. Every coordinate a float can hold gives an index in [0, size) and a
// weight in [0, 1].
TEST(TextureSampling, AnyCoordinateStaysInsideTheImage) {
    const float inf = std::numeric_limits<float>::infinity();
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::vector<float> extremes = {0.0f,
                                   -0.0f,
                                   1.0f,
                                   -1e-9f,
                                   1e-9f,
                                   1e7f,
                                   -1e7f,
                                   3e9f,
                                   -3e9f,
                                   1e30f,
                                   -1e30f,
                                   3.4e38f,
                                   -3.4e38f,
                                   inf,
                                   -inf,
                                   nan,
                                   std::numeric_limits<float>::denorm_min()};
    for (int k = -40; k <= 40; ++k) extremes.push_back(std::ldexp(1.37f, k) * (k % 2 ? -1 : 1));
    for (int size : {1, 3, 64, 16384}) {
        for (uint32_t mode : kModes) {
            for (float u : extremes) {
                const int n = nearestTexel(u, size, mode);
                EXPECT_GE(n, 0) << u;
                EXPECT_LT(n, size) << u;
                int i0 = -1, i1 = -1;
                float w1 = -1.0f;
                linearTexels(u, size, mode, i0, i1, w1);
                EXPECT_GE(i0, 0) << u;
                EXPECT_LT(i0, size) << u;
                EXPECT_GE(i1, 0) << u;
                EXPECT_LT(i1, size) << u;
                EXPECT_GE(w1, 0.0f) << u;
                EXPECT_LE(w1, 1.0f) << u;
            }
        }
    }
}

}  // namespace
}  // namespace previs::shader
