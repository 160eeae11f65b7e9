// The held view following a moving camera (render/held_reprojection.h): where one pixel's
// samples land (the shared math, analytically), the shader's two stages against the same math on
// the host (the nearest surface hides the others), and, on a rendered scene, samples moved with
// the camera against samples traced afresh from its new pose.
#include "render/held_reprojection.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <glm/gtc/matrix_transform.hpp>
#include <limits>

#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

constexpr uint32_t kWidth = 48;
constexpr uint32_t kHeight = 32;

DenoiseCamera pinhole(const glm::dmat4& worldFromCamera) {
    return {worldFromCamera, glm::vec2(0.6f, 0.4f)};
}

// The camera moved `dx` metres to its right and turned `yawRad` to its left.
glm::dmat4 moved(double dx, double yawRad) {
    return glm::rotate(glm::translate(glm::dmat4(1.0), glm::dvec3(dx, 0.0, 0.0)), yawRad,
                       glm::dvec3(0.0, 1.0, 0.0));
}

TEST(HeldLanding, AStillCameraLandsEveryPixelOnItself) {
    const shader::ReprojectParams p =
        reprojectParams(pinhole(glm::dmat4(1.0)), pinhole(glm::dmat4(1.0)), kWidth, kHeight, 1.0f);
    for (uint32_t y = 0; y < kHeight; ++y)
        for (uint32_t x = 0; x < kWidth; ++x) {
            const glm::vec3 l = shader::heldLanding(p, glm::uvec2(x, y), 2.5f);
            EXPECT_EQ(uint32_t(l.x), x);
            EXPECT_EQ(uint32_t(l.y), y);
            EXPECT_NEAR(l.z, 2.5f, 1e-5f);
        }
}

// A sideways step of the camera moves a surface across the image by the focal length times the
// step over its depth: near surfaces more than far ones, and the far sky not at all.
TEST(HeldLanding, ASideStepMovesNearSurfacesMoreThanFarOnes) {
    const double step = 0.1;
    const shader::ReprojectParams p =
        reprojectParams(pinhole(glm::dmat4(1.0)), pinhole(moved(step, 0.0)), kWidth, kHeight, 1.0f);
    const glm::uvec2 centre(kWidth / 2, kHeight / 2);  // its ray is nearly the optical axis
    const double focalPx = 0.5 * kWidth / 0.6;
    const double rayX = ((centre.x + 0.5) / kWidth * 2.0 - 1.0) * 0.6;  // x/depth of its ray
    for (float depth : {1.0f, 4.0f}) {
        const glm::vec3 l =
            shader::heldLanding(p, centre, depth * float(std::sqrt(1.0 + rayX * rayX)));
        EXPECT_NEAR(l.x, centre.x + 0.5 - step / depth * focalPx, 1e-3) << depth;
        EXPECT_NEAR(l.y, centre.y + 0.5, 1e-3) << depth;
    }
    EXPECT_NEAR(shader::heldLanding(p, centre, 1e4f).x, centre.x + 0.5, 0.01);
    // Behind the new camera, or out of its image: nowhere.
    const shader::ReprojectParams back =
        reprojectParams(pinhole(glm::dmat4(1.0)),
                        pinhole(glm::translate(glm::dmat4(1.0), glm::dvec3(0.0, 0.0, -3.0))),
                        kWidth, kHeight, 1.0f);
    EXPECT_EQ(shader::heldLanding(back, centre, 2.0f).z, 0.0f);
    const shader::ReprojectParams aside =
        reprojectParams(pinhole(glm::dmat4(1.0)), pinhole(moved(0.0, 1.2)), kWidth, kHeight, 1.0f);
    EXPECT_EQ(shader::heldLanding(aside, glm::uvec2(kWidth - 1, 0), 2.0f).z, 0.0f);
}

// Samples with a near box in front of a far wall, each pixel's sums distinct.
std::vector<glm::vec4> boxBeforeAWall() {
    std::vector<glm::vec4> held(2 * size_t(kWidth) * kHeight);
    for (uint32_t y = 0; y < kHeight; ++y)
        for (uint32_t x = 0; x < kWidth; ++x) {
            const size_t i = size_t(y) * kWidth + x;
            const bool box = x >= 18 && x < 30 && y >= 10 && y < 22;
            const float count = float(1 + (x + y) % 5);
            const float distance = box ? 0.8f : 3.0f + 0.01f * float(y);
            held[2 * i] = glm::vec4(0.1f * float(x), 0.2f * float(y), float(i % 7), count * 0.5f);
            if ((x * 7 + y * 3) % 11 == 0) continue;  // some pixels keep nothing
            held[2 * i + 1] = glm::vec4(count, count * distance, 0.0f, 0.0f);
        }
    return held;
}

// The shader's two stages as the host would run them; `hidden` counts samples that landed where
// a nearer one did.
std::vector<glm::vec4> moveOnHost(const std::vector<glm::vec4>& from,
                                  const shader::ReprojectParams& p, size_t& hidden) {
    const size_t pixels = size_t(p.width) * p.height;
    std::vector<float> nearest(pixels, std::numeric_limits<float>::infinity());
    std::vector<glm::vec4> to(2 * pixels, glm::vec4(0.0f));
    auto landing = [&](size_t i) {
        const glm::vec4 c = from[2 * i + 1];
        if (!(c.x > 0.0f)) return glm::vec3(0.0f);
        return shader::heldLanding(p, glm::uvec2(i % p.width, i / p.width), c.y / c.x);
    };
    auto at = [&](glm::vec3 l) { return size_t(l.y) * p.width + size_t(l.x); };
    size_t landed = 0;
    for (size_t i = 0; i < pixels; ++i)
        if (const glm::vec3 l = landing(i); l.z > 0.0f) {
            nearest[at(l)] = std::min(nearest[at(l)], l.z);
            ++landed;
        }
    size_t moved = 0;
    for (size_t i = 0; i < pixels; ++i) {
        const glm::vec3 l = landing(i);
        if (!(l.z > 0.0f) || l.z != nearest[at(l)]) continue;
        const float kept = from[2 * i + 1].x * p.keep;
        to[2 * at(l)] = from[2 * i] * p.keep;
        to[2 * at(l) + 1] = glm::vec4(kept, l.z * kept, from[2 * i + 1].z, PV_HELD_MOVED);
        ++moved;
    }
    hidden = landed - moved;
    return to;
}

class HeldReprojectionTest : public GpuTest {
protected:
    std::vector<glm::vec4> moveOnDevice(const std::vector<glm::vec4>& from,
                                        const shader::ReprojectParams& p) {
        auto r = HeldReprojection::create(ctx(), p.width, p.height);
        EXPECT_TRUE(r.ok()) << r.message();
        auto held = GpuBuffer::create(ctx(), from.size() * sizeof(glm::vec4), "held");
        EXPECT_TRUE(held.ok());
        if (!r || !held) return {};
        EXPECT_TRUE(held->upload(from.data(), from.size() * sizeof(glm::vec4)).ok());
        EXPECT_TRUE(r->run(*held, p).ok());
        std::vector<glm::vec4> out(from.size());
        EXPECT_TRUE(held->download(out.data(), out.size() * sizeof(glm::vec4)).ok());
        return out;
    }
};

// The device moves each pixel's samples where the host's math says, weighted by `keep`, the
// nearer surface winning where two land together. Float rounding may put a landing on a pixel's
// edge on either side: at most one pixel in a hundred may differ.
TEST_F(HeldReprojectionTest, TheShaderMovesSamplesWhereTheHostMathSays) {
    const std::vector<glm::vec4> from = boxBeforeAWall();
    const shader::ReprojectParams p = reprojectParams(
        pinhole(glm::dmat4(1.0)), pinhole(moved(0.12, 0.02)), kWidth, kHeight, 0.75f);
    size_t hidden = 0;
    const std::vector<glm::vec4> expected = moveOnHost(from, p, hidden);
    EXPECT_GT(hidden, 10u) << "the box should hide part of the wall";
    const std::vector<glm::vec4> got = moveOnDevice(from, p);
    ASSERT_EQ(got.size(), expected.size());
    size_t differ = 0, empty = 0;
    for (size_t i = 0; i < got.size() / 2; ++i) {
        bool same = true;
        for (int k = 0; k < 2; ++k)
            for (int c = 0; c < 4; ++c)
                same = same && std::abs(got[2 * i + k][c] - expected[2 * i + k][c]) <=
                                   1e-4f * std::max(1.0f, std::abs(expected[2 * i + k][c]));
        differ += same ? 0 : 1;
        empty += expected[2 * i + 1].x == 0.0f ? 1 : 0;
    }
    EXPECT_LE(differ, got.size() / 2 / 100);
    // What the move uncovers keeps nothing (the new frames start it afresh).
    EXPECT_GT(empty, 20u);
}

TEST_F(HeldReprojectionTest, AStillCameraOnlyFadesTheSamples) {
    const std::vector<glm::vec4> from = boxBeforeAWall();
    const shader::ReprojectParams p =
        reprojectParams(pinhole(glm::dmat4(1.0)), pinhole(glm::dmat4(1.0)), kWidth, kHeight, 0.75f);
    const std::vector<glm::vec4> got = moveOnDevice(from, p);
    ASSERT_EQ(got.size(), from.size());
    for (size_t i = 0; i < got.size() / 2; ++i) {
        const float count = from[2 * i + 1].x;
        const glm::vec4 sums = count > 0.0f ? from[2 * i] * 0.75f : glm::vec4(0.0f);
        for (int c = 0; c < 4; ++c) EXPECT_FLOAT_EQ(got[2 * i][c], sums[c]) << i;
        EXPECT_FLOAT_EQ(got[2 * i + 1].x, count * 0.75f) << i;
        if (count > 0.0f) {
            EXPECT_NEAR(got[2 * i + 1].y / got[2 * i + 1].x, from[2 * i + 1].y / count, 1e-4f);
        }
    }
}

// On a rendered scene (a virtual ball on a real floor): the held view's samples of a few frames,
// moved to a new pose, against the samples of frames traced from that pose. The virtual mask is
// their sharpest signal: its outline moves by several pixels, so the samples left where they were
// disagree with the new pose along it, and moved they agree but for a pixel's rounding.
TEST_F(HeldReprojectionTest, SamplesMovedWithTheCameraAgreeWithSamplesTracedThere) {
    const Scene scene = ballOnRealFloor(glm::vec3(1.0f));
    RenderSettings rs = renderSettings(64, 64, 2);
    rs.differential = true;
    rs.resolutionScale = 0.5f;
    auto r = Renderer::create(ctx(), scene, rs);
    ASSERT_TRUE(r.ok()) << r.message();
    Renderer& renderer = **r;
    const glm::dmat4 poseA(renderer.camera().worldFromCamera);
    auto traceAt = [&](const glm::dmat4& pose) {
        renderer.setCameraPose(pose);
        EXPECT_TRUE(renderer.holdView(false).ok());
        for (uint64_t frame = 1; frame <= 4; ++frame) {
            EXPECT_TRUE(renderer.holdView(true).ok());
            EXPECT_TRUE(renderer.renderPreviewFrame(8, frame).ok());
        }
        Result<std::vector<glm::vec4>> held = renderer.heldSamples();
        EXPECT_TRUE(held.ok());
        return held ? *held : std::vector<glm::vec4>{};
    };
    // 6 cm to the right and a turn of 1.7° to the right: the ball's outline moves about 6
    // pixels, the floor's texture less, the sky by the turn alone.
    const glm::dmat4 poseB = poseA * moved(0.06, -0.03);
    const std::vector<glm::vec4> fresh = traceAt(poseB);
    const std::vector<glm::vec4> left = traceAt(poseA);
    renderer.setCameraPose(poseB);
    ASSERT_TRUE(renderer.followView().ok());
    Result<std::vector<glm::vec4>> followed = renderer.heldSamples();
    ASSERT_TRUE(followed.ok());
    ASSERT_EQ(followed->size(), fresh.size());
    // Pixels whose mask disagrees (by more than a half) with the fresh samples', and how many
    // pixels both hold.
    auto disagreement = [&](const std::vector<glm::vec4>& held) {
        size_t differ = 0, both = 0;
        for (size_t i = 0; i < fresh.size() / 2; ++i) {
            const float n = held[2 * i + 1].x, m = fresh[2 * i + 1].x;
            if (!(n > 0.0f && m > 0.0f)) continue;
            ++both;
            differ += std::abs(held[2 * i].w / n - fresh[2 * i].w / m) > 0.5f ? 1 : 0;
        }
        return std::pair{differ, both};
    };
    const auto [movedDiffer, movedBoth] = disagreement(*followed);
    const auto [leftDiffer, leftBoth] = disagreement(left);
    EXPECT_GT(movedBoth, fresh.size() / 2 * 8 / 10);
    // Measured: 262 pixels left behind disagree, 10 moved ones (mixed pixels at the outline).
    EXPECT_GT(leftDiffer, 150u) << "the move should show along the ball's outline";
    EXPECT_LT(movedDiffer * 10, leftDiffer) << movedDiffer << " against " << leftDiffer;
    // The moved samples' distances are the new pose's.
    size_t far = 0;
    for (size_t i = 0; i < fresh.size() / 2; ++i) {
        const float n = (*followed)[2 * i + 1].x, m = fresh[2 * i + 1].x;
        if (!(n > 0.0f && m > 0.0f)) continue;
        const float a = (*followed)[2 * i + 1].y / n, b = fresh[2 * i + 1].y / m;
        far += std::abs(a - b) > 0.05f * b ? 1 : 0;
    }
    EXPECT_LT(far, movedDiffer + movedBoth / 20);
    // And they weigh kFollowKeep of what they weighed.
    double before = 0.0, after = 0.0;
    for (size_t i = 0; i < left.size() / 2; ++i) {
        before += left[2 * i + 1].x;
        after += (*followed)[2 * i + 1].x;
    }
    EXPECT_LT(after, before * HeldView::kFollowKeep * 1.001);
    EXPECT_GT(after, before * HeldView::kFollowKeep * 0.8);
}

TEST(HeldNormalCode, KeepsAUnitNormalWithinATenthOfADegree) {
    EXPECT_EQ(shader::heldNormalCode(glm::vec3(0.0f)), 0.0f);
    EXPECT_EQ(shader::heldNormalOf(0.0f), glm::vec3(0.0f));
    for (int i = 0; i < 2000; ++i) {
        // A spiral over the sphere, the poles and the octahedron's folds included.
        const float z = 1.0f - 2.0f * (float(i) + 0.5f) / 2000.0f;
        const float phi = 2.399963f * float(i);
        const float r = std::sqrt(1.0f - z * z);
        const glm::vec3 n(r * std::cos(phi), r * std::sin(phi), z);
        const float code = shader::heldNormalCode(n);
        EXPECT_EQ(code, std::floor(code)) << "an integer a float holds exactly";
        EXPECT_LE(code, 16777216.0f);
        const float cosine = glm::dot(shader::heldNormalOf(code), n);
        EXPECT_GT(cosine, std::cos(glm::radians(0.1f))) << i;
    }
}

// A history of 4 samples 2 m away on an upward-facing real surface: one more sample of that
// surface agrees; one of another surface (nearer, turned, or virtual) does not.
TEST(HeldHistoryAgrees, KeepsTheSameSurfaceAndDropsAnother) {
    const glm::vec3 up(0.0f, 1.0f, 0.0f);
    const glm::vec4 sums(1.0f, 1.0f, 1.0f, 0.0f);
    const glm::vec4 counts(4.0f, 8.0f, shader::heldNormalCode(up), PV_HELD_MOVED);
    const glm::vec3 tilted10(std::sin(glm::radians(10.0f)), std::cos(glm::radians(10.0f)), 0.0f);
    const glm::vec3 tilted40(std::sin(glm::radians(40.0f)), std::cos(glm::radians(40.0f)), 0.0f);
    EXPECT_TRUE(shader::heldHistoryAgrees(sums, counts, 2.05f, tilted10, 0.0f));
    EXPECT_FALSE(shader::heldHistoryAgrees(sums, counts, 1.8f, up, 0.0f)) << "nearer";
    EXPECT_FALSE(shader::heldHistoryAgrees(sums, counts, 2.3f, up, 0.0f)) << "farther";
    EXPECT_FALSE(shader::heldHistoryAgrees(sums, counts, 2.0f, tilted40, 0.0f)) << "turned";
    EXPECT_FALSE(shader::heldHistoryAgrees(sums, counts, 2.0f, up, 1.0f)) << "virtual";
    // A mixed outline's history (half virtual) agrees with either side's mask.
    const glm::vec4 mixed(1.0f, 1.0f, 1.0f, 2.0f);
    EXPECT_TRUE(shader::heldHistoryAgrees(mixed, counts, 2.0f, up, 1.0f));
    EXPECT_TRUE(shader::heldHistoryAgrees(mixed, counts, 2.0f, up, 0.0f));
    // Without a normal on either side (refinement's seed; a miss) only distance and mask count.
    const glm::vec4 noNormal(4.0f, 8.0f, 0.0f, PV_HELD_MOVED);
    EXPECT_TRUE(shader::heldHistoryAgrees(sums, noNormal, 2.0f, tilted40, 0.0f));
    EXPECT_TRUE(shader::heldHistoryAgrees(sums, counts, 2.0f, glm::vec3(0.0f), 0.0f));
    EXPECT_TRUE(shader::heldHistoryAgrees(sums, glm::vec4(0.0f), 9.0f, up, 1.0f)) << "empty";
}

// The held view's history after a move is kept only where the new camera's first sample in a
// pixel meets the same surface (SVGF's temporal test for the output-resolution history): seeded
// with a hold's own samples and moved (in place), it is kept; altered to say another surface
// (nearer, turned, or the virtual mask flipped), one frame from the same camera drops it.
TEST_F(HeldReprojectionTest, AMovedHistoryIsKeptOnlyWhereTheNewCameraMeetsItsSurface) {
    RenderSettings rs = renderSettings(64, 64, 2);
    rs.differential = true;
    rs.resolutionScale = 0.5f;
    auto r = Renderer::create(ctx(), ballOnRealFloor(glm::vec3(1.0f)), rs);
    ASSERT_TRUE(r.ok()) << r.message();
    Renderer& renderer = **r;
    ASSERT_TRUE(renderer.holdView(true).ok());
    for (uint64_t frame = 1; frame <= 4; ++frame)
        ASSERT_TRUE(renderer.renderPreviewFrame(8, frame).ok());
    Result<std::vector<glm::vec4>> held = renderer.heldSamples();
    ASSERT_TRUE(held.ok()) << held.message();
    const std::vector<glm::vec4> traced = *held;
    // The share of the `tested` pixels (by their seeded samples) whose history the next frame
    // kept, among those its samples reached.
    auto keptShare = [&](const std::vector<glm::vec4>& seed, auto tested) {
        EXPECT_TRUE(renderer.holdView(false).ok());
        EXPECT_TRUE(renderer.holdView(true).ok());
        EXPECT_TRUE(renderer.seedHeldView(seed).ok());
        EXPECT_TRUE(renderer.followView().ok());
        EXPECT_TRUE(renderer.renderPreviewFrame(1, 5).ok());
        Result<std::vector<glm::vec4>> after = renderer.heldSamples();
        EXPECT_TRUE(after.ok());
        size_t reached = 0, kept = 0;
        for (size_t i = 0; after && i < after->size() / 2; ++i) {
            const glm::vec4 c = (*after)[2 * i + 1];
            if (!(seed[2 * i + 1].x > 0.0f) || !tested(seed[2 * i], seed[2 * i + 1]) ||
                c.w == PV_HELD_MOVED)
                continue;
            ++reached;
            // Kept: kFollowKeep of the seed's samples plus this frame's; dropped: its alone.
            kept += c.x >= HeldView::kFollowKeep * seed[2 * i + 1].x ? 1 : 0;
        }
        EXPECT_GT(reached, traced.size() / 2 / 10);  // a quarter at 1 spp, less a filter
        return reached > 0 ? double(kept) / double(reached) : -1.0;
    };
    auto any = [](glm::vec4, glm::vec4) { return true; };
    const double asTraced = keptShare(traced, any);
    std::printf("the hold's own samples kept in %.1f %% of the pixels reached\n", 100.0 * asTraced);
    EXPECT_GT(asTraced, 0.95) << "only outline pixels may lose theirs";

    std::vector<glm::vec4> nearer = traced, turned = traced, flipped = traced;
    for (size_t i = 0; i < traced.size() / 2; ++i) {
        nearer[2 * i + 1].y *= 0.8f;
        const glm::vec3 n = shader::heldNormalOf(traced[2 * i + 1].z);
        if (n != glm::vec3(0.0f))  // a normal at right angles to it
            turned[2 * i + 1].z =
                shader::heldNormalCode(glm::normalize(glm::cross(n, glm::vec3(0.3f, 0.5f, 0.8f))));
        flipped[2 * i].w = traced[2 * i + 1].x - traced[2 * i].w;
    }
    auto hasNormal = [](glm::vec4, glm::vec4 c) { return c.z > 0.0f; };
    auto pure = [](glm::vec4 s, glm::vec4 c) { return s.w == 0.0f || s.w == c.x; };
    EXPECT_LT(keptShare(nearer, any), 0.01);
    EXPECT_LT(keptShare(turned, hasNormal), 0.01);
    EXPECT_LT(keptShare(flipped, pure), 0.01);
}

}  // namespace
}  // namespace previs::testing
