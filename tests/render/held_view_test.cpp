// The held view's bookkeeping (render/held_view.h): where a frame's samples are kept, and how
// they join a frame's estimate.
#include "render/held_view.h"

#include <gtest/gtest.h>

#include "tests/support/images.h"

namespace previs {
namespace {

TEST(HeldView, AnyTraceSmallerThanTheOutput) {
    EXPECT_TRUE(HeldView::create(640, 360, 320, 180)->traces(320, 180));
    EXPECT_TRUE(HeldView::create(640, 360, 213, 120));  // a third of 640 is not whole
    EXPECT_TRUE(HeldView::create(640, 360, 320, 120));  // the fractions differ
    EXPECT_FALSE(HeldView::create(640, 360, 320, 180)->traces(160, 90));
    EXPECT_FALSE(HeldView::create(640, 360, 640, 360));  // full resolution: nothing to keep
    EXPECT_FALSE(HeldView::create(640, 360, 640, 180));
}

// The kept samples (summed over frames in the renderer's buffer) join the estimate, which
// counts as the samples given; a pixel without samples shows the estimate.
TEST(HeldView, KeptSamplesJoinTheEstimate) {
    auto view = HeldView::create(4, 2, 2, 1);
    ASSERT_TRUE(view);
    std::vector<glm::vec4> kept(16, glm::vec4(0.0f));  // row 1 keeps nothing
    kept[0] = glm::vec4(12.0f, 12.0f, 12.0f, 6.0f);    // pixel 0: 6 samples of 2, all virtual
    kept[1].x = 6.0f;
    view->frameAdded(DenoiseCamera{});
    view->frameAdded(DenoiseCamera{});
    EXPECT_EQ(view->frames(), 2u);
    const ImageF estimate = testing::filledImage(4, 2, 4, 1.0f);
    const float k = 16.0f;
    const ImageF out = HeldView::blend(kept, estimate, k, true);
    for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(out.pixels[c], float((12.0 + k) / (6.0 + k)));
    EXPECT_FLOAT_EQ(out.pixels[3], float((6.0 + k) / (6.0 + k)));
    for (size_t i = 4; i < out.pixels.size(); ++i) EXPECT_FLOAT_EQ(out.pixels[i], 1.0f) << i;
    view->reset();
    EXPECT_EQ(view->frames(), 0u);
    EXPECT_FALSE(view->camera());
    EXPECT_EQ(
        HeldView::blend(std::vector<glm::vec4>(16, glm::vec4(0.0f)), estimate, k, true).pixels,
        estimate.pixels);
}

// A held camera's samples test the estimate's outline by their mask, a Bernoulli variable: where
// they agree with the estimate's M within two of its spreads, it counts in full; beyond, for
// less by the excess, so the samples traced in the pixel show the outline the upsampling lost.
TEST(HeldView, TheSamplesOverruleAnEstimateWhoseOutlineTheyContradict) {
    const float k = 64.0f;
    // An estimate of M = 0.5 against 4 samples, 2 or 3 of them virtual (2 spreads: 0.5): full.
    EXPECT_FLOAT_EQ(shader::heldEstimateWeight(2.0f, 4.0f, 0.5f, k), k);
    EXPECT_FLOAT_EQ(shader::heldEstimateWeight(3.0f, 4.0f, 0.5f, k), k);
    // The estimate says background (M = 0), 16 samples all hit the object: their spread at the
    // variance floor is √(0.0475/16) ≈ 0.054, so the excess is 1 − 0.109 and the estimate
    // counts as 64 · 0.109² ≈ 0.76 samples.
    const float contradicted = shader::heldEstimateWeight(16.0f, 16.0f, 0.0f, k);
    EXPECT_NEAR(contradicted, k * 0.109f * 0.109f, 0.01f);
    // The same disagreement from fewer samples is surer to be noise: it counts for more.
    EXPECT_GT(shader::heldEstimateWeight(1.0f, 1.0f, 0.0f, k), contradicted);
    EXPECT_LT(shader::heldEstimateWeight(1.0f, 1.0f, 0.0f, k), 0.2f * k);
    // The blend: the estimate's background (1, M 0) against 16 object samples of 3 (M 1).
    std::vector<glm::vec4> kept{glm::vec4(48.0f, 48.0f, 48.0f, 16.0f), glm::vec4(16.0f, 0, 0, 0)};
    ImageF estimate = testing::filledImage(1, 1, 4, 1.0f);
    estimate.pixels[3] = 0.0f;
    const ImageF tested = HeldView::blend(kept, estimate, k, true);
    EXPECT_NEAR(tested.pixels[0], (48.0f + contradicted) / (16.0f + contradicted), 1e-4f);
    EXPECT_GT(tested.pixels[3], 0.9f);
    // Untested (a moving camera's, or the test off), the estimate counts as ever.
    const ImageF untested = HeldView::blend(kept, estimate, k, false);
    EXPECT_FLOAT_EQ(untested.pixels[0], (48.0f + k) / (16.0f + k));
    EXPECT_FLOAT_EQ(untested.pixels[3], 16.0f / (16.0f + k));
}

// A camera held for 4 frames tests the outline; a moving one does not (its moved samples may be
// the stale ones), nor one that just stopped (the samples the move left outnumber its own).
TEST(HeldView, OnlyACameraHeldAFewFramesTestsTheOutline) {
    auto view = HeldView::create(4, 2, 2, 1);
    ASSERT_TRUE(view);
    for (int i = 0; i < 4; ++i) {
        EXPECT_FALSE(view->testsOutline()) << i;
        view->frameAdded(DenoiseCamera{});
    }
    EXPECT_TRUE(view->testsOutline());
    view->follow();
    view->frameAdded(DenoiseCamera{});
    EXPECT_FALSE(view->testsOutline());
    view->hold();
    view->frameAdded(DenoiseCamera{});
    EXPECT_FALSE(view->testsOutline());
}

// The estimate counts as 16 samples for each sample a frame traces per traced pixel (the weights
// measured best at 1 and at 4 spp).
TEST(HeldView, TheEstimateCountsMoreTheMoreSamplesAFrameTraces) {
    EXPECT_FLOAT_EQ(HeldView::estimateSamples(1), 16.0f);
    EXPECT_FLOAT_EQ(HeldView::estimateSamples(4), 64.0f);
    EXPECT_FLOAT_EQ(HeldView::estimateSamples(0), 16.0f);
}

// While the camera moves, the samples are kept and follow it (render/held_reprojection.h), but
// its frames are not frames held (the status's heldViewFrames); they count again once it holds.
TEST(HeldView, AMovingCamerasFramesKeepSamplesButAreNotHeld) {
    auto view = HeldView::create(4, 2, 2, 1);
    ASSERT_TRUE(view);
    DenoiseCamera a;
    a.worldFromCamera[3][0] = 1.0;
    view->frameAdded(a);
    EXPECT_EQ(view->frames(), 1u);
    view->follow();
    DenoiseCamera b;
    b.worldFromCamera[3][0] = 2.0;
    view->frameAdded(b);
    EXPECT_EQ(view->frames(), 0u);
    ASSERT_TRUE(view->camera());
    EXPECT_EQ(view->camera()->worldFromCamera[3][0], 2.0);
    view->hold();
    view->frameAdded(b);
    EXPECT_EQ(view->frames(), 1u);
    EXPECT_TRUE(view->camera());
}

}  // namespace
}  // namespace previs
