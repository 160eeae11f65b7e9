// The plate-consistency meter (render/plate_consistency.h) on analytic input: a known gain reads
// as that ratio, noise moves the median by no more than its standard error, clipped and dark
// plate values and cells that are not wholly real surface are left out, too few cells give no
// reading. Bounds are stated where they come from statistics.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "render/plate_consistency.h"
#include "tests/support/images.h"

namespace previs {
namespace {

// A grid of w×h cells, all real surface, plate values spread over [0.05, 0.8] (channels differ).
PlateMeterGrid plateGrid(uint32_t w, uint32_t h, uint32_t seed = 1) {
    PlateMeterGrid g;
    g.width = w;
    g.height = h;
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.05f, 0.8f);
    for (uint32_t i = 0; i < w * h; ++i) {
        g.plate.emplace_back(u(rng), u(rng), u(rng));
        g.realSurface.push_back(1);
    }
    g.real.resize(g.plate.size());
    return g;
}

void applyGain(PlateMeterGrid& g, glm::vec3 gain) {
    for (size_t i = 0; i < g.plate.size(); ++i) g.real[i] = g.plate[i] * gain;
}

TEST(PlateConsistency, AKnownGainReadsAsThatRatio) {
    PlateMeterGrid g = plateGrid(20, 10);
    // The demo's today: a render about 12 times too dim, a little bluer.
    applyGain(g, {0.08f, 0.08f, 0.1f});
    std::optional<PlateConsistency> c = measurePlateConsistency(g, PlateLimits{});
    ASSERT_TRUE(c);
    EXPECT_NEAR(c->ratio[0], 0.08, 1e-6);
    EXPECT_NEAR(c->ratio[1], 0.08, 1e-6);
    EXPECT_NEAR(c->ratio[2], 0.1, 1e-6);
    for (double s : c->spread) EXPECT_NEAR(s, 0.0, 1e-6) << "one gain everywhere: no spread";
    EXPECT_EQ(c->pixels, 200u);
    EXPECT_EQ(c->gridWidth, 20u);
    EXPECT_EQ(c->gridHeight, 10u);
    EXPECT_FALSE(c->ok);

    applyGain(g, {1.0f, 1.0f, 1.0f});
    c = measurePlateConsistency(g, PlateLimits{});
    ASSERT_TRUE(c);
    EXPECT_TRUE(c->ok);
    // The range's ends: [0.8, 1.25] in every channel.
    for (auto [gain, ok] :
         {std::pair{0.81f, true}, {0.79f, false}, {1.24f, true}, {1.26f, false}}) {
        applyGain(g, {1.0f, gain, 1.0f});
        c = measurePlateConsistency(g, PlateLimits{});
        ASSERT_TRUE(c);
        EXPECT_EQ(c->ok, ok) << "green gain " << gain;
    }
}

TEST(PlateConsistency, NoiseMovesTheMedianByItsStandardErrorAndShowsAsSpread) {
    // Each cell's L_or is the gain times the plate times (1 + σ·N(0,1)): a Monte Carlo mean.
    constexpr double kSigma = 0.1;
    constexpr double kGain = 0.5;
    PlateMeterGrid g = plateGrid(50, 40, 7);
    std::mt19937 rng(3);
    std::normal_distribution<double> n(0.0, 1.0);
    for (size_t i = 0; i < g.plate.size(); ++i)
        for (int c = 0; c < 3; ++c)
            g.real[i][c] = float(kGain * g.plate[i][c] * (1.0 + kSigma * n(rng)));
    std::optional<PlateConsistency> c = measurePlateConsistency(g, PlateLimits{});
    ASSERT_TRUE(c);
    ASSERT_EQ(c->pixels, 2000u);
    // The median's standard error is 1.2533·σ/√n of the gain (0.14 % here); 5 of them.
    const double se = 1.2533 * kSigma / std::sqrt(2000.0) * kGain;
    for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(c->ratio[k], kGain, 5.0 * se) << "channel " << k;
        // ln(1 + σx) has a standard deviation of about σ; the 16–84 % half range estimates it
        // to within a few per cent at n = 2000 (and ln's curvature widens it by ~σ²).
        EXPECT_NEAR(c->spread[k], kSigma, 0.015) << "channel " << k;
    }
}

TEST(PlateConsistency, ClippedAndDarkPlateCellsAreLeftOut) {
    PlateMeterGrid g = plateGrid(20, 10);
    applyGain(g, {1.0f, 1.0f, 1.0f});
    PlateLimits limits;
    limits.dark = {0.02f, 0.02f, 0.02f};
    limits.clipped = {0.9f, 0.9f, 0.9f};
    // Make a third of the cells clipped in one channel and a third dark in one: their L_or is
    // way off (a lamp the plate cannot show, a shadow the sensor's noise fills), so any of them
    // that counted would pull the median.
    size_t clippedCells = 0, darkCells = 0;
    for (size_t i = 0; i < g.plate.size(); ++i) {
        if (i % 3 == 0) {
            g.plate[i][i % 2 ? 0 : 2] = 0.95f;
            g.real[i] = glm::vec3(20.0f);
            ++clippedCells;
        } else if (i % 3 == 1) {
            g.plate[i][1] = 0.01f;
            g.real[i] = glm::vec3(0.0f);
            ++darkCells;
        }
    }
    std::optional<PlateConsistency> c = measurePlateConsistency(g, limits);
    ASSERT_TRUE(c);
    EXPECT_EQ(c->pixels, g.plate.size() - clippedCells - darkCells);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(c->ratio[k], 1.0, 1e-6);
    EXPECT_TRUE(c->ok);
}

TEST(PlateConsistency, TooFewCellsGiveNoReading) {
    PlateMeterGrid g = plateGrid(8, 4);  // 32 cells
    applyGain(g, {1.0f, 1.0f, 1.0f});
    EXPECT_TRUE(measurePlateConsistency(g, PlateLimits{}, 32));
    g.realSurface[5] = 0;  // 31 left
    EXPECT_FALSE(measurePlateConsistency(g, PlateLimits{}, 32));
    std::fill(g.realSurface.begin(), g.realSurface.end(), 0);
    EXPECT_FALSE(measurePlateConsistency(g, PlateLimits{}, 1)) << "nothing real in view";
    EXPECT_FALSE(measurePlateConsistency(PlateMeterGrid{}, PlateLimits{})) << "an empty grid";
    // L_or that is not finite never counts.
    g = plateGrid(8, 4);
    applyGain(g, {1.0f, 1.0f, 1.0f});
    g.real[0].x = std::nanf("");
    EXPECT_FALSE(measurePlateConsistency(g, PlateLimits{}, 32));
}

// The renderer's traced means: 5 channels (L_or RGB, real-hit fraction, mask).
ImageF tracedImage(uint32_t w, uint32_t h, glm::vec3 real) {
    return testing::uniformImage(w, h, {real.x, real.y, real.z, 1.0f, 0.0f});
}

ImageF plateImage(uint32_t w, uint32_t h, glm::vec3 value) {
    return testing::uniformImage(w, h, {value.x, value.y, value.z});
}

TEST(PlateMeterGrid, AveragesCellsAndKeepsOnlyRealSurfaceWithAMargin) {
    // Traced at half the plate's resolution (preview's resolution scale), 10×5 cells of 4×4
    // traced and 8×8 plate pixels.
    ImageF traced = tracedImage(40, 20, {0.5f, 0.5f, 0.5f});
    ImageF plate = plateImage(80, 40, {0.25f, 0.25f, 0.25f});
    // One traced pixel's sample missed the phantom set (the environment) in cell (2, 1); one is
    // a virtual object's in cell (7, 3).
    traced.pixels[(size_t(1 * 4 + 2) * 40 + 2 * 4 + 1) * 5 + 3] = 0.75f;
    traced.pixels[(size_t(3 * 4 + 1) * 40 + 7 * 4 + 3) * 5 + 4] = 0.25f;
    // One clipped plate pixel in cell (5, 0).
    PlateLimits limits;
    limits.clipped = {1.0f, 1.0f, 1.0f};
    plate.pixels[(size_t(0 * 8 + 3) * 80 + 5 * 8 + 6) * 3 + 1] = 1.0f;
    // L_or twice as bright in cell (0, 4)'s traced pixels: the cell's mean.
    for (uint32_t y = 16; y < 20; ++y)
        for (uint32_t x = 0; x < 4; ++x)
            for (int c = 0; c < 3; ++c) traced.pixels[(size_t(y) * 40 + x) * 5 + c] = 1.0f;

    PlateMeterGrid g = plateMeterGrid(traced, plate, limits, 10);
    ASSERT_EQ(g.width, 10u);
    ASSERT_EQ(g.height, 5u);
    auto at = [&](uint32_t x, uint32_t y) { return size_t(y) * g.width + x; };
    EXPECT_FLOAT_EQ(g.real[at(0, 4)].x, 1.0f);
    EXPECT_FLOAT_EQ(g.real[at(1, 4)].x, 0.5f);
    EXPECT_FLOAT_EQ(g.plate[at(3, 3)].y, 0.25f);
    // The environment's and the virtual object's cells and their eight neighbours are out; the
    // clipped cell alone (a clipped pixel says nothing of its neighbours' real surface).
    size_t out = 0;
    for (uint32_t y = 0; y < 5; ++y)
        for (uint32_t x = 0; x < 10; ++x) {
            const bool nearEnv = std::abs(int(x) - 2) <= 1 && std::abs(int(y) - 1) <= 1;
            const bool nearVirtual = std::abs(int(x) - 7) <= 1 && std::abs(int(y) - 3) <= 1;
            const bool clipped = x == 5 && y == 0;
            const bool expected = !(nearEnv || nearVirtual || clipped);
            EXPECT_EQ(bool(g.realSurface[at(x, y)]), expected) << x << "," << y;
            out += !expected;
        }
    std::optional<PlateConsistency> c = measurePlateConsistency(g, limits, 1);
    ASSERT_TRUE(c);
    EXPECT_EQ(c->pixels, 50u - out);
    EXPECT_NEAR(c->ratio[0], 2.0, 1e-6) << "the median, not pulled by the one bright cell";

    // A grid wider than the trace is capped at the traced width (every cell has a sample).
    g = plateMeterGrid(tracedImage(6, 3, glm::vec3(1.0f)), plateImage(80, 40, glm::vec3(1.0f)),
                       limits, 40);
    EXPECT_EQ(g.width, 6u);
    EXPECT_EQ(g.height, 3u);
}

TEST(PlateConsistency, QuantileInterpolatesBetweenOrderStatistics) {
    std::vector<double> v{5, 1, 3};
    EXPECT_EQ(quantile(v, 0.5), 3.0);
    v = {4, 1, 3, 2};
    EXPECT_EQ(quantile(v, 0.5), 2.5);
    v = {4, 1, 3, 2};
    EXPECT_EQ(quantile(v, 0.0), 1.0);
    v = {4, 1, 3, 2};
    EXPECT_EQ(quantile(v, 1.0), 4.0);
    v.clear();
    EXPECT_TRUE(std::isnan(quantile(v, 0.5)));
}

}  // namespace
}  // namespace previs
