// The path tracer's sample generator (gpu/shaders/shared/sampler.h) run on the CPU: the Sobol'
// matrices against Joe & Kuo's primitive polynomials, the stratification Owen scrambling must
// keep (exact net properties, not statistics), the range of the values, and the randomisation
// that makes the estimates unbiased and the pixels independent.
#include "gpu/shaders/shared/sampler.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "tests/support/chi2.h"

namespace previs::testing {
namespace {

using namespace previs::shader;

// Column k of the generator matrix of Sobol' dimension `dim` (1-3), bit-reversed as
// sobolReversed4 stores it, rebuilt from Joe & Kuo's (new-joe-kuo-6.21201) degree s, polynomial
// coefficients a and initial direction integers m by Bratley & Fox's recurrence
// m_k = 2 a_1 m_{k-1} ⊕ … ⊕ 2^{s-1} a_{s-1} m_{k-s+1} ⊕ 2^s m_{k-s} ⊕ m_{k-s};
// direction number v_k = m_k / 2^{k+1}.
uint32_t joeKuoColumn(int dim, int k) {
    struct Poly {
        int s;
        uint32_t a;
        std::vector<uint32_t> m;
    };
    const Poly polys[] = {{1, 0, {1}}, {2, 1, {1, 3}}, {3, 1, {1, 3, 1}}};
    Poly p = polys[dim - 1];
    std::vector<uint32_t> m = p.m;
    for (int i = p.s; i <= k; ++i) {
        uint32_t v = m[i - p.s] ^ (m[i - p.s] << p.s);
        for (int j = 1; j < p.s; ++j)
            if ((p.a >> (p.s - 1 - j)) & 1u) v ^= m[i - j] << j;
        m.push_back(v);
    }
    uint32_t value = m[k] << (31 - k);  // v_k as a 32-bit fixed-point fraction
    uint32_t reversed = 0;
    for (int b = 0; b < 32; ++b) reversed |= ((value >> b) & 1u) << (31 - b);
    return reversed;
}

TEST(SobolTest, MatricesAreJoeKuos) {
    for (int k = 0; k < int(PV_SOBOL_BITS); ++k) {
        uvec4 c = sobolReversed4(1u << k);
        EXPECT_EQ(c.x, 1u << k) << "dimension 0 (van der Corput), column " << k;
        EXPECT_EQ(c.y, joeKuoColumn(1, k)) << "dimension 1, column " << k;
        EXPECT_EQ(c.z, joeKuoColumn(2, k)) << "dimension 2, column " << k;
        EXPECT_EQ(c.w, joeKuoColumn(3, k)) << "dimension 3, column " << k;
    }
    // Linearity over GF(2): the point of a sum of bits is the xor of the columns.
    EXPECT_EQ(sobolReversed4(0x5a5au).w, sobolReversed4(0x5a00u).w ^ sobolReversed4(0x005au).w);
}

// The digits of a value in [0, 1) above 2^-bits, exactly (the values are multiples of 2^-24).
uint32_t cell(float v, int bits) { return bits == 0 ? 0u : uint32_t(std::ldexp(double(v), bits)); }

// True when the points are a (0, m, 2)-net in base 2: for every split k + l = m each of the
// 2^m elementary intervals [a/2^k, (a+1)/2^k) × [b/2^l, (b+1)/2^l) holds exactly one point.
bool isNet2D(const std::vector<vec2>& pts, int m) {
    for (int k = 0; k <= m; ++k) {
        std::vector<int> count(size_t(1) << m, 0);
        for (vec2 p : pts) {
            uint32_t idx = (cell(p.x, k) << (m - k)) | cell(p.y, m - k);
            if (++count[idx] != 1) return false;
        }
    }
    return true;
}

bool isNet1D(const std::vector<float>& values, int m) {
    std::vector<int> count(size_t(1) << m, 0);
    for (float v : values)
        if (++count[cell(v, m)] != 1) return false;
    return true;
}

// Every aligned power-of-two block of samples is a (0,m,2)-net in each set's .xy and stratifies
// .z and .w, for any pixel, seed and set — also the first block of the second 2^16 samples, whose
// scramble is new — in each replicate (the interleaved halves). Exact: no point may share an
// elementary interval with another.
TEST(SobolTest, EveryPowerOfTwoBlockIsANetInEachSet) {
    const uint32_t pixels[] = {0u, 1u, 641u, 307199u};
    const uint32_t sets[] = {PV_SET_CAMERA_JITTER, PV_SET_CAMERA_LENS,
                             vertexSet(0, PV_SET_VERTEX_EMISSIVE),
                             vertexSet(3, PV_SET_VERTEX_BSDF)};
    for (uint32_t replicate = 0; replicate < PV_MAX_REPLICATES; ++replicate)
        for (uint32_t pixel : pixels) {
            for (uint32_t set : sets) {
                for (int m = 0; m <= 12; ++m) {
                    const uint32_t n = 1u << m;
                    for (uint32_t first : {0u, 5u * n, 1u << 16}) {
                        std::vector<vec2> xy;
                        std::vector<float> z, w;
                        for (uint32_t i = first; i < first + n; ++i) {
                            vec4 u = sobolSet(makeSampleKey(pixel, i, 7u, replicate), set);
                            xy.push_back(vec2(u.x, u.y));
                            z.push_back(u.z);
                            w.push_back(u.w);
                        }
                        ASSERT_TRUE(isNet2D(xy, m)) << "pixel " << pixel << " set " << set << " 2^"
                                                    << m << " samples from " << first;
                        ASSERT_TRUE(isNet1D(z, m)) << "z, set " << set << " 2^" << m;
                        ASSERT_TRUE(isNet1D(w, m)) << "w, set " << set << " 2^" << m;
                    }
                }
            }
        }
}

// Values stay in [0, 1), up to the largest fraction; both generators and the deep-vertex fallback.
TEST(SamplerTest, ValuesAreInTheUnitInterval) {
    EXPECT_LT(fractionToFloat(0xffffffffu), 1.0f);
    EXPECT_EQ(fractionToFloat(0u), 0.0f);
    float lo = 1.0f, hi = 0.0f;
    for (uint32_t generator : {PV_SAMPLER_SOBOL, PV_SAMPLER_INDEPENDENT}) {
        for (uint32_t pixel = 0; pixel < 64; ++pixel) {
            for (uint32_t i = 0; i < 256; ++i) {
                SampleKey key = interleavedSampleKey(pixel, i, 3u, 2u);
                for (uint32_t set : {0u, 5u, vertexSet(PV_SOBOL_MAX_DEPTH + 2, 1)}) {
                    vec4 u = sampleSet(generator, key, set);
                    for (int d = 0; d < 4; ++d) {
                        ASSERT_GE(u[d], 0.0f);
                        ASSERT_LT(u[d], 1.0f);
                        lo = std::min(lo, u[d]);
                        hi = std::max(hi, u[d]);
                    }
                }
            }
        }
    }
    EXPECT_LT(lo, 1e-3f);
    EXPECT_GT(hi, 1.0f - 1e-3f);
}

// The same (pixel, sample, seed, set) always gives the same numbers (preview's fixed sequence),
// and vertices past PV_SOBOL_MAX_DEPTH use the independent generator.
TEST(SamplerTest, NumbersDependOnlyOnTheirAddress) {
    SampleKey a = interleavedSampleKey(12, 34, 5, 2u);
    SampleKey b = interleavedSampleKey(12, 34, 5, 2u);
    for (uint32_t set = 0; set < 40; ++set)
        for (uint32_t g : {PV_SAMPLER_SOBOL, PV_SAMPLER_INDEPENDENT})
            EXPECT_EQ(sampleSet(g, a, set), sampleSet(g, b, set));
    uint32_t deep = vertexSet(PV_SOBOL_MAX_DEPTH, PV_SET_VERTEX_BSDF);
    EXPECT_EQ(sampleSet(PV_SAMPLER_SOBOL, a, deep), independentSet(a, deep));
    EXPECT_EQ(sampleSet(PV_SAMPLER_SOBOL, a, deep - PV_SETS_PER_VERTEX), sobolSet(a, deep - 4u));
}

// Randomisation: at a fixed sample index, over many pixels (each its own scramble), every
// dimension is uniform — what makes each sample's estimate unbiased. Chi-square, 64 bins,
// Šidák-corrected 1% over the 3 indices × 4 dimensions × 2 sets tested.
TEST(SobolTest, EachSampleIsUniformOverScrambles) {
    const int bins = 64, pixels = 64 * 200;
    const double level = sidakLevel(0.01, 3 * 4 * 2);
    for (uint32_t index : {0u, 1u, 1000u}) {
        for (uint32_t set : {PV_SET_CAMERA_JITTER, vertexSet(1, PV_SET_VERTEX_BSDF)}) {
            for (int d = 0; d < 4; ++d) {
                std::vector<int> count(bins, 0);
                for (int p = 0; p < pixels; ++p)
                    ++count[int(
                        sobolSet(interleavedSampleKey(uint32_t(p), index, 11u, 2u), set)[d] *
                        bins)];
                double chi2 = 0.0, expected = double(pixels) / bins;
                for (int c : count) chi2 += (c - expected) * (c - expected) / expected;
                double p = incompleteGammaQ(0.5 * (bins - 1), 0.5 * chi2);
                EXPECT_GT(p, level) << "index " << index << " set " << set << " dim " << d;
            }
        }
    }
}

// Pixels draw decorrelated sequences, and so do the sets of one pixel (padding): the sample
// correlation of two independent sequences of n values is ≈ N(0, 1/n), so |r|·√n stays below
// the Šidák-corrected 1% two-sided normal bound for the pairs tested (here 4.0 covers 3·60
// pairs: Φ⁻¹(1 − 0.01/(2·240)) = 3.53, with margin for the normal approximation of r). The
// two replicates of one pixel are decorrelated too: the convergence meter assumes they are
// independent estimates.
TEST(SobolTest, PixelsSetsAndReplicatesAreDecorrelated) {
    const int n = 4096;
    auto sequence = [&](uint32_t pixel, uint32_t set, int d, uint32_t replicate = 0) {
        std::vector<double> v;
        for (int i = 0; i < n; ++i)
            v.push_back(sobolSet(makeSampleKey(pixel, uint32_t(i), 0u, replicate), set)[d]);
        return v;
    };
    auto correlation = [](const std::vector<double>& a, const std::vector<double>& b) {
        double ma = 0, mb = 0;
        for (size_t i = 0; i < a.size(); ++i) ma += a[i], mb += b[i];
        ma /= a.size();
        mb /= b.size();
        double sab = 0, saa = 0, sbb = 0;
        for (size_t i = 0; i < a.size(); ++i) {
            sab += (a[i] - ma) * (b[i] - mb);
            saa += (a[i] - ma) * (a[i] - ma);
            sbb += (b[i] - mb) * (b[i] - mb);
        }
        return sab / std::sqrt(saa * sbb);
    };
    const double bound = 4.0 / std::sqrt(double(n));
    double worst = 0.0;
    for (uint32_t p = 0; p < 60; ++p) {
        // Neighbouring pixels, same set and dimension.
        double r1 = correlation(sequence(p, PV_SET_CAMERA_JITTER, 0),
                                sequence(p + 1, PV_SET_CAMERA_JITTER, 0));
        // One pixel, two sets (the padding between dimension sets).
        double r2 = correlation(sequence(p, vertexSet(0, PV_SET_VERTEX_EMISSIVE), 0),
                                sequence(p, vertexSet(0, PV_SET_VERTEX_BSDF), 0));
        // Pixel jitter x of a pixel against its neighbour's y.
        double r3 = correlation(sequence(p, PV_SET_CAMERA_JITTER, 0),
                                sequence(p + 640, PV_SET_CAMERA_JITTER, 1));
        // One pixel, one set, the two replicates.
        double r4 = correlation(sequence(p, PV_SET_CAMERA_JITTER, 0, 0),
                                sequence(p, PV_SET_CAMERA_JITTER, 0, 1));
        worst = std::max({worst, std::abs(r1), std::abs(r2), std::abs(r3), std::abs(r4)});
    }
    RecordProperty("worstCorrelationTimesSqrtN", std::to_string(worst * std::sqrt(double(n))));
    EXPECT_LT(worst, bound);
    // Not merely uncorrelated: two pixels never share their point sequence.
    auto a = sequence(3, PV_SET_CAMERA_JITTER, 0), b = sequence(4, PV_SET_CAMERA_JITTER, 0);
    int equal = 0;
    for (int i = 0; i < n; ++i) equal += a[i] == b[i];
    EXPECT_LT(equal, 4);
    auto c = sequence(3, PV_SET_CAMERA_JITTER, 0, 1);
    equal = 0;
    for (int i = 0; i < n; ++i) equal += a[i] == c[i];
    EXPECT_LT(equal, 4);
}

}  // namespace
}  // namespace previs::testing
