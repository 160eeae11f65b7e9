// Loader tests on small glTF files written here: geometry, transforms, roles, materials, lights,
// cameras, .glb, and every kind of bad input (each must give one error naming the file).
#include "scene/gltf_loader.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <glm/gtc/matrix_transform.hpp>
#include <limits>
#include <nlohmann/json.hpp>

#include "image/image.h"
#include "tests/support/base64.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

using nlohmann::json;

std::filesystem::path tempDir() { return previs::testing::scratchDir("previs_scene_test"); }

// Builds a glTF document and its single binary buffer.
class GltfBuilder {
public:
    GltfBuilder() {
        doc_ = {{"asset", {{"version", "2.0"}}},
                {"scene", 0},
                {"scenes", json::array({json{{"nodes", json::array()}}})},
                {"nodes", json::array()},
                {"meshes", json::array()},
                {"accessors", json::array()},
                {"bufferViews", json::array()}};
    }

    json& doc() { return doc_; }
    std::vector<uint8_t>& bin() { return bin_; }

    int addAccessor(const void* data, size_t bytes, int componentType, const char* type,
                    size_t count) {
        while (bin_.size() % 4) bin_.push_back(0);
        const size_t offset = bin_.size();
        bin_.insert(bin_.end(), static_cast<const uint8_t*>(data),
                    static_cast<const uint8_t*>(data) + bytes);
        doc_["bufferViews"].push_back(
            {{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}});
        doc_["accessors"].push_back({{"bufferView", doc_["bufferViews"].size() - 1},
                                     {"componentType", componentType},
                                     {"type", type},
                                     {"count", count}});
        return int(doc_["accessors"].size() - 1);
    }
    int addPositions(const std::vector<glm::vec3>& p) {
        return addAccessor(p.data(), p.size() * 12, 5126, "VEC3", p.size());
    }
    int addVec3(const std::vector<glm::vec3>& p) { return addPositions(p); }
    int addIndices(const std::vector<uint16_t>& i) {
        return addAccessor(i.data(), i.size() * 2, 5123, "SCALAR", i.size());
    }
    int addMesh(json primitives) {
        doc_["meshes"].push_back(
            {{"name", "mesh" + std::to_string(doc_["meshes"].size())}, {"primitives", primitives}});
        return int(doc_["meshes"].size() - 1);
    }
    // A unit right triangle in the XY plane, indexed.
    int addTriangleMesh(int material = -1) {
        int pos = addPositions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
        int idx = addIndices({0, 1, 2});
        json prim = {{"attributes", {{"POSITION", pos}}}, {"indices", idx}};
        if (material >= 0) prim["material"] = material;
        return addMesh(json::array({prim}));
    }
    int addNode(json node, int parent = -1) {
        doc_["nodes"].push_back(node);
        const int index = int(doc_["nodes"].size() - 1);
        if (parent < 0) {
            doc_["scenes"][0]["nodes"].push_back(index);
        } else {
            doc_["nodes"][parent]["children"].push_back(index);
        }
        return index;
    }

    // .gltf with the buffer as a data URI (dataUri) or as a .bin file beside it.
    std::string writeGltf(const std::string& name, bool dataUri = true) {
        const auto path = tempDir() / name;
        json d = doc_;
        std::vector<uint8_t> bin = bin_;
        if (bin.empty()) {
            // No geometry: glTF forbids empty buffers.
        } else if (dataUri) {
            d["buffers"] = json::array({{{"byteLength", bin.size()},
                                         {"uri", "data:application/octet-stream;base64," +
                                                     previs::testing::base64(bin)}}});
        } else {
            const std::string binName = std::filesystem::path(name).stem().string() + ".bin";
            std::ofstream(tempDir() / binName, std::ios::binary)
                .write(reinterpret_cast<const char*>(bin.data()), std::streamsize(bin.size()));
            d["buffers"] = json::array({{{"byteLength", bin.size()}, {"uri", binName}}});
        }
        std::ofstream(path) << d.dump(1);
        return path.string();
    }

    std::string writeGlb(const std::string& name) {
        json d = doc_;
        std::vector<uint8_t> bin = bin_;
        while (bin.size() % 4) bin.push_back(0);
        d["buffers"] = json::array({{{"byteLength", bin_.size()}}});
        std::string text = d.dump();
        while (text.size() % 4) text += ' ';
        std::vector<uint8_t> out;
        auto put32 = [&](uint32_t v) {
            for (int k = 0; k < 4; ++k) out.push_back(uint8_t(v >> (8 * k)));
        };
        put32(0x46546C67);
        put32(2);
        put32(uint32_t(12 + 8 + text.size() + 8 + bin.size()));
        put32(uint32_t(text.size()));
        put32(0x4E4F534A);
        out.insert(out.end(), text.begin(), text.end());
        put32(uint32_t(bin.size()));
        put32(0x004E4942);
        out.insert(out.end(), bin.begin(), bin.end());
        const auto path = tempDir() / name;
        std::ofstream(path, std::ios::binary)
            .write(reinterpret_cast<const char*>(out.data()), std::streamsize(out.size()));
        return path.string();
    }

private:
    json doc_;
    std::vector<uint8_t> bin_;
};

void expectNear(const glm::vec3& a, const glm::vec3& b, float tol = 1e-5f) {
    EXPECT_NEAR(a.x, b.x, tol);
    EXPECT_NEAR(a.y, b.y, tol);
    EXPECT_NEAR(a.z, b.z, tol);
}

// glTF rotation (x, y, z, w) for an angle about +Y.
json quatY(float angleRad) {
    return json::array({0.0, std::sin(angleRad / 2), 0.0, std::cos(angleRad / 2)});
}

void expectErrorNamesFile(const std::string& path, const std::string& fragment) {
    Result<Scene> r = loadGltf(path);
    ASSERT_FALSE(r.ok()) << "expected an error for " << path;
    std::printf("%s\n", r.message().c_str());
    EXPECT_NE(r.message().find(std::filesystem::path(path).filename().string()), std::string::npos)
        << r.message();
    EXPECT_NE(r.message().find(fragment), std::string::npos)
        << "message '" << r.message() << "' lacks '" << fragment << "'";
}

TEST(GltfLoader, TrianglesAndWorldTransforms) {
    GltfBuilder b;
    const int mesh = b.addTriangleMesh();
    // Non-indexed quad: two triangles, six vertices.
    const int quadPos =
        b.addPositions({{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 0, 0}, {1, 1, 0}, {0, 1, 0}});
    const int quad = b.addMesh(json::array({{{"attributes", {{"POSITION", quadPos}}}}}));
    const int parent = b.addNode({{"name", "parent"},
                                  {"mesh", mesh},
                                  {"translation", {1.0, 2.0, 3.0}},
                                  {"scale", {2.0, 2.0, 2.0}}});
    b.addNode({{"name", "child"}, {"mesh", mesh}, {"rotation", quatY(float(M_PI / 2))}}, parent);
    glm::mat4 m = glm::translate(glm::mat4(1.0f), glm::vec3(5, 0, 0));
    std::vector<double> matrix(16);
    for (int i = 0; i < 16; ++i) matrix[i] = (&m[0][0])[i];
    b.addNode({{"name", "quad"}, {"mesh", quad}, {"matrix", matrix}});
    // A node outside the default scene is not loaded.
    b.doc()["nodes"].push_back({{"name", "orphan"}, {"mesh", mesh}});

    Result<Scene> scene = loadGltf(b.writeGltf("transforms.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    const Geometry& g = scene->geometry;
    ASSERT_EQ(g.triangles.size(), 4u);
    ASSERT_EQ(g.triangleMaterials.size(), 4u);
    ASSERT_EQ(g.triangleIsReal.size(), 4u);
    ASSERT_EQ(g.normals.size(), g.positions.size());
    ASSERT_EQ(g.uvs.size(), g.positions.size());
    // Parent: p * 2 + (1, 2, 3).
    const glm::uvec3 t0 = g.triangles[0];
    expectNear(g.positions[t0.x], {1, 2, 3});
    expectNear(g.positions[t0.y], {3, 2, 3});
    expectNear(g.positions[t0.z], {1, 4, 3});
    // No normals in the file: flat normal +Z.
    expectNear(g.normals[t0.x], {0, 0, 1});
    // Child: rotate 90° about +Y ((1,0,0) -> (0,0,-1)), then the parent's transform.
    const glm::uvec3 t1 = g.triangles[1];
    expectNear(g.positions[t1.y], glm::vec3(0, 0, -2) + glm::vec3(1, 2, 3));
    expectNear(g.normals[t1.x], {1, 0, 0});
    // Quad through its matrix.
    expectNear(g.positions[g.triangles[2].x], {5, 0, 0});
    expectNear(g.positions[g.triangles[3].z], {5, 1, 0});
    // A default material was appended for primitives without one.
    ASSERT_EQ(scene->materials.size(), 1u);
    EXPECT_EQ(scene->materials[0].metallic, 1.0f);
    EXPECT_EQ(scene->materials[0].roughness, 1.0f);
    EXPECT_EQ(g.triangleMaterials[0], 0u);
}

TEST(GltfLoader, NormalsTransformedByInverseTransposeAndMirroringKeepsFront) {
    GltfBuilder b;
    const int pos = b.addPositions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    const glm::vec3 n = glm::normalize(glm::vec3(1, 1, 1));
    const int nrm = b.addVec3({n, n, n});
    const int mesh =
        b.addMesh(json::array({{{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}}}}}));
    b.addNode({{"mesh", mesh}, {"scale", {2.0, 1.0, 1.0}}});
    b.addNode({{"mesh", mesh}, {"scale", {1.0, 1.0, -1.0}}});
    Result<Scene> scene = loadGltf(b.writeGltf("normals.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    const Geometry& g = scene->geometry;
    ASSERT_EQ(g.triangles.size(), 2u);
    // Non-uniform scale (2,1,1): normal (1,1,1) -> (1/2, 1, 1), normalised.
    expectNear(g.normals[g.triangles[0].x], glm::normalize(glm::vec3(0.5f, 1, 1)));
    // Mirror in z: the geometric normal of the stored winding still agrees with the shading
    // normal's side.
    const glm::uvec3 t = g.triangles[1];
    const glm::vec3 geo =
        glm::cross(g.positions[t.y] - g.positions[t.x], g.positions[t.z] - g.positions[t.x]);
    EXPECT_GT(glm::dot(geo, g.normals[t.x]), 0.0f);
}

// tinygltf reads an attribute's accessor index as given, -1 included: the loader takes it as
// absent (flat normals, no texture coordinates), as it does a missing attribute.
TEST(GltfLoader, ANegativeAttributeAccessorIsAbsent) {
    GltfBuilder b;
    const int pos = b.addPositions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    const int mesh = b.addMesh(
        json::array({{{"attributes", {{"POSITION", pos}, {"NORMAL", -1}, {"TEXCOORD_0", -1}}}}}));
    b.addNode({{"mesh", mesh}});
    Result<Scene> scene = loadGltf(b.writeGltf("negative_attributes.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    ASSERT_EQ(scene->geometry.triangles.size(), 1u);
    expectNear(scene->geometry.normals[scene->geometry.triangles[0].x], {0, 0, 1});
}

TEST(GltfLoader, RoleInheritance) {
    GltfBuilder b;
    const int mesh = b.addTriangleMesh();
    const json real = {{"previs", {{"role", "real"}}}};
    const json virt = {{"previs", {{"role", "virtual"}}}};
    const int a = b.addNode({{"name", "table"}, {"mesh", mesh}, {"extras", real}});
    const int a1 = b.addNode({{"name", "leg"}, {"mesh", mesh}}, a);
    b.addNode({{"name", "foot"}, {"mesh", mesh}}, a1);
    b.addNode({{"name", "vase"}, {"mesh", mesh}, {"extras", virt}}, a);
    b.addNode({{"name", "cg"}, {"mesh", mesh}});
    const int empty = b.addNode({{"name", "group"}, {"extras", real}});
    b.addNode({{"name", "inGroup"}, {"mesh", mesh}}, empty);
    Result<Scene> scene = loadGltf(b.writeGltf("roles.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    // Depth-first order: table, leg, foot, vase, cg, inGroup.
    const std::vector<uint8_t> expected = {1, 1, 1, 0, 0, 1};
    EXPECT_EQ(scene->geometry.triangleIsReal, expected);
}

TEST(GltfLoader, MaterialsWithExtensionsAndTextures) {
    // A 2x1 PNG texture beside the file: red, then half-transparent green.
    const std::string png = (tempDir() / "tex.png").string();
    ASSERT_TRUE(writePng(png, 2, 1, {255, 0, 0, 0, 255, 0}).ok());
    GltfBuilder b;
    json& d = b.doc();
    d["extensionsUsed"] = {"KHR_materials_transmission", "KHR_materials_ior",
                           "KHR_materials_specular", "KHR_materials_emissive_strength"};
    d["extensionsRequired"] = {"KHR_materials_transmission"};
    d["images"] = json::array({{{"uri", "tex.png"}}});
    d["textures"] = json::array({{{"source", 0}}});
    d["materials"] =
        json::array({{{"name", "glass"},
                      {"pbrMetallicRoughness",
                       {{"baseColorFactor", {0.5, 0.25, 1.0, 0.75}},
                        {"metallicFactor", 0.0},
                        {"roughnessFactor", 0.1},
                        {"baseColorTexture", {{"index", 0}}},
                        {"metallicRoughnessTexture", {{"index", 0}}}}},
                      {"normalTexture", {{"index", 0}}},
                      {"emissiveTexture", {{"index", 0}}},
                      {"emissiveFactor", {1.0, 0.5, 0.0}},
                      {"doubleSided", true},
                      {"extensions",
                       {{"KHR_materials_transmission", {{"transmissionFactor", 0.9}}},
                        {"KHR_materials_ior", {{"ior", 1.33}}},
                        {"KHR_materials_specular",
                         {{"specularFactor", 0.3}, {"specularColorFactor", {0.1, 0.2, 0.3}}}},
                        {"KHR_materials_emissive_strength", {{"emissiveStrength", 4.0}}}}}},
                     {{"name", "plain"}}});
    b.addNode({{"mesh", b.addTriangleMesh(0)}});
    b.addNode({{"mesh", b.addTriangleMesh(1)}});
    Result<Scene> scene = loadGltf(b.writeGltf("materials.gltf", false));
    ASSERT_TRUE(scene.ok()) << scene.message();
    ASSERT_EQ(scene->materials.size(), 2u);
    const Material& m = scene->materials[0];
    EXPECT_EQ(m.name, "glass");
    EXPECT_FLOAT_EQ(m.baseColor.g, 0.25f);
    EXPECT_FLOAT_EQ(m.baseColor.a, 0.75f);
    EXPECT_FLOAT_EQ(m.metallic, 0.0f);
    EXPECT_FLOAT_EQ(m.roughness, 0.1f);
    EXPECT_FLOAT_EQ(m.transmission, 0.9f);
    EXPECT_FLOAT_EQ(m.ior, 1.33f);
    EXPECT_FLOAT_EQ(m.specular, 0.3f);
    expectNear(m.specularColor, {0.1f, 0.2f, 0.3f});
    expectNear(m.emission, {4.0f, 2.0f, 0.0f});
    EXPECT_TRUE(m.doubleSided);
    // One image used as colour (sRGB) and as data (linear): two textures.
    ASSERT_EQ(scene->textures.size(), 2u);
    ASSERT_GE(m.baseColorTexture, 0);
    ASSERT_GE(m.metallicRoughnessTexture, 0);
    EXPECT_EQ(m.baseColorTexture, m.emissiveTexture);
    EXPECT_EQ(m.metallicRoughnessTexture, m.normalTexture);
    EXPECT_TRUE(scene->textures[m.baseColorTexture].srgb);
    EXPECT_FALSE(scene->textures[m.normalTexture].srgb);
    const Texture& t = scene->textures[m.baseColorTexture];
    ASSERT_EQ(t.width, 2u);
    ASSERT_EQ(t.height, 1u);
    EXPECT_EQ(t.rgba8[0], 0xff0000ffu);  // R=255, A=255
    EXPECT_EQ(t.rgba8[1], 0xff00ff00u);  // G=255
    // glTF defaults.
    const Material& p = scene->materials[1];
    EXPECT_EQ(p.baseColor, glm::vec4(1.0f));
    EXPECT_EQ(p.metallic, 1.0f);
    EXPECT_EQ(p.roughness, 1.0f);
    EXPECT_EQ(p.transmission, 0.0f);
    EXPECT_EQ(p.ior, 1.5f);
    EXPECT_EQ(p.specular, 1.0f);
    EXPECT_EQ(p.emission, glm::vec3(0.0f));
    EXPECT_EQ(p.baseColorTexture, -1);
    EXPECT_FALSE(p.doubleSided);
    EXPECT_EQ(scene->geometry.triangleMaterials, (std::vector<uint32_t>{0, 1}));
}

// glTF: transmission without KHR_materials_volume (or with thicknessFactor 0) is thin-walled;
// with a thickness it is a solid, with Beer–Lambert attenuation when given.
TEST(GltfLoader, TransmissionIsThinWalledUnlessItHasAVolume) {
    GltfBuilder b;
    json& d = b.doc();
    d["extensionsUsed"] = {"KHR_materials_transmission", "KHR_materials_volume"};
    d["extensionsRequired"] = {"KHR_materials_volume"};
    const json transmission = {{"transmissionFactor", 1.0}};
    d["materials"] = json::array(
        {{{"name", "pane"}, {"extensions", {{"KHR_materials_transmission", transmission}}}},
         {{"name", "zeroThickness"},
          {"extensions",
           {{"KHR_materials_transmission", transmission},
            {"KHR_materials_volume", {{"thicknessFactor", 0.0}}}}}},
         {{"name", "tintedSolid"},
          {"extensions",
           {{"KHR_materials_transmission", transmission},
            {"KHR_materials_volume",
             {{"thicknessFactor", 0.2},
              {"attenuationColor", {0.5, 0.8, 1.0}},
              {"attenuationDistance", 0.05}}}}}},
         {{"name", "clearSolid"},
          {"extensions",
           {{"KHR_materials_transmission", transmission},
            {"KHR_materials_volume", {{"thicknessFactor", 1.0}}}}}}});
    for (int i = 0; i < 4; ++i) b.addNode({{"mesh", b.addTriangleMesh(i)}});
    Result<Scene> scene = loadGltf(b.writeGltf("volume.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    ASSERT_EQ(scene->materials.size(), 4u);
    EXPECT_TRUE(scene->materials[0].thinWalled);
    EXPECT_TRUE(scene->materials[1].thinWalled);
    const Material& tinted = scene->materials[2];
    EXPECT_FALSE(tinted.thinWalled);
    expectNear(tinted.attenuationColor, {0.5f, 0.8f, 1.0f});
    EXPECT_FLOAT_EQ(tinted.attenuationDistanceM, 0.05f);
    EXPECT_FALSE(scene->materials[3].thinWalled);
    EXPECT_TRUE(std::isinf(scene->materials[3].attenuationDistanceM));

    d["materials"][2]["extensions"]["KHR_materials_volume"]["attenuationDistance"] = 0.0;
    const std::string bad = b.writeGltf("volume_bad.gltf");
    Result<Scene> refused = loadGltf(bad);
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.message().find("attenuationDistance"), std::string::npos)
        << refused.message();
}

// A 2 m cube as Blender's glTF exporter writes one: 24 vertices (each face its own four, for its
// normal and texture coordinates), 36 indices.
int addBlenderCube(GltfBuilder& b, int material) {
    std::vector<glm::vec3> positions, normals;
    std::vector<glm::vec2> uvs;
    std::vector<uint16_t> indices;
    for (int axis = 0; axis < 3; ++axis) {
        for (float side : {-1.0f, 1.0f}) {
            const uint16_t first = uint16_t(positions.size());
            for (glm::vec2 corner : {glm::vec2(-1, -1), {1, -1}, {1, 1}, {-1, 1}}) {
                glm::vec3 p;
                p[axis] = side;
                p[(axis + 1) % 3] = corner.x * side;
                p[(axis + 2) % 3] = corner.y;
                glm::vec3 n(0.0f);
                n[axis] = side;
                positions.push_back(p);
                normals.push_back(n);
                uvs.push_back(0.5f * (corner + 1.0f));
            }
            for (int k : {0, 1, 2, 0, 2, 3}) indices.push_back(uint16_t(first + k));
        }
    }
    const int pos = b.addPositions(positions);
    const int nrm = b.addVec3(normals);
    const int uv = b.addAccessor(uvs.data(), uvs.size() * 8, 5126, "VEC2", uvs.size());
    const int idx = b.addIndices(indices);
    const int mesh = b.addMesh(
        json::array({{{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}, {"TEXCOORD_0", uv}}},
                      {"indices", idx},
                      {"material", material}}}));
    b.doc()["meshes"][mesh]["name"] = "Cube";
    return mesh;
}

// Blender's exporter writes glass (Principled BSDF, Transmission 1) as KHR_materials_transmission
// without KHR_materials_volume unless the material has a thickness: a thin wall by glTF's rule,
// which previs keeps, but on a closed mesh almost always meant as solid glass. One warning per
// such material, naming it, the mesh and the fix; none for thin glass on an open mesh; a
// previs.toml override (thinWalledByMaterial) decides and silences it.
TEST(GltfLoader, BlendersDefaultGlassOnAClosedMeshWarnsOncePerMaterial) {
    GltfBuilder b;
    json& d = b.doc();
    d["asset"]["generator"] = "Khronos glTF Blender I/O v3.4.50";
    d["extensionsUsed"] = {"KHR_materials_transmission"};
    auto glassMaterial = [](const char* name) {
        return json{{"name", name},
                    {"pbrMetallicRoughness", {{"metallicFactor", 0}, {"roughnessFactor", 0}}},
                    {"extensions", {{"KHR_materials_transmission", {{"transmissionFactor", 1}}}}}};
    };
    d["materials"] = json::array({glassMaterial("Glass"), glassMaterial("Window")});
    const int cube = addBlenderCube(b, 0);
    b.addNode({{"name", "Cube"}, {"mesh", cube}});
    b.addNode({{"name", "Cube.001"}, {"mesh", cube}, {"translation", {3, 0, 0}}});
    b.addNode({{"name", "Shard"}, {"mesh", b.addTriangleMesh(0)}});
    b.addNode({{"name", "Pane"}, {"mesh", b.addTriangleMesh(1)}});
    const std::string path = b.writeGltf("blender_glass.gltf");

    auto load = [&](const GltfLoadOptions& options, std::string& log) {
        ::testing::internal::CaptureStderr();
        Result<Scene> scene = loadGltf(path, options);
        log = ::testing::internal::GetCapturedStderr();
        std::printf("%s", log.c_str());
        return scene;
    };
    auto count = [](const std::string& log, const std::string& needle) {
        int n = 0;
        for (size_t at = log.find(needle); at != std::string::npos; at = log.find(needle, at + 1))
            ++n;
        return n;
    };
    std::string log;
    Result<Scene> byDefault = load({}, log);
    ASSERT_TRUE(byDefault.ok()) << byDefault.message();
    EXPECT_TRUE(byDefault->materials[0].thinWalled);  // glTF's rule holds without an override
    EXPECT_TRUE(byDefault->materials[1].thinWalled);
    EXPECT_EQ(count(log, "\n"), 1) << log;  // two cube instances, one material: one line
    for (const char* what :
         {"blender_glass.gltf", "material 'Glass'", "closed mesh 'Cube'", "KHR_materials_volume",
          "Thickness", "`thin_walled = false` under [materials.\"Glass\"]"})
        EXPECT_NE(log.find(what), std::string::npos) << what << " missing in: " << log;
    EXPECT_EQ(count(log, "Window"), 0) << "thin glass on an open mesh is what glTF means: " << log;

    GltfLoadOptions solid;
    solid.thinWalledByMaterial = {{"Glass", false}, {"Window", true}};
    Result<Scene> overridden = load(solid, log);
    ASSERT_TRUE(overridden.ok()) << overridden.message();
    EXPECT_FALSE(overridden->materials[0].thinWalled);
    EXPECT_TRUE(std::isinf(overridden->materials[0].attenuationDistanceM));  // clear
    EXPECT_TRUE(overridden->materials[1].thinWalled);
    EXPECT_EQ(log, "");

    GltfLoadOptions thin;
    thin.thinWalledByMaterial = {{"Glass", true}, {"Glas", false}};
    thin.materialsOrigin = "[materials] of 'shot/previs.toml'";
    Result<Scene> kept = load(thin, log);
    ASSERT_TRUE(kept.ok()) << kept.message();
    EXPECT_TRUE(kept->materials[0].thinWalled);
    EXPECT_EQ(count(log, "\n"), 1) << log;  // only the misspelt name
    for (const char* what : {"'Glas'", "[materials] of 'shot/previs.toml'", "'Glass', 'Window'"})
        EXPECT_NE(log.find(what), std::string::npos) << what << " missing in: " << log;
}

TEST(GltfLoader, LightsAndCameras) {
    GltfBuilder b;
    json& d = b.doc();
    d["extensionsUsed"] = {"KHR_lights_punctual"};
    d["extensions"] = {
        {"KHR_lights_punctual",
         {{"lights",
           json::array({{{"name", "sun"}, {"type", "directional"}, {"intensity", 3.0}},
                        {{"name", "lamp"},
                         {"type", "spot"},
                         {"color", {1.0, 0.5, 0.25}},
                         {"intensity", 100.0},
                         {"range", 10.0},
                         {"spot", {{"innerConeAngle", 0.1}, {"outerConeAngle", 0.5}}}}})}}}};
    d["cameras"] = json::array(
        {{{"name", "main"},
          {"type", "perspective"},
          {"perspective", {{"yfov", 0.6}, {"aspectRatio", 1.5}, {"znear", 0.01}}}},
         {{"name", "ortho"},
          {"type", "orthographic"},
          {"orthographic", {{"xmag", 1.0}, {"ymag", 1.0}, {"znear", 0.01}, {"zfar", 10.0}}}}});
    const int rig = b.addNode({{"name", "rig"}, {"translation", {0.0, 1.0, 0.0}}});
    // Sun rotated 90° about +Y: -Z becomes -X.
    b.addNode({{"name", "sunNode"},
               {"rotation", quatY(float(M_PI / 2))},
               {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}},
              rig);
    b.addNode({{"name", "lampNode"},
               {"translation", {2.0, 0.0, 0.0}},
               {"extensions", {{"KHR_lights_punctual", {{"light", 1}}}}}},
              rig);
    b.addNode({{"name", "camNode"},
               {"camera", 0},
               {"translation", {0.0, 0.0, 5.0}},
               {"rotation", quatY(float(M_PI))},
               {"scale", {2.0, 2.0, 2.0}},
               {"extras", {{"previs", {{"apertureRadiusM", 0.01}, {"focusDistanceM", 2.5}}}}}},
              rig);
    b.addNode({{"name", "orthoNode"}, {"camera", 1}});
    Result<Scene> scene = loadGltf(b.writeGltf("lights.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    ASSERT_EQ(scene->lights.size(), 2u);
    const PunctualLight& sun = scene->lights[0];
    EXPECT_EQ(sun.type, LightType::Directional);
    // Photometric in the file (lux, candela), radiometric in the scene: ÷ 683 lm/W.
    EXPECT_FLOAT_EQ(sun.intensity, 3.0f / 683.0f);
    expectNear(sun.direction, {-1, 0, 0});
    const PunctualLight& lamp = scene->lights[1];
    EXPECT_EQ(lamp.type, LightType::Spot);
    expectNear(lamp.position, {2, 1, 0});
    expectNear(lamp.direction, {0, 0, -1});
    expectNear(lamp.color, {1, 0.5f, 0.25f});
    EXPECT_FLOAT_EQ(lamp.intensity, 100.0f / 683.0f);
    EXPECT_FLOAT_EQ(lamp.range, 10.0f);
    EXPECT_FLOAT_EQ(lamp.innerConeAngleRad, 0.1f);
    EXPECT_FLOAT_EQ(lamp.outerConeAngleRad, 0.5f);
    // The orthographic camera is skipped with a warning.
    ASSERT_EQ(scene->cameras.size(), 1u);
    const Camera& cam = scene->cameras[0];
    EXPECT_EQ(cam.name, "main");
    EXPECT_FLOAT_EQ(cam.fovYRad, 0.6f);
    EXPECT_FLOAT_EQ(cam.aspectRatio, 1.5f);
    EXPECT_FLOAT_EQ(cam.apertureRadiusM, 0.01f);
    EXPECT_FLOAT_EQ(cam.focusDistanceM, 2.5f);
    expectNear(glm::vec3(cam.worldFromCamera[3]), {0, 1, 5});
    // Turned around: looks along +Z in the world; scale removed from the frame.
    expectNear(-glm::vec3(cam.worldFromCamera[2]), {0, 0, 1});
    expectNear(glm::vec3(cam.worldFromCamera[1]), {0, 1, 0});
}

TEST(GltfLoader, LoadsGlb) {
    GltfBuilder b;
    b.addNode({{"mesh", b.addTriangleMesh()}, {"translation", {0.0, 0.0, -1.0}}});
    Result<Scene> scene = loadGltf(b.writeGlb("scene.glb"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    ASSERT_EQ(scene->geometry.triangles.size(), 1u);
    expectNear(scene->geometry.positions[scene->geometry.triangles[0].y], {1, 0, -1});
}

TEST(GltfLoader, DegenerateTrianglesDroppedSliversKept) {
    GltfBuilder b;
    const int pos = b.addPositions({{0, 0, 0},
                                    {1, 0, 0},
                                    {0, 1, 0},
                                    {2, 0, 0},      // collinear with 0 and 1
                                    {1, 1e-5f, 0},  // sliver with 0 and 3
                                    {0, 0, 0}});    // coincident with 0
    const int idx = b.addIndices({0, 1, 2,          // good
                                  0, 0, 2,          // repeated index
                                  0, 1, 3,          // zero area (collinear)
                                  0, 3, 4,          // sliver: kept
                                  0, 5, 1});        // coincident vertices: zero area
    b.addNode({{"mesh", b.addMesh(json::array(
                            {{{"attributes", {{"POSITION", pos}}}, {"indices", idx}}}))}});
    Result<Scene> scene = loadGltf(b.writeGltf("degenerate.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    ASSERT_EQ(scene->geometry.triangles.size(), 2u);
    for (const glm::vec3& n : scene->geometry.normals) {
        EXPECT_TRUE(std::isfinite(n.x) && std::isfinite(n.y) && std::isfinite(n.z));
        EXPECT_NEAR(glm::length(n), 1.0f, 1e-5f);
    }
}

TEST(GltfLoader, NonFiniteNormalsReplacedByGeometric) {
    GltfBuilder b;
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const int pos = b.addPositions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    const int nrm = b.addVec3({{nan, 0, 0}, {0, 0, 0}, {0, 0, 1}});
    b.addNode({{"mesh",
                b.addMesh(json::array({{{"attributes", {{"POSITION", pos}, {"NORMAL", nrm}}}}}))}});
    Result<Scene> scene = loadGltf(b.writeGltf("nan_normals.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    for (const glm::vec3& n : scene->geometry.normals) expectNear(n, {0, 0, 1});
}

TEST(GltfLoader, SkipsNonTrianglePrimitives) {
    GltfBuilder b;
    const int pos = b.addPositions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
    b.addNode({{"mesh", b.addMesh(json::array({{{"attributes", {{"POSITION", pos}}}, {"mode", 1}},
                                               {{"attributes", {{"POSITION", pos}}}}}))}});
    Result<Scene> scene = loadGltf(b.writeGltf("lines.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    EXPECT_EQ(scene->geometry.triangles.size(), 1u);
}

TEST(GltfLoader, UndecodableTextureFallsBackToNoTexture) {
    GltfBuilder b;
    json& d = b.doc();
    d["images"] = json::array(
        {{{"uri", "data:image/png;base64," + previs::testing::base64({1, 2, 3, 4, 5, 6, 7, 8})}},
         {{"uri", "missing_texture.png"}}});
    d["textures"] = json::array({{{"source", 0}}, {{"source", 1}}});
    d["materials"] = json::array({{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}},
                                   {"emissiveTexture", {{"index", 1}}}}});
    b.addNode({{"mesh", b.addTriangleMesh(0)}});
    Result<Scene> scene = loadGltf(b.writeGltf("badtexture.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    EXPECT_EQ(scene->materials[0].baseColorTexture, -1);
    EXPECT_EQ(scene->materials[0].emissiveTexture, -1);
    EXPECT_TRUE(scene->textures.empty());
}

// A URI naming a FIFO blocked tinygltf's reader forever (and one naming a device opened it):
// only regular files are read.
TEST(GltfLoader, BufferUriNamingAFifoIsRefused) {
    const auto fifo = tempDir() / "pipe.bin";
    std::filesystem::remove(fifo);
    ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
    GltfBuilder b;
    b.addNode({{"mesh", b.addTriangleMesh()}});
    b.doc()["buffers"] = json::array({{{"byteLength", 64}, {"uri", "pipe.bin"}}});
    const std::string path = (tempDir() / "fifo_buffer.gltf").string();
    std::ofstream(path) << b.doc().dump(1);
    auto loading = std::async(std::launch::async, [&] { return loadGltf(path); });
    if (loading.wait_for(std::chrono::seconds(10)) != std::future_status::ready) {
        // Release the blocked reader before failing, so the test ends.
        const int fd = ::open(fifo.c_str(), O_WRONLY);
        if (fd >= 0) ::close(fd);
        FAIL() << "loadGltf blocked on a FIFO";
    }
    Result<Scene> r = loading.get();
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.message().find("fifo_buffer.gltf"), std::string::npos) << r.message();
    EXPECT_NE(r.message().find("pipe.bin"), std::string::npos) << r.message();
}

// A glTF in `folder` whose one triangle's buffer is `bufferUri` (holding the right bytes
// wherever it points: inside.bin and ../outside.bin, `bufferBytes` long when more than the
// triangle) and whose one texture is `imageUri` (none when empty).
std::string writeSceneInFolder(const std::filesystem::path& folder, const std::string& bufferUri,
                               const std::string& imageUri = {}, size_t bufferBytes = 0) {
    std::filesystem::create_directories(folder);
    GltfBuilder b;
    b.doc()["materials"] = json::array({json::object()});
    b.addNode({{"mesh", b.addTriangleMesh(0)}});
    if (b.bin().size() < bufferBytes) b.bin().resize(bufferBytes);
    b.doc()["buffers"] = json::array({{{"byteLength", b.bin().size()}, {"uri", bufferUri}}});
    if (!imageUri.empty()) {
        b.doc()["images"] = json::array({{{"uri", imageUri}}});
        b.doc()["textures"] = json::array({{{"source", 0}}});
        b.doc()["materials"][0]["emissiveTexture"] = {{"index", 0}};
    }
    for (const char* name : {"inside.bin", "../outside.bin"})
        std::ofstream(folder / name, std::ios::binary)
            .write(reinterpret_cast<const char*>(b.bin().data()), std::streamsize(b.bin().size()));
    const std::filesystem::path path = folder / "scene.gltf";
    std::ofstream(path) << b.doc().dump(1);
    return path.string();
}

// A scene is a file someone sends: it may make previs read the files inside its own folder and
// nothing else — not `../`, not an absolute path, not a link out, not another scheme, and not
// the working folder tinygltf also searches — each refused with one line naming the glTF file
// and the URI, whether a buffer or an image names it.
TEST(GltfLoader, UrisLeavingTheScenesFolderAreRefused) {
    const auto root = tempDir() / "containment";
    std::filesystem::remove_all(root);
    const auto folder = root / "scene";
    writeSceneInFolder(folder, "inside.bin");
    std::filesystem::create_directories(folder / "sub");
    std::filesystem::create_symlink("../outside.bin", folder / "link_out.bin");
    std::filesystem::create_symlink("inside.bin", folder / "link_in.bin");
    ASSERT_TRUE(writePng((root / "outside.png").string(), 1, 1, {255, 0, 0}).ok());
    ASSERT_TRUE(writePng((folder / "inside.png").string(), 1, 1, {255, 0, 0}).ok());
    const std::string outside = (root / "outside.bin").string();
    const std::pair<std::string, std::string> refused[] = {
        {"../outside.bin", "outside the glTF's folder"},
        {"%2E%2E/outside.bin", "outside the glTF's folder"},  // tinygltf decodes the URI first
        {"sub/../../outside.bin", "outside the glTF's folder"},
        {"link_out.bin", "outside the glTF's folder"},
        {outside, "is an absolute path"},
        {"file://" + outside, "is a file: URI"},
        {"http://example.com/outside.bin", "is a http: URI"},
    };
    for (const auto& [uri, why] : refused) {
        Result<Scene> r = loadGltf(writeSceneInFolder(folder, uri));
        ASSERT_FALSE(r.ok()) << uri << " loaded";
        std::printf("%s\n", r.message().c_str());
        EXPECT_NE(r.message().find("scene.gltf"), std::string::npos) << r.message();
        EXPECT_NE(r.message().find(why), std::string::npos) << r.message();
        EXPECT_NE(r.message().find("copy the file there"), std::string::npos) << r.message();
        EXPECT_EQ(r.message().find('\n'), std::string::npos) << r.message();
    }
    // An image is refused the same way, not dropped with a warning.
    Result<Scene> image = loadGltf(writeSceneInFolder(folder, "inside.bin", "../outside.png"));
    ASSERT_FALSE(image.ok());
    EXPECT_NE(image.message().find("'../outside.png'"), std::string::npos) << image.message();

    // What stays inside loads: `..` that comes back, a link to a file beside it.
    for (const std::string uri : {"inside.bin", "sub/../inside.bin", "link_in.bin"}) {
        Result<Scene> r = loadGltf(writeSceneInFolder(folder, uri, "sub/../inside.png"));
        ASSERT_TRUE(r.ok()) << uri << ": " << r.message();
        EXPECT_EQ(r->geometry.triangles.size(), 1u);
        EXPECT_EQ(r->textures.size(), 1u);
    }

    // tinygltf looks for a URI in the working folder when the glTF's has no such file.
    std::filesystem::remove(folder / "inside.bin");
    const std::filesystem::path workingFolder = std::filesystem::current_path();
    std::filesystem::current_path(root);
    std::filesystem::copy_file(root / "outside.bin", root / "inside.bin");
    Result<Scene> fromWorkingFolder = loadGltf((folder / "scene.gltf").string());
    std::filesystem::current_path(workingFolder);
    EXPECT_FALSE(fromWorkingFolder.ok()) << "read the working folder's inside.bin";
}

// Every byte a scene makes previs read and every pixel it decodes come out of one budget: a
// buffer or an image over it is refused with one line, an image by the size its header
// declares, before a pixel is decoded.
TEST(GltfLoader, ScenesOverTheirMemoryBudgetAreRefused) {
    const auto folder = tempDir() / "budget";
    std::filesystem::remove_all(folder);
    std::filesystem::create_directories(folder);
    ASSERT_TRUE(
        writePng((folder / "big.png").string(), 512, 512, std::vector<uint8_t>(512 * 512 * 3, 7))
            .ok());
    GltfLoadOptions tight;
    tight.maxDataBytes = 512 * 512 * 4 - 1;  // less than the texture's decoded pixels alone
    Result<Scene> image = loadGltf(writeSceneInFolder(folder, "inside.bin", "big.png"), tight);
    ASSERT_FALSE(image.ok());
    std::printf("%s\n", image.message().c_str());
    EXPECT_NE(image.message().find("scene.gltf"), std::string::npos) << image.message();
    EXPECT_NE(image.message().find("512x512"), std::string::npos) << image.message();
    GltfLoadOptions roomy;
    roomy.maxDataBytes = 512 * 512 * 4 + 64 * 1024;
    EXPECT_TRUE(loadGltf((folder / "scene.gltf").string(), roomy).ok());

    // A PNG of a few bytes declaring 16384 x 16384 (1 GiB decoded): refused by its header.
    std::vector<uint8_t> header;
    {
        std::ifstream in(folder / "big.png", std::ios::binary);
        header.assign(std::istreambuf_iterator<char>(in), {});
        header.resize(33);  // signature and IHDR only
        for (int at : {16, 20}) {
            header[at] = 0;
            header[at + 1] = 0;
            header[at + 2] = 0x40;
            header[at + 3] = 0;
        }
        std::ofstream(folder / "huge.png", std::ios::binary)
            .write(reinterpret_cast<const char*>(header.data()), std::streamsize(header.size()));
    }
    GltfLoadOptions quarter;
    quarter.maxDataBytes = uint64_t(256) << 20;
    Result<Scene> huge = loadGltf(writeSceneInFolder(folder, "inside.bin", "huge.png"), quarter);
    ASSERT_FALSE(huge.ok());
    EXPECT_NE(huge.message().find("16384x16384"), std::string::npos) << huge.message();
    // The same as a JPEG: start of image, an APP0 segment, then the frame header (SOF0: 8-bit
    // precision, height 0x4000, width 0x3000, 3 components) and nothing more.
    {
        const std::vector<uint8_t> jpeg = {0xff, 0xd8, 0xff, 0xe0, 0x00, 0x04, 'J',  'F',  0xff,
                                           0xc0, 0x00, 0x11, 0x08, 0x40, 0x00, 0x30, 0x00, 0x03,
                                           1,    0x11, 0,    2,    0x11, 1,    3,    0x11, 1};
        std::ofstream(folder / "huge.jpg", std::ios::binary)
            .write(reinterpret_cast<const char*>(jpeg.data()), std::streamsize(jpeg.size()));
    }
    Result<Scene> hugeJpeg =
        loadGltf(writeSceneInFolder(folder, "inside.bin", "huge.jpg"), quarter);
    ASSERT_FALSE(hugeJpeg.ok());
    EXPECT_NE(hugeJpeg.message().find("12288x16384"), std::string::npos) << hugeJpeg.message();

    GltfLoadOptions small;
    small.maxDataBytes = 16 * 1024;
    Result<Scene> buffer = loadGltf(writeSceneInFolder(folder, "inside.bin", {}, 64 * 1024), small);
    ASSERT_FALSE(buffer.ok());
    std::printf("%s\n", buffer.message().c_str());
    EXPECT_NE(buffer.message().find("more than the 16 KiB"), std::string::npos) << buffer.message();
    EXPECT_NE(buffer.message().find("'inside.bin'"), std::string::npos) << buffer.message();
}

// Blender 3.4's own exporter, default lighting mode (tests/data/light_units/make_light_units.py):
// a 100 W point light is written as 100 / 4π × 683 cd, a 3 W/m² sun as 3 × 683 lx. Read back, a
// point light of P watts must have Blender's radiant intensity P / 4π W/sr, a spot the same
// (Blender spots are specified "as if they were points"), a sun its irradiance in W/m².
TEST(GltfLoader, LightUnitsOfBlenderExportsAreRadiometric) {
    const std::string dir = testing::sourcePath("tests/data/light_units/");
    const double wattsPerSr = 100.0 / (4.0 * M_PI);
    for (const char* name : {"point", "spot", "sun"}) {
        Result<Scene> scene = loadGltf(dir + name + ".gltf");
        ASSERT_TRUE(scene.ok()) << scene.message();
        ASSERT_EQ(scene->lights.size(), 1u) << name;
        const PunctualLight& l = scene->lights[0];
        const double expected = std::string(name) == "sun" ? 3.0 : wattsPerSr;
        EXPECT_NEAR(l.intensity, expected, 1e-6 * expected) << name;
        expectNear(l.direction, {0, -1, 0});
        if (std::string(name) == "spot") {
            EXPECT_EQ(l.type, LightType::Spot);
            EXPECT_NEAR(l.outerConeAngleRad, 22.5 * M_PI / 180.0, 1e-6);
            EXPECT_NEAR(l.innerConeAngleRad, 0.85 * 22.5 * M_PI / 180.0, 1e-6);
        }
    }
}

// Out-of-range material values are clamped to the glTF specification's ranges, with one warning
// per material naming it; non-finite values (JSON numbers beyond float) become the defaults.
TEST(GltfLoader, MaterialValuesOutOfRangeAreClampedWithOneWarning) {
    GltfBuilder b;
    json& d = b.doc();
    d["extensionsUsed"] = {"KHR_materials_ior", "KHR_materials_transmission",
                           "KHR_materials_emissive_strength", "KHR_materials_specular"};
    d["materials"] =
        json::array({{{"name", "wild"},
                      {"pbrMetallicRoughness",
                       {{"baseColorFactor", {-0.5, 0.5, 2.0, 1.0}},
                        {"metallicFactor", 1.5},
                        {"roughnessFactor", -0.25}}},
                      {"emissiveFactor", {2.0, 0.5, -1.0}},
                      {"extensions",
                       {{"KHR_materials_ior", {{"ior", 0.5}}},
                        {"KHR_materials_transmission", {{"transmissionFactor", 2.0}}},
                        {"KHR_materials_emissive_strength", {{"emissiveStrength", 4.0}}},
                        {"KHR_materials_specular",
                         {{"specularFactor", 3.0}, {"specularColorFactor", {2.0, -1.0, 0.5}}}}}}},
                     {{"name", "fresnelOne"},
                      {"emissiveFactor", {1.0, 1.0, 1.0}},
                      {"extensions",
                       {{"KHR_materials_ior", {{"ior", 0.0}}},
                        {"KHR_materials_emissive_strength", {{"emissiveStrength", -2.0}}}}}},
                     {{"name", "fine"}, {"extensions", {{"KHR_materials_ior", {{"ior", 1.0}}}}}}});
    b.addNode({{"mesh", b.addTriangleMesh(0)}});
    const std::string path = b.writeGltf("clamped.gltf");
    // 1e39 overflows a float: the JSON is valid, the value non-finite once read.
    {
        std::ifstream in(path);
        std::string text((std::istreambuf_iterator<char>(in)), {});
        const std::string from = "\"roughnessFactor\": -0.25";
        ASSERT_NE(text.find(from), std::string::npos);
        text.replace(text.find(from), from.size(), "\"roughnessFactor\": 1e39");
        std::ofstream(path) << text;
    }
    ::testing::internal::CaptureStderr();
    Result<Scene> scene = loadGltf(path);
    const std::string log = ::testing::internal::GetCapturedStderr();
    std::printf("%s", log.c_str());
    ASSERT_TRUE(scene.ok()) << scene.message();
    const Material& w = scene->materials[0];
    EXPECT_EQ(w.baseColor, glm::vec4(0.0f, 0.5f, 1.0f, 1.0f));
    EXPECT_EQ(w.metallic, 1.0f);
    EXPECT_EQ(w.roughness, 1.0f);  // non-finite: the default
    EXPECT_EQ(w.ior, 1.0f);
    EXPECT_EQ(w.transmission, 1.0f);
    EXPECT_EQ(w.specular, 1.0f);
    EXPECT_EQ(w.specularColor, glm::vec3(2.0f, 0.0f, 0.5f));  // no upper limit in the schema
    EXPECT_EQ(w.emission, glm::vec3(4.0f, 2.0f, 0.0f));       // factor clamped, then × strength
    const Material& f = scene->materials[1];
    EXPECT_EQ(f.ior, 1.5f);
    EXPECT_EQ(f.emission, glm::vec3(0.0f));
    EXPECT_EQ(scene->materials[2].ior, 1.0f);

    // One line per changed material, naming it and each value; none for the valid one.
    auto lines = [&](const std::string& needle) {
        int n = 0;
        for (size_t at = log.find(needle); at != std::string::npos; at = log.find(needle, at + 1))
            ++n;
        return n;
    };
    EXPECT_EQ(lines("\n"), 2) << log;
    EXPECT_EQ(lines("material 'wild'"), 1) << log;
    EXPECT_EQ(lines("material 'fresnelOne'"), 1) << log;
    EXPECT_EQ(lines("'fine'"), 0) << log;
    for (const char* what : {"metallicFactor 1.5 → 1", "roughnessFactor inf → 1", "ior 0.5 → 1",
                             "transmissionFactor 2 → 1", "baseColorFactor[0] -0.5 → 0",
                             "emissiveStrength -2 → 0", "clamped.gltf"})
        EXPECT_NE(log.find(what), std::string::npos) << what << " missing in: " << log;
}

// The sampler's wrap modes and filter reach the texture; textures that share an image but not a
// sampler stay apart; a sampler glTF does not define is an error naming it.
TEST(GltfLoader, SamplerWrapAndFilterAreRead) {
    ASSERT_TRUE(writePng((tempDir() / "sampler.png").string(), 2, 1, {200, 0, 0, 0, 200, 0}).ok());
    GltfBuilder b;
    json& d = b.doc();
    d["images"] = json::array({{{"uri", "sampler.png"}}});
    d["samplers"] = json::array({{{"wrapS", 33648}, {"wrapT", 33071}, {"magFilter", 9728}},
                                 {{"minFilter", 9986}},
                                 {{"wrapS", 12345}}});
    d["textures"] = json::array(
        {{{"source", 0}, {"sampler", 0}}, {{"source", 0}, {"sampler", 1}}, {{"source", 0}}});
    d["materials"] = json::array(
        {{{"pbrMetallicRoughness",
           {{"baseColorTexture", {{"index", 0}}}, {"metallicRoughnessTexture", {{"index", 1}}}}},
          {"emissiveTexture", {{"index", 2}}}}});
    b.addNode({{"mesh", b.addTriangleMesh(0)}});
    Result<Scene> scene = loadGltf(b.writeGltf("samplers.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    const Material& m = scene->materials[0];
    const Texture& mirrored = scene->textures[m.baseColorTexture];
    EXPECT_EQ(mirrored.wrapS, TextureWrap::MirroredRepeat);
    EXPECT_EQ(mirrored.wrapT, TextureWrap::ClampToEdge);
    EXPECT_TRUE(mirrored.nearest);
    const Texture& minNearest = scene->textures[m.metallicRoughnessTexture];
    EXPECT_EQ(minNearest.wrapS, TextureWrap::Repeat);
    EXPECT_TRUE(minNearest.nearest);  // no magFilter, NEAREST_MIPMAP_LINEAR minFilter
    const Texture& noSampler = scene->textures[m.emissiveTexture];
    EXPECT_EQ(noSampler.wrapS, TextureWrap::Repeat);
    EXPECT_EQ(noSampler.wrapT, TextureWrap::Repeat);
    EXPECT_FALSE(noSampler.nearest);

    d["materials"][0]["emissiveTexture"]["index"] = 2;
    d["textures"][2]["sampler"] = 2;
    expectErrorNamesFile(b.writeGltf("bad_sampler.gltf"), "sampler 2 has wrapS 12345");
}

// Texture coordinates far from 0 lose their fraction in float; a primitive whose material only
// repeats is shifted by an even integer (a period of both REPEAT and MIRRORED_REPEAT), one that
// clamps is left alone.
TEST(GltfLoader, FarTextureCoordinatesAreShiftedByWholePeriods) {
    for (int wrap : {10497, 33648, 33071}) {
        GltfBuilder b;
        json& d = b.doc();
        ASSERT_TRUE(writePng((tempDir() / "far.png").string(), 2, 1, {255, 0, 0, 0, 255, 0}).ok());
        d["images"] = json::array({{{"uri", "far.png"}}});
        d["samplers"] = json::array({{{"wrapS", wrap}, {"wrapT", wrap}}});
        d["textures"] = json::array({{{"source", 0}, {"sampler", 0}}});
        d["materials"] =
            json::array({{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}});
        const int pos = b.addPositions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
        const std::vector<glm::vec2> uv = {{1e7f, -3.0f}, {1e7f + 1.0f, -3.0f}, {1e7f, -2.0f}};
        const int uvs = b.addAccessor(uv.data(), uv.size() * 8, 5126, "VEC2", uv.size());
        b.addNode({{"mesh", b.addMesh(json::array(
                                {{{"attributes", {{"POSITION", pos}, {"TEXCOORD_0", uvs}}},
                                  {"material", 0}}}))}});
        Result<Scene> scene = loadGltf(b.writeGltf("far_uv.gltf"));
        ASSERT_TRUE(scene.ok()) << scene.message();
        const auto& got = scene->geometry.uvs;
        ASSERT_EQ(got.size(), 3u);
        if (wrap == 33071) {
            EXPECT_EQ(got[0], uv[0]);
            EXPECT_EQ(got[2], uv[2]);
        } else {
            // 1e7 and -4 are even: the lowest coordinates land on 0 (u) and 1 (v: -3 − (−4)).
            EXPECT_EQ(got[0], glm::vec2(0.0f, 1.0f));
            EXPECT_EQ(got[1], glm::vec2(1.0f, 1.0f));
            EXPECT_EQ(got[2], glm::vec2(0.0f, 2.0f));
        }
    }
}

// tinygltf's tests/issue-416.gltf (MIT), the whole file: an image URI that decodes to a NUL byte
// made tinygltf read the file's own folder and die in std::bad_alloc. The version is refused by
// name; with a valid version the image is a missing file, the texture falls back with a warning.
TEST(GltfLoader, TinygltfIssue416IsRefusedByName) {
    const auto p = tempDir() / "issue-416.gltf";
    std::ofstream(p) << R"({"images":[{"uri":"%!QAAAQAAA5"}],"asset":{"version":""}})";
    expectErrorNamesFile(p.string(), "asset.version is ''");

    GltfBuilder b;
    b.doc()["images"] = json::array({{{"uri", "%!QAAAQAAA5"}}, {{"uri", "."}}});
    b.doc()["textures"] = json::array({{{"source", 0}}, {{"source", 1}}});
    b.doc()["materials"] = json::array(
        {{{"pbrMetallicRoughness",
           {{"baseColorTexture", {{"index", 0}}}, {"metallicRoughnessTexture", {{"index", 1}}}}}}});
    b.addNode({{"mesh", b.addTriangleMesh(0)}});
    Result<Scene> scene = loadGltf(b.writeGltf("nul_uri.gltf"));
    ASSERT_TRUE(scene.ok()) << scene.message();
    EXPECT_EQ(scene->materials[0].baseColorTexture, -1);
    EXPECT_EQ(scene->materials[0].metallicRoughnessTexture, -1);
}

// Extensions previs ignores are listed in one warning line, including those the file uses
// without listing them in extensionsUsed (tinygltf's Cube-textransform.gltf); a required one is
// an error naming it (BadInputGivesOneErrorNamingTheFile, Draco).
TEST(GltfLoader, IgnoredExtensionsAreListedInOneWarning) {
    GltfBuilder b;
    json& d = b.doc();
    d["extensionsUsed"] = {"KHR_materials_volume", "KHR_draco_mesh_compression",
                           "KHR_materials_clearcoat"};
    d["materials"] =
        json::array({{{"pbrMetallicRoughness",
                       {{"baseColorTexture",
                         {{"index", 0},
                          {"extensions", {{"KHR_texture_transform", {{"offset", {0.5, 0.0}}}}}}}}}},
                      {"extensions", {{"KHR_materials_clearcoat", {{"clearcoatFactor", 1.0}}}}}}});
    d["textures"] = json::array({{{"source", 0}}});
    d["images"] = json::array({{{"uri", "absent.png"}}});
    b.addNode({{"mesh", b.addTriangleMesh(0)}});
    ::testing::internal::CaptureStderr();
    Result<Scene> scene = loadGltf(b.writeGltf("extensions.gltf"));
    const std::string log = ::testing::internal::GetCapturedStderr();
    std::printf("%s", log.c_str());
    ASSERT_TRUE(scene.ok()) << scene.message();
    std::string line;
    for (size_t start = 0, end; start < log.size(); start = end + 1) {
        end = log.find('\n', start);
        if (end == std::string::npos) end = log.size();
        if (log.substr(start, end - start).find("ignoring the extensions") != std::string::npos) {
            EXPECT_TRUE(line.empty()) << "more than one line: " << log;
            line = log.substr(start, end - start);
        }
    }
    ASSERT_FALSE(line.empty()) << log;
    EXPECT_NE(line.find("extensions.gltf"), std::string::npos) << line;
    for (const char* ext :
         {"KHR_draco_mesh_compression", "KHR_materials_clearcoat", "KHR_texture_transform"})
        EXPECT_NE(line.find(ext), std::string::npos) << ext << ": " << line;
    EXPECT_EQ(line.find("KHR_materials_volume"), std::string::npos) << "supported: " << line;
}

// A scene with nothing emitting is what the no-light warning of `previs render` looks for.
TEST(GltfLoader, HasLightSource) {
    GltfBuilder b;
    b.addNode({{"mesh", b.addTriangleMesh()}});
    Result<Scene> dark = loadGltf(b.writeGltf("dark.gltf"));
    ASSERT_TRUE(dark.ok()) << dark.message();
    EXPECT_FALSE(hasLightSource(*dark));
    Scene lit = *dark;
    lit.lights.push_back(PunctualLight{});
    EXPECT_TRUE(hasLightSource(lit));
    lit.lights[0].intensity = 0.0f;
    EXPECT_FALSE(hasLightSource(lit));
    Scene glowing = *dark;
    glowing.materials[glowing.geometry.triangleMaterials[0]].emission = glm::vec3(0.0f, 1.0f, 0.0f);
    EXPECT_TRUE(hasLightSource(glowing));
}

TEST(GltfLoader, BadInputGivesOneErrorNamingTheFile) {
    const auto dir = tempDir();
    expectErrorNamesFile((dir / "does_not_exist.gltf").string(), "no such file");

    {
        const auto p = dir / "malformed.gltf";
        std::ofstream(p) << "{ \"asset\": { \"version\": \"2.0\" }, \"nodes\": [ {,] ";
        Result<Scene> r = loadGltf(p.string());
        ASSERT_FALSE(r.ok());
        std::printf("%s\n", r.message().c_str());
        EXPECT_NE(r.message().find("malformed.gltf"), std::string::npos) << r.message();
    }
    {
        const auto p = dir / "not_json.glb";
        std::ofstream(p) << "garbage that is not a binary glTF";
        Result<Scene> r = loadGltf(p.string());
        ASSERT_FALSE(r.ok());
        std::printf("%s\n", r.message().c_str());
        EXPECT_NE(r.message().find("not_json.glb"), std::string::npos) << r.message();
    }
    {
        // The .bin beside the file is missing.
        GltfBuilder b;
        b.addNode({{"mesh", b.addTriangleMesh()}});
        const std::string p = b.writeGltf("missing_bin.gltf", false);
        std::filesystem::remove(dir / "missing_bin.bin");
        Result<Scene> r = loadGltf(p);
        ASSERT_FALSE(r.ok());
        std::printf("%s\n", r.message().c_str());
        EXPECT_NE(r.message().find("missing_bin.gltf"), std::string::npos) << r.message();
    }
    {
        // The buffer is shorter than the buffer view says (byteLength matches the short data).
        GltfBuilder b;
        b.addNode({{"mesh", b.addTriangleMesh()}});
        b.bin().resize(20);
        const std::string p = b.writeGltf("short_buffer.gltf");
        Result<Scene> r = loadGltf(p);
        ASSERT_FALSE(r.ok());
        std::printf("%s\n", r.message().c_str());
        EXPECT_NE(r.message().find("short_buffer.gltf"), std::string::npos) << r.message();
    }
    {
        GltfBuilder b;
        b.addNode({{"mesh", b.addTriangleMesh()}});
        b.doc()["accessors"][0]["count"] = 1000;
        expectErrorNamesFile(b.writeGltf("accessor_range.gltf"), "out of range");
    }
    {
        GltfBuilder b;
        b.addNode({{"mesh", b.addTriangleMesh()}});
        b.doc()["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = 42;
        expectErrorNamesFile(b.writeGltf("accessor_index.gltf"), "accessor 42");
    }
    {
        GltfBuilder b;
        const int pos = b.addPositions({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
        const int idx = b.addIndices({0, 1, 7});
        b.addNode({{"mesh", b.addMesh(json::array(
                                {{{"attributes", {{"POSITION", pos}}}, {"indices", idx}}}))}});
        expectErrorNamesFile(b.writeGltf("index_range.gltf"), "index 7 out of range");
    }
    {
        GltfBuilder b;
        const float inf = std::numeric_limits<float>::infinity();
        const int pos = b.addPositions({{0, 0, 0}, {inf, 0, 0}, {0, 1, 0}});
        b.addMesh(json::array({{{"attributes", {{"POSITION", pos}}}}}));
        b.doc()["meshes"][0]["name"] = "brokenMesh";
        b.addNode({{"mesh", 0}});
        expectErrorNamesFile(b.writeGltf("nan_position.gltf"), "brokenMesh");
    }
    {
        GltfBuilder b;
        b.addNode({{"mesh", b.addTriangleMesh()}});
        b.doc()["extensionsUsed"] = {"KHR_draco_mesh_compression"};
        b.doc()["extensionsRequired"] = {"KHR_draco_mesh_compression"};
        expectErrorNamesFile(b.writeGltf("draco.gltf"), "KHR_draco_mesh_compression");
    }
    {
        GltfBuilder b;
        b.addNode({{"mesh", b.addTriangleMesh(3)}});
        expectErrorNamesFile(b.writeGltf("material_range.gltf"), "material 3");
    }
    {
        // A node that is its own child: no infinite recursion.
        GltfBuilder b;
        const int n = b.addNode({{"mesh", b.addTriangleMesh()}});
        b.doc()["nodes"][n]["children"] = {n};
        Result<Scene> r = loadGltf(b.writeGltf("cycle.gltf"));
        ASSERT_FALSE(r.ok());
        EXPECT_NE(r.message().find("cycle.gltf"), std::string::npos) << r.message();
    }
    expectErrorNamesFile((dir / "scene.obj").string(), "no such file");
    {
        const auto p = dir / "scene.obj";
        std::ofstream(p) << "v 0 0 0";
        expectErrorNamesFile(p.string(), "unsupported extension");
    }
}

}  // namespace
}  // namespace previs
