// The held view's phase schedule (temporal super-resolution; shared/sampler.h's heldPhaseJitter,
// RenderSettings::previewPhases): the schedule's Latin order on the host, and on a rendered
// preview at a third of the output's size that a held camera's frames give every output pixel
// its samples evenly, where random jitter leaves a third of them without one.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <utility>

#include "gpu/shaders/shared/sampler.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

using Cell = std::pair<int, int>;

Cell cellOf(uint32_t phase, uint32_t offset, uint32_t k) {
    const glm::vec2 j = shader::heldPhaseJitter(phase, offset, k, glm::vec2(0.5f));
    return {int(j.x * float(k)), int(j.y * float(k))};
}

TEST(HeldPhaseJitter, AnyKSquaredConsecutivePhasesFillEveryCellOnce) {
    for (uint32_t k = 1; k <= 5; ++k)
        for (uint32_t offset : {0u, 7u, 0xfffffff3u})
            for (uint32_t first = 0; first < 2 * k * k; ++first) {
                std::set<Cell> cells;
                for (uint32_t p = first; p < first + k * k; ++p) cells.insert(cellOf(p, offset, k));
                EXPECT_EQ(cells.size(), size_t(k) * k) << k << " " << offset << " " << first;
            }
}

// The k phases from a multiple of k (the first k samples of a cycle) take each column and each
// row once: the first frames already spread over the footprint.
TEST(HeldPhaseJitter, EachKPhasesOfACycleTakeEveryRowAndColumnOnce) {
    for (uint32_t k = 1; k <= 5; ++k)
        for (uint32_t offset : {0u, 1u, 7u, 0xfffffff3u})
            for (uint32_t first = 0; first < k * k; first += k) {
                std::set<int> columns, rows;
                for (uint32_t p = first; p < first + k; ++p) {
                    columns.insert(cellOf(p, offset, k).first);
                    rows.insert(cellOf(p, offset, k).second);
                }
                EXPECT_EQ(columns.size(), k) << k << " " << offset << " " << first;
                EXPECT_EQ(rows.size(), k) << k << " " << offset << " " << first;
            }
}

TEST(HeldPhaseJitter, TheJitterStaysInItsCellAndInThePixel) {
    const glm::vec2 below1(std::nextafter(1.0f, 0.0f));
    for (uint32_t k : {2u, 3u, 5u})
        for (uint32_t p = 0; p < k * k; ++p)
            for (glm::vec2 u : {glm::vec2(0.0f), below1}) {
                const glm::vec2 j = shader::heldPhaseJitter(p, 5, k, u);
                const Cell c = cellOf(p, 5, k);
                EXPECT_GE(j.x, float(c.first) / k);
                EXPECT_LE(j.x, float(c.first + 1) / k);
                EXPECT_GE(j.y, float(c.second) / k);
                EXPECT_LE(j.y, float(c.second + 1) / k);
                EXPECT_LT(j.x, 1.0f);
                EXPECT_LT(j.y, 1.0f);
            }
}

constexpr uint32_t kOutputWidth = 96;
constexpr uint32_t kOutputHeight = 72;

// A virtual ball of radius 0.4 seen from 3 m: its disc about 13 output pixels in radius.
Scene virtualBall() {
    Scene s;
    addSphere(s, glm::vec3(0.0f), 0.4f, addMaterial(s, lambert(glm::vec3(0.5f))));
    s.cameras.push_back(lookAt(glm::vec3(0.0f, 0.0f, 3.0f), glm::vec3(0.0f),
                               glm::vec3(0.0f, 1.0f, 0.0f), glm::radians(40.0f)));
    return s;
}

class HeldPhaseTest : public GpuTest {
protected:
    // The held view's sample count per output pixel after `frames` held preview frames of `spp`
    // samples a traced pixel, traced at a third of the output's size, with `objectSamples` more
    // a frame per output pixel where the virtual objects are.
    std::vector<float> samplesAfter(uint32_t frames, bool phases,
                                    const Scene& s = realFloorSeenFromAbove(), uint32_t spp = 1,
                                    float objectSamples = 0.0f) {
        RenderSettings rs = renderSettings(kOutputWidth, kOutputHeight, 2);
        rs.objectSamplesPerOutputPixel = objectSamples;
        rs.resolutionScale = 1.0f / 3.0f;
        rs.previewPhases = phases;
        auto r = Renderer::create(ctx(), s, rs);
        EXPECT_TRUE(r.ok()) << r.message();
        if (!r) return {};
        EXPECT_TRUE((*r)->holdView(true).ok());
        for (uint32_t f = 1; f <= frames; ++f) EXPECT_TRUE((*r)->renderPreviewFrame(spp, f).ok());
        Result<std::vector<glm::vec4>> held = (*r)->heldSamples();
        EXPECT_TRUE(held.ok()) << held.message();
        std::vector<float> counts;
        if (!held) return counts;
        for (size_t i = 1; i < held->size(); i += 2) counts.push_back((*held)[i].x);
        EXPECT_EQ(counts.size(), size_t(kOutputWidth) * kOutputHeight);
        return counts;
    }
};

// k = 3: nine frames give each output pixel one sample, eighteen two. Random jitter leaves
// (8/9)^9 ≈ 35 % of them without any after nine (asserted > 20 %: 6,912 pixels, so the count's
// standard deviation is about 0.6 %).
TEST_F(HeldPhaseTest, AHeldCameraGivesEveryOutputPixelASampleInKSquaredFrames) {
    for (uint32_t frames : {9u, 18u}) {
        const std::vector<float> counts = samplesAfter(frames, true);
        ASSERT_FALSE(counts.empty());
        const auto [least, most] = std::minmax_element(counts.begin(), counts.end());
        EXPECT_EQ(*least, float(frames / 9)) << frames << " frames";
        EXPECT_EQ(*most, float(frames / 9)) << frames << " frames";
    }
    const std::vector<float> random = samplesAfter(9, false);
    ASSERT_FALSE(random.empty());
    const double empty =
        double(std::count(random.begin(), random.end(), 0.0f)) / double(random.size());
    EXPECT_GT(empty, 0.2);
}

// The virtual objects at the output's resolution: a frame's added samples there (one per output
// pixel: 9 a traced pixel, within the renderer's budget at 4 spp) follow the frame's own in the
// schedule, so one frame gives every output pixel on the ball a sample of its own. The sampler's
// own jitter, one scrambled Sobol' net a frame, stratifies by halves, not thirds: its 13 samples
// leave 7.6 % of these 144 pixels without (measured; 22 % were they independent).
TEST_F(HeldPhaseTest, OneFrameGivesEveryOutputPixelOfAVirtualObjectASample) {
    auto onTheBall = [](const std::vector<float>& counts) {
        std::vector<float> ball;  // the 12 × 12 output pixels round the disc's centre
        for (uint32_t y = kOutputHeight / 2 - 6; y < kOutputHeight / 2 + 6; ++y)
            for (uint32_t x = kOutputWidth / 2 - 6; x < kOutputWidth / 2 + 6; ++x)
                ball.push_back(counts.at(size_t(y) * kOutputWidth + x));
        return ball;
    };
    const std::vector<float> ball = onTheBall(samplesAfter(1, true, virtualBall(), 4, 1.0f));
    EXPECT_GE(*std::min_element(ball.begin(), ball.end()), 1.0f);
    const std::vector<float> random = onTheBall(samplesAfter(1, false, virtualBall(), 4, 1.0f));
    const double empty =
        double(std::count(random.begin(), random.end(), 0.0f)) / double(random.size());
    EXPECT_GT(empty, 0.02);
}

}  // namespace
}  // namespace previs::testing
