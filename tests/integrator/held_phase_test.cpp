// The held view's phase schedule (temporal super-resolution; shared/sampler.h's heldPhaseJitter,
// RenderSettings::previewPhases): the schedule's Latin order on the host, and on a rendered
// preview at a third of the output's size that a held camera's frames give every output pixel
// its samples evenly, where random jitter leaves a third of them without one.
#include <gtest/gtest.h>

#include <algorithm>
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
        for (uint32_t first = 0; first < k * k; first += k) {
            std::set<int> columns, rows;
            for (uint32_t p = first; p < first + k; ++p) {
                columns.insert(cellOf(p, 0, k).first);
                rows.insert(cellOf(p, 0, k).second);
            }
            EXPECT_EQ(columns.size(), k);
            EXPECT_EQ(rows.size(), k);
        }
}

TEST(HeldPhaseJitter, TheJitterStaysInItsCellAndInThePixel) {
    const uint32_t k = 3;
    for (uint32_t p = 0; p < k * k; ++p)
        for (glm::vec2 u : {glm::vec2(0.0f), glm::vec2(0.999999f)}) {
            const glm::vec2 j = shader::heldPhaseJitter(p, 0, k, u);
            const Cell c = cellOf(p, 0, k);
            EXPECT_GE(j.x, float(c.first) / k);
            EXPECT_LT(j.x, float(c.first + 1) / k);
            EXPECT_GE(j.y, float(c.second) / k);
            EXPECT_LT(j.y, float(c.second + 1) / k);
        }
}

constexpr uint32_t kOutputWidth = 48;
constexpr uint32_t kOutputHeight = 36;

class HeldPhaseTest : public GpuTest {
protected:
    // The held view's sample count per output pixel after `frames` held preview frames of one
    // sample a traced pixel, traced at a third of the output's size.
    std::vector<float> samplesAfter(uint32_t frames, bool phases) {
        Scene s;
        addQuad(s, glm::vec3(0.0f), glm::vec3(2.0f, 0.0f, 0.0f), glm::vec3(0.0f, 0.0f, -2.0f),
                addMaterial(s, lambert(glm::vec3(0.5f))), /*real=*/true);
        s.cameras.push_back(lookAt(glm::vec3(-0.5f, 1.5f, 0.0f), glm::vec3(-0.5f, 0.0f, 0.0f),
                                   glm::vec3(0.0f, 0.0f, -1.0f), glm::radians(40.0f)));
        RenderSettings rs = renderSettings(kOutputWidth, kOutputHeight, 2);
        rs.resolutionScale = 1.0f / 3.0f;
        rs.previewPhases = phases;
        auto r = Renderer::create(ctx(), s, rs);
        EXPECT_TRUE(r.ok()) << r.message();
        if (!r) return {};
        EXPECT_TRUE((*r)->holdView(true).ok());
        for (uint32_t f = 1; f <= frames; ++f) EXPECT_TRUE((*r)->renderPreviewFrame(1, f).ok());
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
// (8/9)^9 ≈ 35 % of them without any after nine (asserted > 20 %: 1,728 pixels, so the count's
// standard deviation is about 1.1 %).
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

}  // namespace
}  // namespace previs::testing
