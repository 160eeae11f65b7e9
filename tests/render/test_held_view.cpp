// The held view's bookkeeping (render/held_view.h): which output pixel each frame samples, where
// its samples land, and the blend of kept samples with a frame's estimate.
#include <gtest/gtest.h>

#include <set>

#include "render/held_view.h"

namespace previs {
namespace {

ImageF constant(uint32_t width, uint32_t height, float value) {
    ImageF img;
    img.width = width;
    img.height = height;
    img.channels = 4;
    img.pixels.assign(size_t(width) * height * 4, value);
    return img;
}

TEST(HeldView, OnlyAWholeFactorOfTwoOrMore) {
    EXPECT_TRUE(HeldView::create(640, 360, 320, 180));
    EXPECT_EQ(HeldView::create(640, 360, 320, 180)->factor(), 2u);
    EXPECT_EQ(HeldView::create(640, 360, 160, 90)->factor(), 4u);
    EXPECT_FALSE(HeldView::create(640, 360, 640, 360));  // full resolution: nothing to keep
    EXPECT_FALSE(HeldView::create(640, 360, 213, 120));  // a third, not whole
    EXPECT_FALSE(HeldView::create(640, 360, 320, 120));  // factors differ
}

TEST(HeldView, EveryFactorFramesCoverEachRowAndColumnAndTheSquareCoversTheBlock) {
    for (uint32_t f : {2u, 3u, 4u}) {
        auto view = HeldView::create(12 * f, 12 * f, 12, 12);
        ASSERT_TRUE(view);
        const std::vector<float> samples(144, 1.0f);
        std::vector<glm::uvec2> phases;
        for (uint32_t k = 0; k < f * f; ++k) {
            phases.push_back(view->phase());
            view->add(constant(12, 12, 0.0f), samples);
        }
        std::set<std::pair<uint32_t, uint32_t>> block;
        for (uint32_t group = 0; group < f; ++group) {
            std::set<uint32_t> rows, columns;
            for (uint32_t k = group * f; k < (group + 1) * f; ++k) {
                rows.insert(phases[k].y);
                columns.insert(phases[k].x);
                block.insert({phases[k].x, phases[k].y});
            }
            EXPECT_EQ(rows.size(), f) << "factor " << f << ", frames from " << group * f;
            EXPECT_EQ(columns.size(), f) << "factor " << f << ", frames from " << group * f;
        }
        EXPECT_EQ(block.size(), size_t(f) * f) << "factor " << f;
        EXPECT_EQ(view->frames(), f * f);
        EXPECT_EQ(view->phase(), phases.front());  // and round again
    }
}

TEST(HeldView, SamplesLandOnTheirPhasesPixelAndBlendByCount) {
    auto view = HeldView::create(4, 2, 2, 1);
    ASSERT_TRUE(view);
    // Frame 0 samples output pixel (0, 0) of each block: traced pixel 1 (value 5, 3 samples)
    // lands on output (2, 0); traced pixel 0 has no sample and keeps nothing.
    ImageF traced = constant(2, 1, 0.0f);
    for (int c = 0; c < 4; ++c) traced.pixels[4 + c] = 5.0f;
    view->add(traced, std::vector<float>{0.0f, 3.0f});
    const ImageF estimate = constant(4, 2, 1.0f);
    const ImageF out = view->blend(estimate, 1.0);
    for (uint32_t i = 0; i < 8; ++i) {
        // (3 · 5 + 1 · 1) / 4 where a sample was kept, the estimate elsewhere.
        const float want = i == 2 ? 4.0f : 1.0f;
        for (int c = 0; c < 4; ++c) EXPECT_FLOAT_EQ(out.pixels[i * 4 + c], want) << i;
    }
    view->reset();
    EXPECT_EQ(view->frames(), 0u);
    EXPECT_EQ(view->blend(estimate, 1.0).pixels, estimate.pixels);
}

}  // namespace
}  // namespace previs
