// glTF files rendered end to end (loader + renderer): light units against Blender's exporter and
// Cycles, and texture addressing at far and negative texture coordinates. Tolerances come from
// the measured noise; seeds are fixed.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "image/image.h"
#include "scene/gltf_loader.h"
#include "tests/integrator/gpu_fixture.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs::testing {
namespace {

using nlohmann::json;

constexpr double kPi = 3.14159265358979323846;

class GltfRenderTest : public GpuTest {};

// The camera ray through image position (px, py) in pixels, as trace_paths.comp builds it.
glm::vec3 cameraDirection(const Camera& c, uint32_t w, uint32_t h, float px, float py) {
    float tanY = std::tan(0.5f * c.fovYRad);
    glm::vec3 d((px / float(w) * 2.0f - 1.0f) * tanY * float(w) / float(h),
                (1.0f - py / float(h) * 2.0f) * tanY, -1.0f);
    return glm::normalize(glm::mat3(c.worldFromCamera) * d);
}

// Light units (tests/data/light_units, made by make_light_units.py with Blender 3.4): a plane of
// albedo ρ = 0.8 at y = 0, a light 1 m above its centre pointing down, the camera 3 m above
// looking down. Blender's definitions, which Cycles' numbers in cycles.json confirm:
//   point, P = 100 W:  radiant intensity I = P / 4π W/sr, so L = ρ/π · I · h / d³
//   spot, P = 100 W:   Cycles 3.4 multiplies I by cos of the angle to the spot's axis (h / d) as
//                      well as by its blend; glTF's spot (previs) is I inside the inner cone.
//   sun, S = 3 W/m²:   irradiance S on a surface facing it, L = ρ/π · S
// The exporter writes I × 683 cd and S × 683 lx; previs divides by 683, so it must render
// ρ/π · I · h / d³ (point, and spot inside its inner cone) and ρ/π · S — and, against Cycles, a
// ratio of 1 for point and sun, and for the spot the window average of d / h (Cycles' extra cos).
// The issue reported previs at 683× Cycles.
TEST_F(GltfRenderTest, BlenderLightUnitsMatchCycles) {
    const std::string dir = testing::sourcePath("tests/data/light_units/");
    json cycles;
    std::ifstream(dir + "cycles.json") >> cycles;
    const double rho = cycles["albedo"].get<double>();
    const uint32_t size = cycles["width"].get<uint32_t>();
    ASSERT_EQ(size, cycles["height"].get<uint32_t>());
    const double h = 1.0;
    const double wattsPerSr = 100.0 / (4.0 * kPi);
    const double sunIrradiance = 3.0;
    // Student t, 15 degrees of freedom (16 seeds on both sides), two-sided 1 % Šidák-corrected
    // over the 3 × (size² + 1) comparisons below: 6.6 (as test_integrator's kPixelT for 1024
    // pixels; 3 × 1025 comparisons need a little more).
    const double kT = 6.9;
    for (const char* name : {"point", "spot", "sun"}) {
        SCOPED_TRACE(name);
        const bool sun = std::string(name) == "sun";
        const bool spot = std::string(name) == "spot";
        Result<Scene> loaded = loadGltf(dir + name + ".gltf");
        ASSERT_TRUE(loaded.ok()) << loaded.message();
        Scene s = std::move(*loaded);
        // The Cycles reference used a Diffuse BSDF: previs's glTF material is Lambertian with
        // specularFactor 0 (Blender 3.4 does not export KHR_materials_specular for it).
        ASSERT_EQ(s.materials.size(), 1u);
        s.materials[0].specular = 0.0f;
        ASSERT_EQ(s.cameras.size(), 1u);
        RenderSettings rs = renderSettings(size, size, 1);
        Estimate e = estimate(s, rs, 4, 16);
        const Camera& cam = s.cameras[0];
        const glm::vec3 eye(cam.worldFromCamera[3]);
        const PunctualLight& light = s.lights[0];
        const double cosInner = std::cos(light.innerConeAngleRad);

        // Per pixel against the closed form (glTF's definition of the light).
        double windowPrevis = 0.0, windowVariance = 0.0, windowExpected = 0.0;
        double windowCyclesModel = 0.0;
        for (uint32_t y = 0; y < size; ++y) {
            for (uint32_t x = 0; x < size; ++x) {
                bool inInnerCone = true;
                double cyclesModel = 0.0;
                double expected = 0.0;
                const int n = 8;
                for (int j = 0; j < n; ++j) {
                    for (int i = 0; i < n; ++i) {
                        glm::vec3 d = cameraDirection(cam, size, size, x + (i + 0.5f) / n,
                                                      y + (j + 0.5f) / n);
                        glm::dvec3 p = glm::dvec3(eye) + glm::dvec3(d) * (-double(eye.y) / d.y);
                        const double dist = glm::length(glm::dvec3(light.position) - p);
                        const double cosAxis = h / dist;
                        if (spot && cosAxis < cosInner) inInnerCone = false;
                        const double value =
                            sun ? rho / kPi * sunIrradiance
                                : rho / kPi * wattsPerSr * h / (dist * dist * dist);
                        expected += value / (n * n);
                        cyclesModel += value * (spot ? cosAxis : 1.0) / (n * n);
                    }
                }
                const double got = e.mean.at(x, y, 0);
                const double sigma = std::sqrt(e.varianceOfMean[(y * size + x) * 3]);
                if (inInnerCone) {
                    // Noise, plus 1e-4 relative for float arithmetic and the quadrature.
                    EXPECT_NEAR(got, expected, kT * sigma + 1e-4 * expected)
                        << "pixel " << x << "," << y;
                }
                if (x >= size / 2 - 4 && x < size / 2 + 4 && y >= size / 2 - 4 &&
                    y < size / 2 + 4) {
                    windowPrevis += got / 64.0;
                    windowVariance += sigma * sigma / (64.0 * 64.0);
                    windowExpected += expected / 64.0;
                    windowCyclesModel += cyclesModel / 64.0;
                }
            }
        }

        // Against Cycles: the central 8×8 window's mean (cycles.json), its standard error over
        // the seeds; Cycles' own number differs from the closed form by about 4e-5 relative
        // (many of its σ: float arithmetic), hence the same 1e-4 relative allowance.
        const double cyclesMean = cycles[name]["mean"].get<double>();
        const double cyclesError = cycles[name]["standardError"].get<double>();
        EXPECT_NEAR(cyclesMean, windowCyclesModel, kT * cyclesError + 1e-4 * cyclesMean)
            << "Cycles no longer follows the Blender definitions stated above";
        // Cycles' spot cosine divided out (1 for point and sun).
        const double ratio = windowPrevis / cyclesMean * (windowCyclesModel / windowExpected);
        const double ratioSigma = std::sqrt(windowVariance / (windowPrevis * windowPrevis) +
                                            cyclesError * cyclesError / (cyclesMean * cyclesMean));
        std::printf(
            "%s: previs %.6f, Cycles %.6f ± %.6f, previs / Cycles %.5f (%.5f after "
            "Cycles' spot cosine), σ of the ratio %.2g\n",
            name, windowPrevis, cyclesMean, cyclesError, windowPrevis / cyclesMean, ratio,
            ratioSigma);
        RecordProperty(std::string(name) + "PrevisOverCycles", std::to_string(ratio));
        EXPECT_NEAR(ratio, 1.0, kT * ratioSigma + 2e-4);
    }
}

// A plane textured with a 4×4 texture whose every texel differs, seen head-on under a uniform
// environment. The same render at texture coordinates shifted by whole periods of the sampler —
// −3, 1e7 and 1e7 + 1 for REPEAT, −4 and 1e7 for MIRRORED_REPEAT, any far value within one
// clamped side for CLAMP_TO_EDGE — and at −3.25 against 0.75 must give the same image: the
// coordinates go through the loader (whole-period shift) and the shader's addressing
// (shared/texture_sampling.h) exactly as a file's would.
TEST_F(GltfRenderTest, FarAndNegativeTextureCoordinatesWrapAsTheSamplerSays) {
    const auto dir = scratchDir("previs_gltf_render_test");
    std::vector<uint8_t> texels;
    for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x)
            for (int c = 0; c < 3; ++c) texels.push_back(uint8_t(30 + 13 * (x + 4 * y) + 7 * c));
    ASSERT_TRUE(writePng((dir / "texels.png").string(), 4, 4, texels).ok());

    // A 2×2 m quad at z = 0 facing +Z, u and v spanning [offset, offset + 2] (two periods).
    auto sceneWith = [&](int wrap, double uOffset, double vOffset) -> Scene {
        const float positions[] = {-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0};
        const float normals[] = {0, 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1};
        const float uvs[] = {float(uOffset),     float(vOffset + 2), float(uOffset + 2),
                             float(vOffset + 2), float(uOffset + 2), float(vOffset),
                             float(uOffset),     float(vOffset)};
        const uint16_t indices[] = {0, 1, 2, 0, 2, 3};
        std::string bin(reinterpret_cast<const char*>(positions), sizeof positions);
        bin.append(reinterpret_cast<const char*>(normals), sizeof normals);
        bin.append(reinterpret_cast<const char*>(uvs), sizeof uvs);
        bin.append(reinterpret_cast<const char*>(indices), sizeof indices);
        std::ofstream(dir / "quad.bin", std::ios::binary) << bin;
        json d = {
            {"asset", {{"version", "2.0"}}},
            {"scene", 0},
            {"scenes", {{{"nodes", {0}}}}},
            {"nodes", {{{"mesh", 0}}}},
            {"meshes",
             {{{"primitives",
                {{{"attributes", {{"POSITION", 0}, {"NORMAL", 1}, {"TEXCOORD_0", 2}}},
                  {"indices", 3},
                  {"material", 0}}}}}}},
            {"materials",
             {{{"pbrMetallicRoughness",
                {{"baseColorTexture", {{"index", 0}}}, {"metallicFactor", 0.0}}},
               {"extensions", {{"KHR_materials_specular", {{"specularFactor", 0.0}}}}}}}},
            {"extensionsUsed", {"KHR_materials_specular"}},
            {"textures", {{{"source", 0}, {"sampler", 0}}}},
            {"samplers", {{{"wrapS", wrap}, {"wrapT", wrap}, {"magFilter", 9729}}}},
            {"images", {{{"uri", "texels.png"}}}},
            {"buffers", {{{"uri", "quad.bin"}, {"byteLength", bin.size()}}}},
            {"bufferViews",
             {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}},
              {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 48}},
              {{"buffer", 0}, {"byteOffset", 96}, {"byteLength", 32}},
              {{"buffer", 0}, {"byteOffset", 128}, {"byteLength", 12}}}},
            {"accessors",
             {{{"bufferView", 0},
               {"componentType", 5126},
               {"count", 4},
               {"type", "VEC3"},
               {"min", {-1, -1, 0}},
               {"max", {1, 1, 0}}},
              {{"bufferView", 1}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}},
              {{"bufferView", 2}, {"componentType", 5126}, {"count", 4}, {"type", "VEC2"}},
              {{"bufferView", 3}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}}}};
        std::ofstream(dir / "quad.gltf") << d.dump();
        Result<Scene> s = loadGltf((dir / "quad.gltf").string());
        EXPECT_TRUE(s.ok()) << s.message();
        if (!s) return {};
        EnvironmentMap env;
        env.path = "uniform";
        env.width = 16;
        env.height = 8;
        env.radiance.assign(16 * 8, glm::vec3(1.0f));
        s->environment = env;
        Camera cam;
        cam.worldFromCamera = glm::mat4(1.0f);
        cam.worldFromCamera[3] = glm::vec4(0.0f, 0.0f, 2.5f, 1.0f);
        cam.fovYRad = 0.7f;  // sees ±0.91 m of the quad
        s->cameras = {cam};
        return std::move(*s);
    };
    RenderSettings rs = renderSettings(24, 24, 1);
    rs.seed = 7;
    auto renderAt = [&](int wrap, double u, double v) {
        return render(sceneWith(wrap, u, v), rs, 4);
    };
    // Same seeds, same geometry: only the texture lookups can differ, and a wrap done right
    // changes the coordinates by float rounding only (texel values differ by ≥ 7/255 ≈ 0.03).
    auto expectSame = [&](const ImageF& a, const ImageF& b, const std::string& what) {
        ASSERT_EQ(a.pixels.size(), b.pixels.size());
        double worst = 0.0;
        for (size_t i = 0; i < a.pixels.size(); ++i)
            worst = std::max(worst, double(std::abs(a.pixels[i] - b.pixels[i])));
        std::printf("%s: worst difference %.3g\n", what.c_str(), worst);
        EXPECT_LT(worst, 1e-4) << what;
    };
    auto expectDifferent = [&](const ImageF& a, const ImageF& b, const std::string& what) {
        double worst = 0.0;
        for (size_t i = 0; i < a.pixels.size(); ++i)
            worst = std::max(worst, double(std::abs(a.pixels[i] - b.pixels[i])));
        EXPECT_GT(worst, 0.01) << what << ": the test cannot tell wraps apart";
    };

    const int repeat = 10497, mirrored = 33648, clampToEdge = 33071;
    const ImageF base = renderAt(repeat, 0.0, 0.0);
    expectSame(base, renderAt(repeat, -3.0, -3.0), "REPEAT at -3");
    expectSame(base, renderAt(repeat, 1e7, -1e7), "REPEAT at (1e7, -1e7)");
    expectSame(base, renderAt(repeat, 1e7 + 1.0, 1e7 + 1.0), "REPEAT at 1e7 + 1");
    const ImageF quarter = renderAt(repeat, 0.75, 0.75);
    expectDifferent(base, quarter, "REPEAT 0 vs 0.75");
    expectSame(quarter, renderAt(repeat, -3.25, -3.25), "REPEAT at -3.25 vs 0.75");

    const ImageF mirroredBase = renderAt(mirrored, 0.0, 0.0);
    expectSame(mirroredBase, renderAt(mirrored, -4.0, 1e7), "MIRRORED_REPEAT at (-4, 1e7)");
    const ImageF mirroredOdd = renderAt(mirrored, 1.0, 1.0);
    expectDifferent(mirroredBase, mirroredOdd, "MIRRORED_REPEAT 0 vs 1");
    expectSame(mirroredOdd, renderAt(mirrored, -3.0, 1e7 + 1.0), "MIRRORED_REPEAT at (-3, 1e7+1)");
    expectSame(renderAt(mirrored, 0.75, 0.75), renderAt(mirrored, -3.25, -3.25),
               "MIRRORED_REPEAT at -3.25 vs 0.75");

    // Entirely below 0 (or above 1): every lookup is the corner texel, wherever the coordinates.
    const ImageF low = renderAt(clampToEdge, -5.0, -5.0);
    expectSame(low, renderAt(clampToEdge, -1e7, -3.25), "CLAMP_TO_EDGE below 0");
    const ImageF high = renderAt(clampToEdge, 5.0, 5.0);
    expectSame(high, renderAt(clampToEdge, 1e7, 1e7 + 1.0), "CLAMP_TO_EDGE above 1");
    expectDifferent(low, high, "CLAMP_TO_EDGE low vs high corner");
}

}  // namespace
}  // namespace previs::testing
