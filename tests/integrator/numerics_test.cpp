// Numerical extremes (issue 11): a set far from the world origin renders as at the origin
// (camera-relative rendering, transforms composed in double); samples that turn NaN or cast a
// NaN ray are dropped without darkening their pixel or letting the plate through, NaN rays are
// culled before traversal, and NaN/Inf/negative plate values never reach the composite.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <limits>
#include <nlohmann/json.hpp>
#include <tuple>

#include "image/image.h"
#include "render/plate.h"
#include "scene/gltf_loader.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/scene_builders.h"
#include "tests/support/temp_dir.h"

namespace previs::testing {
namespace {

using nlohmann::json;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

class NumericsTest : public GpuTest {};

// A black virtual emitter filling the view behind a virtual triangle that emits infinite
// radiance: every sample that meets the triangle is infinite and dropped; every other sample
// sees exactly the emitter's radiance and mask 1. So each pixel is either exactly the emitter
// (the mean of its kept samples, however many were dropped) or, with no sample kept, the plate;
// never a blend, which is what dividing by all samples (or counting dropped ones as mask 0)
// gives on the triangle's edge.
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

    RenderSettings settings = renderSettings(32, 32, 2);
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
    ASSERT_TRUE((*r)->film().setPlate(plate));
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
    // Every sample of a plate pixel was dropped, and some on the diagonal; the kept and the
    // dropped add up to all samples.
    EXPECT_GT(stats->nonFiniteSamples, uint32_t(platePixels * kSpp));
    auto counts = (*r)->image(Aov::SampleCount);
    ASSERT_TRUE(counts);
    double kept = 0.0;
    for (float n : counts->pixels) kept += n;
    EXPECT_EQ(kept + stats->nonFiniteSamples, double(settings.width * settings.height * kSpp));
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
    RenderSettings settings = renderSettings(16, 16, 3);
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
        // least one iteration per node; a culled one a handful per sample, on top of the
        // dispatch's fixed loops over the accumulation slots (initialise and write back).
        const size_t nodes = (*r)->bvh().wideNodes.size();
        ASSERT_GT(nodes, size_t(100));
        const double fixedLoops = 2.0 * PV_ACCUM_COUNT;
        EXPECT_LT((*r)->diagnostics().loopIterationsPerSample(), fixedLoops + 10.0)
            << nodes << " BVH nodes";
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
    ASSERT_TRUE((*r)->film().setPlate(plate, "test plate"));
    EXPECT_EQ((*r)->film().plateValuesRepaired(), 4u);
    ASSERT_TRUE((*r)->render(2));
    auto composite = (*r)->image(Aov::Composite);
    ASSERT_TRUE(composite);
    // Only real geometry: the composite is the plate (Eq. 1 with M = 0, L_om = L_or).
    for (size_t i = 0; i < composite->pixels.size(); ++i) {
        const float expected = i == 3 * 40 ? 0.0f : 0.5f;
        EXPECT_EQ(composite->pixels[i], expected) << "value " << i;
    }
}

// An EXR plate as another tool writes it, with NaN, ±Inf and negative values: after the repair
// (docs/plates.md) every value is finite and non-negative, NaN/Inf became their neighbours'
// mean, negatives 0, and everything else is untouched.
TEST(PlateFile, NonFiniteAndNegativeValuesAreRepaired) {
    ImageF written;
    written.width = 4;
    written.height = 3;
    written.channels = 3;
    for (uint32_t i = 0; i < 4 * 3 * 3; ++i) written.pixels.push_back(0.1f * float(i % 7) + 0.2f);
    const float inf = std::numeric_limits<float>::infinity();
    written.pixels[3 * 5 + 1] = kNaN;    // (1, 1) green: 8 finite neighbours
    written.pixels[3 * 0 + 0] = inf;     // (0, 0) red: a corner, 3 neighbours
    written.pixels[3 * 6 + 2] = -inf;    // (2, 1) blue
    written.pixels[3 * 11 + 0] = -0.5f;  // (3, 2) red: negative
    written.pixels[3 * 11 + 1] = -0.0f;  // -0 is not negative: kept
    const std::string path = (scratchDir("previs_numerics_test") / "bad_plate.exr").string();
    ASSERT_TRUE(writeExr(path, written));
    auto plate = readImage(path);
    ASSERT_TRUE(plate) << plate.message();
    ASSERT_TRUE(std::isnan(plate->pixels[3 * 5 + 1]));  // the file really holds them
    const ImageF given = *plate;
    const PlateRepair repair = repairPlate(*plate);
    EXPECT_EQ(repair.nonFinite, 3u);
    EXPECT_EQ(repair.negative, 1u);
    auto neighbourMean = [&](int x, int y, int c) {
        double sum = 0.0;
        int n = 0;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                const int nx = x + dx, ny = y + dy;
                if ((dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= 4 || ny >= 3) continue;
                const float v = given.at(uint32_t(nx), uint32_t(ny), uint32_t(c));
                if (std::isfinite(v) && v >= 0.0f) {
                    sum += v;
                    ++n;
                }
            }
        return float(sum / n);
    };
    EXPECT_FLOAT_EQ(plate->at(1, 1, 1), neighbourMean(1, 1, 1));
    EXPECT_FLOAT_EQ(plate->at(0, 0, 0), neighbourMean(0, 0, 0));
    EXPECT_FLOAT_EQ(plate->at(2, 1, 2), neighbourMean(2, 1, 2));
    EXPECT_EQ(plate->at(3, 2, 0), 0.0f);
    for (size_t i = 0; i < plate->pixels.size(); ++i) {
        EXPECT_TRUE(std::isfinite(plate->pixels[i]) && plate->pixels[i] >= 0.0f) << i;
        if (std::isfinite(given.pixels[i]) && given.pixels[i] >= 0.0f) {
            EXPECT_EQ(std::memcmp(&plate->pixels[i], &given.pixels[i], 4), 0) << i;
        }
    }
    // A clean plate comes back bit for bit.
    ImageF clean = written;
    for (float& v : clean.pixels) v = std::abs(v) < inf ? std::abs(v) : 1.0f;
    const ImageF before = clean;
    EXPECT_EQ(repairPlate(clean).total(), 0u);
    EXPECT_EQ(std::memcmp(clean.pixels.data(), before.pixels.data(), 4 * before.pixels.size()), 0);
}

// ---- Scale: a set far from the world origin renders as it does at the origin. ----

struct MeshData {
    std::vector<glm::vec3> positions;
    std::vector<glm::vec3> normals;
    std::vector<uint16_t> indices;
};

MeshData unitCube() {  // [-0.5, 0.5]³, flat normals
    MeshData m;
    for (int axis = 0; axis < 3; ++axis)
        for (float side : {-1.0f, 1.0f}) {
            glm::vec3 n(0.0f);
            n[axis] = side;
            const glm::vec3 u = axis == 0 ? glm::vec3(0, 1, 0) : glm::vec3(1, 0, 0);
            const glm::vec3 v = glm::cross(n, u);
            const uint16_t base = uint16_t(m.positions.size());
            for (auto [a, b] : {std::pair{-1, -1}, {1, -1}, {1, 1}, {-1, 1}}) {
                m.positions.push_back(0.5f * (n + float(a) * u + float(b) * v));
                m.normals.push_back(n);
            }
            for (int k : {0, 1, 2, 0, 2, 3}) m.indices.push_back(uint16_t(base + k));
        }
    return m;
}

MeshData unitSphere(int rings = 16, int segments = 32) {  // radius 1, smooth normals
    MeshData m;
    for (int i = 0; i <= rings; ++i) {
        const float theta = float(M_PI) * float(i) / float(rings);
        for (int j = 0; j <= segments; ++j) {
            const float phi = 2.0f * float(M_PI) * float(j) / float(segments);
            const glm::vec3 p(std::sin(theta) * std::cos(phi), std::cos(theta),
                              -std::sin(theta) * std::sin(phi));
            m.positions.push_back(p);
            m.normals.push_back(p);
        }
    }
    for (int i = 0; i < rings; ++i)
        for (int j = 0; j < segments; ++j) {
            const uint16_t a = uint16_t(i * (segments + 1) + j), b = uint16_t(a + segments + 1);
            for (uint16_t k : {a, b, uint16_t(a + 1), uint16_t(a + 1), b, uint16_t(b + 1)})
                m.indices.push_back(k);
        }
    return m;
}

// The test set of the issue, written as a glTF file with everything under one root node
// translated by `offsetM` (in the file's doubles): a floor, a cube, a diffuse and a mirror
// sphere, a 1 cm cube resting on the floor, a point light, a wide camera and a close-up of the
// small cube's contact shadow.
std::string writeSet(const std::string& name, const glm::dvec3& offsetM) {
    json doc = {
        {"asset", {{"version", "2.0"}}},
        {"extensionsUsed", {"KHR_lights_punctual"}},
        {"scene", 0},
        {"scenes", {{{"nodes", {0}}}}},
        {"nodes",
         {{{"name", "set"},
           {"translation", {offsetM.x, offsetM.y, offsetM.z}},
           {"children", json::array()}}}},
        {"materials",
         {{{"name", "grey"},
           {"pbrMetallicRoughness",
            {{"baseColorFactor", {0.6, 0.6, 0.6, 1}}, {"metallicFactor", 0.0}}}},
          {{"name", "red"},
           {"pbrMetallicRoughness",
            {{"baseColorFactor", {0.7, 0.2, 0.1, 1}}, {"metallicFactor", 0.0}}}},
          {{"name", "mirror"},
           {"pbrMetallicRoughness",
            {{"baseColorFactor", {1, 1, 1, 1}},
             {"metallicFactor", 1.0},
             {"roughnessFactor", 0.0}}}}}},
        {"meshes", json::array()},
        {"accessors", json::array()},
        {"bufferViews", json::array()},
        {"cameras",
         {{{"type", "perspective"}, {"perspective", {{"yfov", 0.7}, {"znear", 0.01}}}},
          {{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.001}}}}}},
        {"extensions",
         {{"KHR_lights_punctual", {{"lights", {{{"type", "point"}, {"intensity", 40.0}}}}}}}}};
    std::vector<uint8_t> bin;
    auto accessor = [&](const void* data, size_t bytes, int componentType, const char* type,
                        size_t count) {
        while (bin.size() % 4) bin.push_back(0);
        doc["bufferViews"].push_back(
            {{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes}});
        bin.insert(bin.end(), static_cast<const uint8_t*>(data),
                   static_cast<const uint8_t*>(data) + bytes);
        json a = {{"bufferView", doc["bufferViews"].size() - 1},
                  {"componentType", componentType},
                  {"type", type},
                  {"count", count}};
        if (componentType == 5126) {  // POSITION needs its bounds
            glm::vec3 lo(1e30f), hi(-1e30f);
            for (size_t i = 0; i < count; ++i) {
                lo = glm::min(lo, static_cast<const glm::vec3*>(data)[i]);
                hi = glm::max(hi, static_cast<const glm::vec3*>(data)[i]);
            }
            a["min"] = {lo.x, lo.y, lo.z};
            a["max"] = {hi.x, hi.y, hi.z};
        }
        doc["accessors"].push_back(a);
        return doc["accessors"].size() - 1;
    };
    auto mesh = [&](const MeshData& m, int material) {
        const size_t p =
            accessor(m.positions.data(), m.positions.size() * 12, 5126, "VEC3", m.positions.size());
        const size_t n =
            accessor(m.normals.data(), m.normals.size() * 12, 5126, "VEC3", m.normals.size());
        const size_t i =
            accessor(m.indices.data(), m.indices.size() * 2, 5123, "SCALAR", m.indices.size());
        doc["meshes"].push_back({{"primitives",
                                  {{{"attributes", {{"POSITION", p}, {"NORMAL", n}}},
                                    {"indices", i},
                                    {"material", material}}}}});
        return doc["meshes"].size() - 1;
    };
    const size_t cube = mesh(unitCube(), 0), redCube = mesh(unitCube(), 1);
    const size_t sphere = mesh(unitSphere(), 0), mirror = mesh(unitSphere(), 2);
    auto child = [&](json node) {
        doc["nodes"].push_back(node);
        doc["nodes"][0]["children"].push_back(doc["nodes"].size() - 1);
    };
    child({{"name", "floor"},
           {"mesh", cube},
           {"translation", {0, -0.05, 0}},
           {"scale", {4, 0.1, 4}}});
    child({{"name", "box"},
           {"mesh", redCube},
           {"translation", {-0.6, 0.25, -0.1}},
           {"rotation", {0, 0.2588190451, 0, 0.9659258263}},
           {"scale", {0.5, 0.5, 0.5}}});
    child({{"name", "ball"},
           {"mesh", sphere},
           {"translation", {0.1, 0.25, 0.55}},
           {"scale", {0.25, 0.25, 0.25}}});
    child({{"name", "mirror"},
           {"mesh", mirror},
           {"translation", {0.55, 0.35, -0.25}},
           {"scale", {0.35, 0.35, 0.35}}});
    child({{"name", "tiny"},
           {"mesh", cube},
           {"translation", {0.0, 0.005, 0.25}},
           {"scale", {0.01, 0.01, 0.01}}});
    child({{"name", "lamp"},
           {"translation", {1.0, 2.5, 1.5}},
           {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
    // glm::lookAt gives cameraFromWorld; the node wants worldFromCamera.
    auto cameraNode = [&](const char* nodeName, int camera, glm::dvec3 eye, glm::dvec3 target) {
        const glm::dmat4 pose = glm::inverse(glm::lookAt(eye, target, glm::dvec3(0, 1, 0)));
        json matrix = json::array();
        for (int c = 0; c < 4; ++c)
            for (int r = 0; r < 4; ++r) matrix.push_back(pose[c][r]);
        child({{"name", nodeName}, {"camera", camera}, {"matrix", matrix}});
    };
    cameraNode("wide", 0, {0.3, 1.2, 2.6}, {0.0, 0.2, 0.0});
    cameraNode("closeup", 1, {0.035, 0.03, 0.3}, {0.0, 0.004, 0.25});
    doc["buffers"] = {{{"byteLength", bin.size()}, {"uri", name + ".bin"}}};
    // PREVIS_NUMERICS_SCENES keeps the sets (to render them with `previs render`, e.g. with an
    // older build for a before/after comparison).
    const char* keep = std::getenv("PREVIS_NUMERICS_SCENES");
    const std::filesystem::path dir = keep ? keep : scratchDir("previs_numerics_test");
    std::ofstream(dir / (name + ".bin"), std::ios::binary)
        .write(reinterpret_cast<const char*>(bin.data()), std::streamsize(bin.size()));
    std::ofstream(dir / (name + ".gltf")) << doc.dump(1);
    return (dir / (name + ".gltf")).string();
}

// The metric: per 8×8 block and channel the block's mean; the RMS over blocks and
// channels of the difference of two images' block means.
double blockError(const ImageF& a, const ImageF& b) {
    double sum = 0.0;
    size_t n = 0;
    for (uint32_t by = 0; by + 8 <= a.height; by += 8)
        for (uint32_t bx = 0; bx + 8 <= a.width; bx += 8)
            for (uint32_t c = 0; c < 3; ++c) {
                double d = 0.0;
                for (uint32_t y = by; y < by + 8; ++y)
                    for (uint32_t x = bx; x < bx + 8; ++x) d += a.at(x, y, c) - b.at(x, y, c);
                sum += (d / 64.0) * (d / 64.0);
                ++n;
            }
    return std::sqrt(sum / double(n));
}

class ScaleTest : public GpuTest {
protected:
    Scene load(const glm::dvec3& offsetM, const std::string& name) {
        auto scene = loadGltf(writeSet(name, offsetM));
        EXPECT_TRUE(scene) << scene.message();
        if (!scene) return {};
        // Direction-only: it does not move with the set.
        scene->environment = uniformEnvironment(glm::vec3(0.3f, 0.35f, 0.4f));
        return std::move(*scene);
    }
    ImageF renderCamera(const Scene& scene, int camera, uint32_t seed) {
        RenderSettings settings = renderSettings(64, 64, 4);
        settings.cameraIndex = camera;
        settings.seed = seed;
        return render(scene, settings, kSpp);
    }
    static constexpr uint32_t kSpp = 16;
};

// Scene and camera moved together by 1 m, 10 km and 1000 km (not on any grid) render as at the
// origin: with the same seed the block error against the origin render must stay below the
// noise, i.e. below 1.5× the block error between two independent renders at the origin (a
// correct render is at worst an independent estimate of the same image: its block error is
// then distributed as the seed-to-seed one, whose RMS over 192 block means spreads by ~5%).
// Before camera-relative rendering, 10 km gave 3× the noise (issue 11), 1000 km garbage.
TEST_F(ScaleTest, FarFromTheOriginRendersAsAtTheOrigin) {
    const Scene origin = load(glm::dvec3(0.0), "origin");
    ASSERT_EQ(origin.cameras.size(), 2u);
    const std::tuple<const char*, const char*, glm::dvec3> offsets[] = {
        {"1 m", "far_1m", {0.61, 0.27, -0.74}},
        {"10 km", "far_10km", {7071.37, 12.71, -7071.13}},
        {"1000 km", "far_1000km", {707106.93, 3.31, -707106.69}}};
    for (int camera : {0, 1}) {  // the wide view, the 1 cm cube's contact shadow
        const ImageF reference = renderCamera(origin, camera, 1);
        const double noise = blockError(reference, renderCamera(origin, camera, 2));
        ASSERT_GT(noise, 0.0);
        for (const auto& [label, file, offset] : offsets) {
            const Scene far = load(offset, file);
            EXPECT_EQ(far.originM, glm::round(offset / 1024.0) * 1024.0) << label;
            const double error = blockError(renderCamera(far, camera, 1), reference);
            std::printf("camera %d at %s: block error %.3g, noise %.3g (ratio %.3f)\n", camera,
                        label, error, noise, error / noise);
            EXPECT_LT(error, 1.5 * noise) << "camera " << camera << " at " << label;
        }
    }
}

// The loader composes node transforms in double: a vertex 1000 km out keeps its tenth of a
// millimetre (a float chain rounds it to 6 cm), and a set near the origin keeps origin 0.
TEST(ScaleLoader, ComposesTransformsInDouble) {
    const glm::dvec3 offset(707106.93, 3.31, -707106.69);
    auto far = loadGltf(writeSet("loader_far", offset));
    auto near = loadGltf(writeSet("loader_near", glm::dvec3(0.5, 0.0, -0.25)));
    ASSERT_TRUE(far && near);
    EXPECT_EQ(near->originM, glm::dvec3(0.0));
    ASSERT_EQ(far->geometry.positions.size(), near->geometry.positions.size());
    for (size_t i = 0; i < far->geometry.positions.size(); ++i) {
        const glm::dvec3 world = far->originM + glm::dvec3(far->geometry.positions[i]);
        const glm::dvec3 expected =
            glm::dvec3(near->geometry.positions[i]) - glm::dvec3(0.5, 0.0, -0.25) + offset;
        ASSERT_LT(glm::length(world - expected), 1e-4) << "vertex " << i;
    }
    ASSERT_EQ(far->lights.size(), 1u);
    EXPECT_LT(glm::length(far->originM + glm::dvec3(far->lights[0].position) -
                          (glm::dvec3(1.0, 2.5, 1.5) + offset)),
              1e-4);
}

// The GPU's origin follows the camera with hysteresis: moves within kRecentreDistanceM keep it
// (no re-upload); a longer move re-centres once, and then renders what a renderer created at
// the new pose renders (same seed; within the noise as above).
TEST_F(ScaleTest, RecentresOnlyWhenTheCameraMovesFar) {
    const Scene scene = load(glm::dvec3(10000.3, 0.0, 0.0), "recentre");
    RenderSettings settings = renderSettings(64, 64, 4);
    auto r = Renderer::create(ctx(), scene, settings);
    ASSERT_TRUE(r) << r.message();
    const glm::dmat4 start = (*r)->worldFromCameraM();
    EXPECT_EQ((*r)->renderOriginM(), glm::round(glm::dvec3(start[3]) / 16.0) * 16.0);
    for (double step : {1.0, 5.0, 3.0}) {  // a few metres about the set: never re-centred
        (*r)->setCameraPose(glm::translate(glm::dmat4(1.0), glm::dvec3(step, 0, 0)) * start);
        ASSERT_TRUE((*r)->renderPreviewFrame(1));
    }
    EXPECT_EQ((*r)->diagnostics().recentreCount(), 0u);
    // 30 m back along the view (the set stays in view), then render as a fresh renderer would.
    const glm::dmat4 moved = start * glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, 30));
    (*r)->setCameraPose(moved);
    ASSERT_TRUE((*r)->reset());
    ASSERT_TRUE((*r)->render(kSpp));
    EXPECT_EQ((*r)->diagnostics().recentreCount(), 1u);
    auto image = (*r)->image();
    ASSERT_TRUE(image);
    Scene at = scene;
    at.cameras[0].worldFromCamera =
        glm::mat4(glm::translate(glm::dmat4(1.0), -scene.originM) * moved);
    const ImageF fresh = render(at, settings, kSpp);
    settings.seed = 7;
    const double noise = blockError(fresh, render(at, settings, kSpp));
    EXPECT_LT(blockError(*image, fresh), 1.5 * noise);
}

}  // namespace
}  // namespace previs::testing
