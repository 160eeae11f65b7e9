// The preview's resampling of the distant light (ReSTIR at the first rough hit;
// gpu/shaders/distant_light_resampling.glsl, RenderSettings::previewResampling), against a deep
// reference: a virtual ball on a real floor in a dim room with a bright softbox in the
// environment, as the demo's set. Resampling must lower a preview frame's error, keep the
// mean of many frames within its stated bias of the reference, keep the differential's
// identity bit for bit, and change nothing in refinement.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <span>

#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

constexpr uint32_t kWidth = 48;
constexpr uint32_t kHeight = 36;

// A dim room (0.2) with a softbox of radiance 400 about 50° up, behind the camera's left: the
// ball's shadow falls on the floor in front of it.
EnvironmentMap softboxRoom() {
    EnvironmentMap env = uniformEnvironment(glm::vec3(0.2f), 64, 32);
    for (uint32_t y = 6; y < 9; ++y)
        for (uint32_t x = 20; x < 24; ++x) env.radiance[y * env.width + x] = glm::vec3(400.0f);
    return env;
}

// scene_builders' ballOnRealFloor under the softbox room; without the ball, its floor alone.
Scene ballUnderSoftbox(bool withBall = true) {
    Scene s = ballOnRealFloor(glm::vec3(0.2f));
    if (!withBall) {
        Scene floor;
        addQuad(floor, glm::vec3(0.0f), glm::vec3(0.0f, 0.0f, 1.0f), glm::vec3(2.0f, 0.0f, 0.0f),
                addMaterial(floor, lambert(glm::vec3(0.5f))), /*real=*/true);
        floor.cameras = s.cameras;
        s = floor;
    }
    s.environment = softboxRoom();
    return s;
}

class DistantLightResamplingTest : public GpuTest {
protected:
    static RenderSettings settings(bool resampling) {
        RenderSettings rs = renderSettings(kWidth, kHeight, 3);
        rs.previewResampling = resampling;
        rs.differential = true;
        return rs;
    }
    // The composite's plate-free part, M·L_om + (1 − M)(L_om − L_or) per pixel and channel
    // (render/film.h's Eq. 1 without its plate term): what the error of the preview's picture is
    // made of, the plate having none.
    static std::vector<float> added(Renderer& r) {
        Result<ImageF> mixed = r.image(Aov::Mixed);
        Result<ImageF> real = r.image(Aov::Real);
        Result<ImageF> mask = r.image(Aov::Mask);
        EXPECT_TRUE(mixed.ok() && real.ok() && mask.ok());
        if (!mixed || !real || !mask) return {};
        std::vector<float> d(mixed->pixels.size());
        for (size_t i = 0; i < d.size(); ++i) {
            const float m = mask->pixels[i / 3];
            d[i] = mixed->pixels[i] - (1.0f - m) * real->pixels[i];
        }
        return d;
    }
    // The solutions and the added term of `frames` preview frames of 1 sample each, from `seed`.
    struct Frames {
        std::vector<std::vector<float>> mixed, real, added;
    };
    Frames previewFrames(const Scene& scene, bool resampling, uint32_t frames, uint32_t seed,
                         std::span<const EstimatedLightSource> lights = {}) {
        RenderSettings rs = settings(resampling);
        rs.seed = seed;
        auto r = Renderer::create(ctx(), scene, rs);
        EXPECT_TRUE(r.ok()) << r.message();
        Frames f;
        if (!r) return f;
        if (!lights.empty()) {
            EXPECT_TRUE((*r)->setEstimatedLights(lights).ok());
        }
        for (uint32_t k = 0; k < frames; ++k) {
            EXPECT_TRUE((*r)->renderPreviewFrame(1, k + 1).ok());
            Result<ImageF> mixed = (*r)->image(Aov::Mixed);
            Result<ImageF> real = (*r)->image(Aov::Real);
            EXPECT_TRUE(mixed.ok() && real.ok());
            if (!mixed || !real) return f;
            f.mixed.push_back(mixed->pixels);
            f.real.push_back(real->pixels);
            f.added.push_back(added(**r));
        }
        return f;
    }
    // A reference of 512 samples: its noise (RMSE about 0.035 here) adds in quadrature to a
    // frame's error of 0.4–0.8, under 1 % of it.
    struct Reference {
        std::vector<float> mixed, added;
    };
    Reference reference(const Scene& scene, std::span<const EstimatedLightSource> lights = {}) {
        auto r = Renderer::create(ctx(), scene, settings(false));
        EXPECT_TRUE(r.ok()) << r.message();
        if (!r) return {};
        if (!lights.empty()) {
            EXPECT_TRUE((*r)->setEstimatedLights(lights).ok());
        }
        EXPECT_TRUE((*r)->render(512).ok());
        Result<ImageF> mixed = (*r)->image(Aov::Mixed);
        EXPECT_TRUE(mixed.ok());
        if (!mixed) return {};
        return {mixed->pixels, added(**r)};
    }
};

double rmse(const std::vector<float>& a, const std::vector<float>& b) {
    double sum = 0.0;
    for (size_t i = 0; i < a.size(); ++i) sum += double(a[i] - b[i]) * (a[i] - b[i]);
    return std::sqrt(sum / double(std::max<size_t>(a.size(), 1)));
}

double sumOf(const std::vector<float>& v) {
    double s = 0.0;
    for (float x : v) s += x;
    return s;
}

std::vector<float> meanOf(const std::vector<std::vector<float>>& frames, size_t from) {
    std::vector<float> mean(frames.front().size(), 0.0f);
    for (size_t k = from; k < frames.size(); ++k)
        for (size_t i = 0; i < mean.size(); ++i) mean[i] += frames[k][i];
    for (float& m : mean) m /= float(frames.size() - from);
    return mean;
}

// Once its history has built up (8 frames), a resampled preview frame of 1 sample is closer to
// the reference than a frame of one light sample: the picture's error falls by 42 % (measured
// 0.80 → 0.47). What the ball adds falls by less (0.50 → 0.47): most of its error is the soft
// shadow's visibility, which no target holds (each sample still casts one shadow ray).
TEST_F(DistantLightResamplingTest, AFrameIsCloserToTheReferenceThanOneLightSample) {
    const Scene scene = ballUnderSoftbox();
    const Reference ref = reference(scene);
    const std::vector<float>& refMixed = ref.mixed;
    const std::vector<float>& refAdded = ref.added;
    double error[2][2] = {};  // [resampling][picture, added]
    for (bool resampling : {false, true}) {
        const Frames f = previewFrames(scene, resampling, 16, 1);
        for (size_t k = 8; k < f.mixed.size(); ++k) {
            error[resampling][0] += rmse(f.mixed[k], refMixed) / 8.0;
            error[resampling][1] += rmse(f.added[k], refAdded) / 8.0;
        }
    }
    std::printf(
        "per-frame RMSE, one light sample / resampled: picture %.4f / %.4f, added %.4f / "
        "%.4f\n",
        error[0][0], error[1][0], error[0][1], error[1][1]);
    EXPECT_LT(error[1][0], 0.7 * error[0][0]);
    EXPECT_LT(error[1][1], error[0][1]);
}

// [lighting] mode = "lights": up to 16 estimated lights (cone lights) over a residual map. One
// light sample picks a light uniformly, so the dim ones waste most samples; resampling weighs
// the candidates by what each gives the surface, and the frame's error falls by more than half.
TEST_F(DistantLightResamplingTest, AmongManyEstimatedLightsAFrameFindsTheOnesThatMatter) {
    Scene scene = ballUnderSoftbox();
    scene.environment = uniformEnvironment(glm::vec3(0.05f));
    std::vector<EstimatedLightSource> lights;
    for (int i = 0; i < 12; ++i) {
        const float azimuth = 0.52f * float(i);
        const float elevation = 0.35f + 0.08f * float(i % 5);
        EstimatedLightSource l;
        l.direction = glm::vec3(std::cos(elevation) * std::cos(azimuth), std::sin(elevation),
                                std::cos(elevation) * std::sin(azimuth));
        l.solidAngleSr = 0.02f;
        // Two lamps carry most of the light, as on a set: 2000 against 5–60.
        l.radiance = glm::vec3(i == 3 || i == 8 ? 2000.0f : 5.0f + 5.0f * float(i));
        lights.push_back(l);
    }
    const std::vector<float> refMixed = reference(scene, lights).mixed;
    double error[2] = {};
    for (bool resampling : {false, true}) {
        const Frames f = previewFrames(scene, resampling, 16, 1, lights);
        for (size_t k = 8; k < f.mixed.size(); ++k)
            error[resampling] += rmse(f.mixed[k], refMixed) / 8.0;
    }
    std::printf("per-frame RMSE under 12 lights, one light sample / resampled: %.4f / %.4f\n",
                error[0], error[1]);
    EXPECT_LT(error[1], 0.5 * error[0]);
}

// The regions whose sums the bias is measured on, from the reference: the floor the ball does
// not shade, the ball's shadow on it (its energy: what the ball takes, L_or − L_om) and the
// ball itself.
struct RegionSums {
    double floor = 0.0, shadow = 0.0, ball = 0.0;
};
RegionSums regionSums(const std::vector<float>& mixed, const std::vector<float>& real,
                      const std::vector<float>& refMixed, const std::vector<float>& refReal,
                      const std::vector<float>& refMask) {
    RegionSums s;
    for (size_t i = 0; i < mixed.size(); ++i) {
        const float m = refMask[i / 3];
        if (m > 0.99f) s.ball += mixed[i];
        if (m > 0.0f) continue;
        if (refMixed[i] < refReal[i] - 0.02f)
            s.shadow += real[i] - mixed[i];
        else
            s.floor += mixed[i];
    }
    return s;
}

// The biased combination (1/M, no visibility in the target) against a 2048-sample
// reference: 8 independent sequences of 32 resampled frames each. Reused samples correlate a
// sequence's frames, so one sequence's mean says little (the shadow's energy varies by ±2 %
// between sequences of 32 frames; ±0.7 % between sequences of 64 without resampling); the mean of
// the sequences' ratios must lie within three of its standard errors of the reference plus the
// combination's stated bias: 1 % on the flat floor (its neighbours' targets are this pixel's), 5 %
// on the curved ball, whose neighbours within 6 pixels (40 % of this 15-pixel ball) see other
// hemispheres (measured −3 %: darker, as 1/M predicts).
TEST_F(DistantLightResamplingTest, ManySequencesMeanIsWithinItsBiasOfTheReference) {
    const Scene scene = ballUnderSoftbox();
    auto ref = Renderer::create(ctx(), scene, settings(false));
    ASSERT_TRUE(ref.ok()) << ref.message();
    ASSERT_TRUE((*ref)->render(2048).ok());
    Result<ImageF> refMixed = (*ref)->image(Aov::Mixed);
    Result<ImageF> refReal = (*ref)->image(Aov::Real);
    Result<ImageF> refMask = (*ref)->image(Aov::Mask);
    ASSERT_TRUE(refMixed.ok() && refReal.ok() && refMask.ok());
    const RegionSums truth = regionSums(refMixed->pixels, refReal->pixels, refMixed->pixels,
                                        refReal->pixels, refMask->pixels);
    constexpr int kSequences = 8;
    std::vector<double> ratios[3];
    for (int k = 0; k < kSequences; ++k) {
        const Frames f = previewFrames(scene, true, 32, 1000 + 7919 * uint32_t(k));
        const RegionSums s = regionSums(meanOf(f.mixed, 0), meanOf(f.real, 0), refMixed->pixels,
                                        refReal->pixels, refMask->pixels);
        ratios[0].push_back(s.floor / truth.floor);
        ratios[1].push_back(s.shadow / truth.shadow);
        ratios[2].push_back(s.ball / truth.ball);
    }
    const char* names[3] = {"floor", "shadow energy", "ball"};
    const double statedBias[3] = {0.01, 0.01, 0.05};
    for (int r = 0; r < 3; ++r) {
        double mean = 0.0, square = 0.0;
        for (double x : ratios[r]) mean += x / kSequences;
        for (double x : ratios[r]) square += (x - mean) * (x - mean) / (kSequences - 1);
        const double standardError = std::sqrt(square / kSequences);
        std::printf("%s: %.4f of the reference, standard error %.4f\n", names[r], mean,
                    standardError);
        EXPECT_NEAR(mean, 1.0, 3.0 * standardError + statedBias[r]) << names[r];
    }
}

// With no virtual object both solutions shade the one direction chosen, seen past the same
// geometry: L_om and L_or are equal bit for bit.
TEST_F(DistantLightResamplingTest, WithoutVirtualObjectsBothSolutionsAreEqual) {
    auto r = Renderer::create(ctx(), ballUnderSoftbox(false), settings(true));
    ASSERT_TRUE(r.ok()) << r.message();
    for (uint64_t k = 1; k <= 4; ++k) {
        ASSERT_TRUE((*r)->renderPreviewFrame(2, k).ok());
        Result<ImageF> mixed = (*r)->image(Aov::Mixed);
        Result<ImageF> real = (*r)->image(Aov::Real);
        ASSERT_TRUE(mixed.ok() && real.ok());
        EXPECT_EQ(mixed->pixels, real->pixels) << "frame " << k;
        EXPECT_GT(sumOf(mixed->pixels), 0.0);
    }
}

// A change of light starts the reservoirs afresh (Renderer::setEnvironment): their weights were
// the old light's. The frame after the change is the very frame a renderer made under the new
// light draws first, with no history.
TEST_F(DistantLightResamplingTest, ANewLightStartsTheReservoirsAfresh) {
    EnvironmentMap moved = softboxRoom();
    std::rotate(moved.radiance.begin(), moved.radiance.begin() + 16, moved.radiance.end());
    Scene before = ballUnderSoftbox();
    Scene after = before;
    after.environment = moved;
    auto changed = Renderer::create(ctx(), before, settings(true));
    auto fresh = Renderer::create(ctx(), after, settings(true));
    ASSERT_TRUE(changed.ok() && fresh.ok());
    for (uint64_t k = 1; k <= 4; ++k) ASSERT_TRUE((*changed)->renderPreviewFrame(1, k).ok());
    ASSERT_TRUE((*changed)->setEnvironment(std::make_shared<EnvironmentMap>(moved)).ok());
    ASSERT_TRUE((*changed)->renderPreviewFrame(1, 5).ok());
    ASSERT_TRUE((*fresh)->renderPreviewFrame(1, 5).ok());
    Result<ImageF> a = (*changed)->image(Aov::Mixed);
    Result<ImageF> b = (*fresh)->image(Aov::Mixed);
    ASSERT_TRUE(a.ok() && b.ok());
    EXPECT_EQ(a->pixels, b->pixels);
    // And the light kept: the next frame reuses this one's reservoirs.
    ASSERT_TRUE((*changed)->renderPreviewFrame(1, 6).ok());
    ASSERT_TRUE((*fresh)->renderPreviewFrame(1, 6).ok());
    EXPECT_EQ((*changed)->image(Aov::Mixed)->pixels, (*fresh)->image(Aov::Mixed)->pixels);
}

// Refinement never resamples: a renderer with the preview's resampling refines the very image
// one without it does, and until a preview frame it holds no reservoirs.
TEST_F(DistantLightResamplingTest, RefinementIsUnchangedAndPaysNothing) {
    const Scene scene = ballUnderSoftbox();
    std::vector<float> images[2];
    uint64_t bytes[2] = {};
    for (bool resampling : {false, true}) {
        auto r = Renderer::create(ctx(), scene, settings(resampling));
        ASSERT_TRUE(r.ok()) << r.message();
        ASSERT_TRUE((*r)->render(8).ok());
        Result<ImageF> mixed = (*r)->image(Aov::Mixed);
        ASSERT_TRUE(mixed.ok());
        images[resampling] = mixed->pixels;
        bytes[resampling] = (*r)->deviceBytes();
    }
    EXPECT_EQ(images[0], images[1]);
    EXPECT_EQ(bytes[0], bytes[1]);
}

}  // namespace
}  // namespace previs::testing
