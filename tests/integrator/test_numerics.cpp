// Numerical extremes (issue 11): samples that turn NaN or cast a NaN ray are dropped without
// darkening their pixel or letting the plate through, NaN rays are culled before traversal, and
// NaN/Inf/negative plate values never reach the composite.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "render/plate.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"

namespace previs::testing {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

class NumericsTest : public GpuTest {};

// A black virtual emitter filling the view behind a virtual triangle that emits infinite
// radiance: every sample that meets the triangle is infinite and dropped; every other sample sees exactly the
// emitter's radiance and mask 1. So each pixel is either exactly the emitter (the mean of its
// kept samples, however many were dropped) or, with no sample kept, the plate; never a blend,
// which is what dividing by all samples (or counting dropped ones as mask 0) gives on the
// triangle's edge.
TEST_F(NumericsTest, DroppedSamplesNeitherDarkenNorShowThePlate) {
    Scene scene;
    const glm::vec3 le(0.25f, 0.5f, 1.0f);
    uint32_t emitting = addMaterial(scene, emitter(le));
    // The shader turns NaN material parameters black (its comparisons fail), but an infinite
    // emission (an emissive_strength beyond float's range) reaches the sample.
    Material poisoned = lambert(glm::vec3(0.5f));
    poisoned.emission = glm::vec3(std::numeric_limits<float>::infinity());
    uint32_t infinite = addMaterial(scene, poisoned);
    addQuad(scene, glm::vec3(0, 0, -3), glm::vec3(10, 0, 0), glm::vec3(0, 10, 0), emitting);
    // The lower-left half of the view; its hypotenuse runs through the image diagonal.
    addMesh(scene, {{-10, -10, -2}, {10, -10, -2}, {-10, 10, -2}},
            {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}}, {{0, 1, 2}}, infinite, false);
    scene.cameras.push_back(lookAt(glm::vec3(0), glm::vec3(0, 0, -1), glm::vec3(0, 1, 0), 0.8f));

    RenderSettings settings;
    settings.width = settings.height = 32;
    settings.maxDepth = 2;
    settings.differential = true;
    constexpr uint32_t kSpp = 16;
    auto r = Renderer::create(ctx(), scene, settings);
    ASSERT_TRUE(r) << r.message();
    const glm::vec3 plateValue(3.0f, 2.0f, 1.0f);
    ImageF plate;
    plate.width = settings.width;
    plate.height = settings.height;
    plate.channels = 3;
    for (uint32_t i = 0; i < settings.width * settings.height; ++i)
        plate.pixels.insert(plate.pixels.end(), {plateValue.r, plateValue.g, plateValue.b});
    ASSERT_TRUE((*r)->setPlate(plate));
    ASSERT_TRUE((*r)->render(kSpp));
    auto composite = (*r)->image(Aov::Composite);
    auto mixed = (*r)->image(Aov::Mixed);
    auto mask = (*r)->image(Aov::Mask);
    auto stats = (*r)->stats();
    ASSERT_TRUE(composite && mixed && mask && stats);

    size_t emitterPixels = 0, platePixels = 0;
    for (uint32_t i = 0; i < settings.width * settings.height; ++i) {
        const float m = mask->pixels[i];
        ASSERT_TRUE(std::isfinite(m));
        bool isEmitter = true, isPlate = m == 0.0f;
        for (int c = 0; c < 3; ++c) {
            const float v = composite->pixels[3 * i + c];
            ASSERT_TRUE(std::isfinite(v)) << "pixel " << i;
            ASSERT_TRUE(std::isfinite(mixed->pixels[3 * i + c]));
            // Kahan-summed means of identical values: a few ULPs at most.
            isEmitter &= std::abs(v - le[c]) <= 1e-5f * le[c] && std::abs(m - 1.0f) <= 1e-6f;
            isPlate &= v == plateValue[c] && mixed->pixels[3 * i + c] == 0.0f;
        }
        EXPECT_TRUE(isEmitter || isPlate)
            << "pixel (" << i % settings.width << ", " << i / settings.width << "): composite "
            << composite->pixels[3 * i] << " " << composite->pixels[3 * i + 1] << " "
            << composite->pixels[3 * i + 2] << ", mask " << m;
        emitterPixels += isEmitter;
        platePixels += isPlate && !isEmitter;
    }
    // Half the view each, less the diagonal.
    EXPECT_GT(emitterPixels, size_t(400));
    EXPECT_GT(platePixels, size_t(400));
    // Every sample of a plate pixel was dropped, and some on the diagonal.
    EXPECT_GT(stats->nonFiniteSamples, uint32_t(platePixels * kSpp));
    EXPECT_LT(stats->nonFiniteSamples, settings.width * settings.height * kSpp);
}

// A camera at a NaN position casts rays with a NaN origin. The slab test lets NaN through, so
// before the cull each such ray walked every node of the BVH; now it is culled at once, counted
// and its sample dropped: the image stays finite (and black: no sample counts).
TEST_F(NumericsTest, NanRaysAreCulledCountedAndDropped) {
    Scene scene;
    addSphere(scene, glm::vec3(0, 0, -3), 1.0f, addMaterial(scene, lambert(glm::vec3(0.5f))));
    scene.environment = uniformEnvironment(glm::vec3(1.0f));
    Camera camera = lookAt(glm::vec3(0), glm::vec3(0, 0, -1), glm::vec3(0, 1, 0), 0.8f);
    camera.worldFromCamera[3] = glm::vec4(kNaN, 0.0f, 0.0f, 1.0f);
    scene.cameras.push_back(camera);
    RenderSettings settings;
    settings.width = settings.height = 16;
    settings.maxDepth = 3;
    auto r = Renderer::create(ctx(), scene, settings);
    ASSERT_TRUE(r) << r.message();
    constexpr uint32_t kSpp = 4;
    ASSERT_TRUE((*r)->render(kSpp));
    auto stats = (*r)->stats();
    ASSERT_TRUE(stats);
    const uint32_t samples = settings.width * settings.height * kSpp;
    EXPECT_EQ(stats->nonFiniteSamples, samples);
    EXPECT_EQ(stats->nonFiniteRays, samples);  // the camera ray; nothing traced after it
    auto image = (*r)->image();
    ASSERT_TRUE(image);
    for (float v : image->pixels) ASSERT_EQ(v, 0.0f);
    if (ctx().isCpuDevice()) {
        // Loop iterations are counted on the CPU device only. A ray that walks the BVH runs at
        // least one iteration per node; a culled one a handful per sample.
        const size_t nodes = (*r)->bvh().wideNodes.size();
        ASSERT_GT(nodes, size_t(100));
        EXPECT_LT((*r)->loopIterationsPerSample(), 16.0) << nodes << " BVH nodes";
    }
}

// A plate with NaN, ±Inf and negative values: the composite has none of them, and where no
// sample meets a virtual object it is the repaired plate (docs/plates.md).
TEST_F(NumericsTest, NonFinitePlateValuesNeverReachTheComposite) {
    Scene scene;
    addQuad(scene, glm::vec3(0, 0, -3), glm::vec3(10, 0, 0), glm::vec3(0, 10, 0),
            addMaterial(scene, lambert(glm::vec3(0.5f))), true);
    scene.environment = uniformEnvironment(glm::vec3(1.0f));
    scene.cameras.push_back(lookAt(glm::vec3(0), glm::vec3(0, 0, -1), glm::vec3(0, 1, 0), 0.8f));
    RenderSettings settings;
    settings.width = settings.height = 8;
    settings.differential = true;
    auto r = Renderer::create(ctx(), scene, settings);
    ASSERT_TRUE(r) << r.message();
    ImageF plate;
    plate.width = plate.height = 8;
    plate.channels = 3;
    plate.pixels.assign(8 * 8 * 3, 0.5f);
    plate.pixels[3 * 9 + 0] = kNaN;
    plate.pixels[3 * 20 + 1] = std::numeric_limits<float>::infinity();
    plate.pixels[3 * 30 + 2] = -std::numeric_limits<float>::infinity();
    plate.pixels[3 * 40 + 0] = -0.25f;
    ASSERT_TRUE((*r)->setPlate(plate, "test plate"));
    EXPECT_EQ((*r)->plateValuesRepaired(), 4u);
    ASSERT_TRUE((*r)->render(2));
    auto composite = (*r)->image(Aov::Composite);
    ASSERT_TRUE(composite);
    // Only real geometry: the composite is the plate (Eq. 1 with M = 0, L_om = L_or).
    for (size_t i = 0; i < composite->pixels.size(); ++i) {
        const float expected = i == 3 * 40 ? 0.0f : 0.5f;
        EXPECT_EQ(composite->pixels[i], expected) << "value " << i;
    }
}

}  // namespace
}  // namespace previs::testing
