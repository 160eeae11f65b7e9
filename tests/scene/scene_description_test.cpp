// Scene description tests: the shipped example, role patterns on small glTF files written here,
// camera and environment overrides, the dispatcher, and every kind of bad input (each must give
// one message naming the description file and the offending key).
#include "scene/scene_description.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numbers>

#include "image/image.h"
#include "scene/environment_map.h"
#include "scene/gltf_loader.h"
#include "tests/support/base64.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

fs::path descriptionDir() { return previs::testing::scratchDir("previs_config_test"); }

std::string writeFile(const std::string& name, const std::string& text) {
    const fs::path path = descriptionDir() / name;
    std::ofstream(path) << text;
    return path.string();
}

// A glTF whose every mesh node holds one triangle (so triangleIsReal lists the nodes' roles in
// depth-first order), plus two cameras "CamA" and "CamB".
class TinyGltf {
public:
    TinyGltf() {
        const float positions[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
        std::vector<uint8_t> bytes(sizeof positions);
        std::memcpy(bytes.data(), positions, sizeof positions);
        doc_ = {
            {"asset", {{"version", "2.0"}}},
            {"scene", 0},
            {"scenes", json::array({json{{"nodes", json::array()}}})},
            {"nodes", json::array()},
            {"meshes",
             json::array({{{"primitives", json::array({{{"attributes", {{"POSITION", 0}}}}})}}})},
            {"accessors", json::array({{{"bufferView", 0},
                                        {"componentType", 5126},
                                        {"type", "VEC3"},
                                        {"count", 3},
                                        {"min", {0, 0, 0}},
                                        {"max", {1, 1, 0}}}})},
            {"bufferViews",
             json::array({{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", bytes.size()}}})},
            {"buffers", json::array({{{"byteLength", bytes.size()},
                                      {"uri", "data:application/octet-stream;base64," +
                                                  previs::testing::base64(bytes)}}})},
            {"cameras", json::array({{{"name", "CamA"},
                                      {"type", "perspective"},
                                      {"perspective", {{"yfov", 0.8}, {"znear", 0.01}}}},
                                     {{"name", "CamB"},
                                      {"type", "perspective"},
                                      {"perspective", {{"yfov", 0.5}, {"znear", 0.01}}}}})}};
        addNode({{"name", "CamNodeA"}, {"camera", 0}});
        addNode({{"name", "CamNodeB"}, {"camera", 1}});
    }

    // A mesh node named `name` (role extras when `role` is not empty) under `parent` (-1: root).
    int addMesh(const std::string& name, const std::string& role = "", int parent = -1) {
        json node = {{"name", name}, {"mesh", 0}};
        if (!role.empty()) node["extras"] = {{"previs", {{"role", role}}}};
        return addNode(node, parent);
    }

    std::string write(const std::string& name) const { return writeFile(name, doc_.dump()); }

private:
    int addNode(json node, int parent = -1) {
        const int index = int(doc_["nodes"].size());
        doc_["nodes"].push_back(std::move(node));
        if (parent < 0)
            doc_["scenes"][0]["nodes"].push_back(index);
        else
            doc_["nodes"][parent]["children"].push_back(index);
        return index;
    }

    json doc_;
};

// The nodes of the role tests; depth-first: Table, Leg1, Vase, Cube1, Cube12, Bunny, Ear, Other.
std::string writeRoleGltf() {
    TinyGltf g;
    const int table = g.addMesh("Table");
    g.addMesh("Leg1", "", table);
    g.addMesh("Vase", "virtual", table);
    g.addMesh("Cube1", "virtual");
    g.addMesh("Cube12");
    const int bunny = g.addMesh("Bunny", "real");
    g.addMesh("Ear", "", bunny);
    g.addMesh("Other", "real");
    return g.write("roles.gltf");
}

std::string writeEnvMap(const std::string& name) {
    ImageF image;
    image.width = 8;
    image.height = 4;
    image.channels = 3;
    image.pixels.assign(8 * 4 * 3, 0.5f);
    const std::string path = (descriptionDir() / name).string();
    EXPECT_TRUE(writeExr(path, image).ok());
    return path;
}

TEST(SceneDescription, ExampleRoundTrip) {
    const std::string dir = testing::sourcePath("examples/cubes_spheres/");
    Result<Scene> plain = loadGltf(dir + "scene.gltf");
    ASSERT_TRUE(plain.ok()) << plain.message();
    Result<Scene> described = loadScene(dir + "previs.toml");
    ASSERT_TRUE(described.ok()) << described.message();
    Result<Scene> metal = loadGltf(dir + "scene.gltf", {{{"MetalSphere", true}}, ""});
    ASSERT_TRUE(metal.ok()) << metal.message();

    // Same geometry; the roles are the file's extras plus the metal sphere, which the example
    // declares real by name.
    const Geometry& a = plain->geometry;
    const Geometry& b = described->geometry;
    ASSERT_EQ(a.triangles.size(), b.triangles.size());
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.triangleMaterials, b.triangleMaterials);
    EXPECT_EQ(b.triangleIsReal, metal->geometry.triangleIsReal);
    size_t realPlain = 0;
    size_t realDescribed = 0;
    for (size_t t = 0; t < a.triangles.size(); ++t) {
        realPlain += a.triangleIsReal[t];
        realDescribed += b.triangleIsReal[t];
        if (a.triangleIsReal[t]) {
            EXPECT_TRUE(b.triangleIsReal[t]) << "triangle " << t;
        }
    }
    EXPECT_GT(realDescribed, realPlain);

    EXPECT_EQ(described->cameraName, "SceneCamera");
    ASSERT_EQ(described->cameras.size(), 1u);
    EXPECT_EQ(described->cameras[0].apertureRadiusM, 0.0f);
    EXPECT_FLOAT_EQ(described->cameras[0].focusDistanceM, 1.5f);
    EXPECT_FALSE(described->environment.has_value());
}

TEST(SceneDescription, DispatchByExtension) {
    const std::string gltf = writeRoleGltf();
    Result<Scene> direct = loadScene(gltf);
    ASSERT_TRUE(direct.ok()) << direct.message();
    EXPECT_EQ(direct->geometry.triangles.size(), 8u);
    EXPECT_TRUE(direct->cameraName.empty());

    const std::string upper = writeFile("SHOT.TOML", "version = 1\ngltf = \"roles.gltf\"\n");
    Result<Scene> described = loadScene(upper);
    ASSERT_TRUE(described.ok()) << described.message();
    EXPECT_EQ(described->geometry.triangles.size(), 8u);

    const std::string obj = writeFile("scene.obj", "v 0 0 0\n");
    Result<Scene> bad = loadScene(obj);
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.message().find(obj), std::string::npos) << bad.message();
    EXPECT_NE(bad.message().find(".gltf, .glb"), std::string::npos) << bad.message();
    EXPECT_NE(bad.message().find("previs.toml"), std::string::npos) << bad.message();
}

TEST(SceneDescription, RoleGlobsOverrideExtrasAndAreInherited) {
    writeRoleGltf();
    const std::string toml = writeFile("roles.toml", R"(version = 1
gltf = "roles.gltf"
[roles]
real = ["Table*", "Cube?"]
virtual = ["Bunny"]
)");
    Result<Scene> scene = loadSceneDescription(toml);
    ASSERT_TRUE(scene.ok()) << scene.message();
    // Table by name; Leg1 inherits it; Vase's own extras beat the inherited role (as with
    // extras alone); Cube1's name beats its extras; Cube12 matches no 'Cube?'; Bunny's name
    // beats its extras and Ear inherits; Other keeps its extras.
    const std::vector<uint8_t> expected = {1, 1, 0, 1, 0, 0, 0, 1};
    EXPECT_EQ(scene->geometry.triangleIsReal, expected);
}

TEST(SceneDescription, GltfLoaderRoleRulesDirectly) {
    const std::string gltf = writeRoleGltf();
    // One argument: extras only.
    Result<Scene> plain = loadGltf(gltf);
    ASSERT_TRUE(plain.ok()) << plain.message();
    EXPECT_EQ(plain->geometry.triangleIsReal, (std::vector<uint8_t>{0, 0, 0, 0, 0, 1, 1, 1}));
    // Bracket expressions and '*' across the whole name (no FNM_PATHNAME).
    GltfLoadOptions options;
    options.roleRules = {{"[CT]*", true}};
    Result<Scene> scene = loadGltf(gltf, options);
    ASSERT_TRUE(scene.ok()) << scene.message();
    EXPECT_EQ(scene->geometry.triangleIsReal, (std::vector<uint8_t>{1, 1, 0, 1, 1, 1, 1, 1}));
}

TEST(SceneDescription, ConflictingPatternsNameBothAndTheFile) {
    writeRoleGltf();
    const std::string toml = writeFile("conflict.toml", R"(version = 1
gltf = "roles.gltf"
[roles]
real = ["Cube*"]
virtual = ["Cube1?"]
)");
    Result<Scene> scene = loadSceneDescription(toml);
    ASSERT_FALSE(scene.ok());
    const std::string& m = scene.message();
    EXPECT_NE(m.find(toml), std::string::npos) << m;
    EXPECT_NE(m.find("[roles]"), std::string::npos) << m;
    EXPECT_NE(m.find("'Cube12'"), std::string::npos) << m;
    EXPECT_NE(m.find("'Cube*'"), std::string::npos) << m;
    EXPECT_NE(m.find("'Cube1?'"), std::string::npos) << m;
}

TEST(SceneDescription, UnmatchedPatternWarns) {
    writeRoleGltf();
    const std::string toml = writeFile("typo.toml", R"(version = 1
gltf = "roles.gltf"
[roles]
real = ["Tabel*", "Table"]
)");
    ::testing::internal::CaptureStderr();
    Result<Scene> scene = loadSceneDescription(toml);
    const std::string log = ::testing::internal::GetCapturedStderr();
    ASSERT_TRUE(scene.ok()) << scene.message();
    EXPECT_NE(log.find("'Tabel*'"), std::string::npos) << log;
    EXPECT_NE(log.find(toml), std::string::npos) << log;
    EXPECT_EQ(log.find("'Table'"), std::string::npos) << log;
}

// [materials."<name>"] thin_walled overrides glTF's thin-wall rule per material (Blender's default
// glass: transmission without a volume). Names with spaces are quoted TOML keys.
TEST(SceneDescription, MaterialsThinWalledOverride) {
    TinyGltf g;
    g.addMesh("Vase");
    std::ifstream written(g.write("glass.gltf"));
    json doc = json::parse(written);
    const json glass = {{"KHR_materials_transmission", {{"transmissionFactor", 1}}}};
    const json volume = {{"KHR_materials_transmission", {{"transmissionFactor", 1}}},
                         {"KHR_materials_volume", {{"thicknessFactor", 0.1}}}};
    doc["materials"] = json::array({{{"name", "Blender Glass"}, {"extensions", glass}},
                                    {{"name", "Lens"}, {"extensions", volume}},
                                    {{"name", "Pane"}, {"extensions", glass}}});
    doc["meshes"][0]["primitives"][0]["material"] = 0;
    writeFile("glass.gltf", doc.dump());
    const std::string toml = writeFile("glass.toml", R"(version = 1
gltf = "glass.gltf"
[materials."Blender Glass"]
thin_walled = false
[materials.Lens]
thin_walled = true
)");
    Result<Scene> scene = loadSceneDescription(toml);
    ASSERT_TRUE(scene.ok()) << scene.message();
    EXPECT_FALSE(scene->materials[0].thinWalled);  // solid, as the description says
    EXPECT_TRUE(scene->materials[1].thinWalled);   // the override beats the volume too
    EXPECT_TRUE(scene->materials[2].thinWalled);   // no override: glTF's rule
}

TEST(SceneDescription, CameraAndEnvironmentOverrides) {
    writeRoleGltf();
    writeEnvMap("studio.exr");
    const std::string toml = writeFile("overrides.toml", R"(version = 1
gltf = "roles.gltf"
[environment]
map = "studio.exr"
rotation_deg = 90
scale = 2.5
[camera]
name = "CamB"
aperture_radius_m = 0.01
focus_distance_m = 2
)");
    Result<Scene> scene = loadSceneDescription(toml);
    ASSERT_TRUE(scene.ok()) << scene.message();
    EXPECT_EQ(scene->cameraName, "CamB");
    ASSERT_EQ(scene->cameras.size(), 2u);
    // The lens goes to the chosen camera only; CamA keeps the glTF's (default) values.
    EXPECT_EQ(scene->cameras[0].name, "CamA");
    EXPECT_EQ(scene->cameras[0].apertureRadiusM, 0.0f);
    EXPECT_EQ(scene->cameras[0].focusDistanceM, 1.0f);
    EXPECT_FLOAT_EQ(scene->cameras[1].apertureRadiusM, 0.01f);
    EXPECT_FLOAT_EQ(scene->cameras[1].focusDistanceM, 2.0f);
    ASSERT_TRUE(scene->environment.has_value());
    EXPECT_EQ(scene->environment->width, 8u);
    EXPECT_FLOAT_EQ(scene->environment->rotationRad, float(std::numbers::pi / 2));
    EXPECT_FLOAT_EQ(scene->environment->scale, 2.5f);

    // Without a name, the lens goes to the first camera.
    const std::string first = writeFile("lens.toml", R"(version = 1
gltf = "roles.gltf"
[camera]
focus_distance_m = 3.5
)");
    Result<Scene> lens = loadSceneDescription(first);
    ASSERT_TRUE(lens.ok()) << lens.message();
    EXPECT_TRUE(lens->cameraName.empty());
    EXPECT_FLOAT_EQ(lens->cameras[0].focusDistanceM, 3.5f);
    EXPECT_EQ(lens->cameras[1].focusDistanceM, 1.0f);
}

TEST(SceneDescription, StudioEnvironmentIsBuiltIn) {
    writeRoleGltf();
    const std::string toml = writeFile("studio.toml", R"(version = 1
gltf = "roles.gltf"
[environment]
map = "studio"
scale = 0.5
)");
    Result<Scene> scene = loadSceneDescription(toml);
    ASSERT_TRUE(scene.ok()) << scene.message();
    ASSERT_TRUE(scene->environment.has_value());
    EXPECT_EQ(scene->environment->path, "studio");
    EXPECT_EQ(scene->environment->width, studioEnvironment().width);
    EXPECT_FLOAT_EQ(scene->environment->scale, 0.5f);
}

TEST(SceneDescription, AbsolutePathsAndDefaults) {
    const std::string gltf = writeRoleGltf();
    const std::string env = writeEnvMap("abs.exr");
    fs::create_directories(descriptionDir() / "sub");
    const std::string toml = writeFile("sub/abs.toml", fmt::format(R"(version = 1
gltf = "{}"
[environment]
map = "{}"
)",
                                                                   gltf, env));
    Result<Scene> scene = loadSceneDescription(toml);
    ASSERT_TRUE(scene.ok()) << scene.message();
    ASSERT_TRUE(scene->environment.has_value());
    EXPECT_EQ(scene->environment->rotationRad, 0.0f);
    EXPECT_EQ(scene->environment->scale, 1.0f);
}

// One bad description: its text, and what its message must mention besides the file's path.
struct BadCase {
    const char* name;
    const char* toml;
    std::vector<std::string> mentions;
};

void PrintTo(const BadCase& c, std::ostream* os) { *os << c.name; }

class BadDescription : public ::testing::TestWithParam<BadCase> {
protected:
    static void SetUpTestSuite() {
        writeRoleGltf();
        writeEnvMap("env.exr");
        writeFile("notanexr.exr", "this is not an OpenEXR file");
        writeFile("broken.gltf", "{ \"asset\": ");
    }
};

TEST_P(BadDescription, OneMessageNamingFileAndKey) {
    const BadCase& c = GetParam();
    const std::string path = writeFile(std::string("bad_") + c.name + ".toml", c.toml);
    Result<Scene> scene = loadSceneDescription(path);
    ASSERT_FALSE(scene.ok());
    const std::string& m = scene.message();
    EXPECT_NE(m.find("'" + path + "'"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    for (const std::string& mention : c.mentions)
        EXPECT_NE(m.find(mention), std::string::npos) << "missing \"" << mention << "\" in: " << m;
}

const BadCase kBadCases[] = {
    {"unknown_key",
     "version = 1\ngltf = \"roles.gltf\"\ngltff = \"x\"\n",
     {"line 3", "'gltff'", "version, gltf, environment, roles, materials, camera"}},
    {"unknown_environment_key",
     "version = 1\ngltf = \"roles.gltf\"\n[environment]\nmap = \"env.exr\"\nrotation = 3\n",
     {"line 5", "'rotation'", "[environment]", "map, rotation_deg, scale"}},
    {"unknown_camera_key",
     "version = 1\ngltf = \"roles.gltf\"\n[camera]\nfov = 1\n",
     {"'fov'", "name, aperture_radius_m, focus_distance_m"}},
    {"unknown_roles_key",
     "version = 1\ngltf = \"roles.gltf\"\n[roles]\nreel = [\"A\"]\n",
     {"'reel'", "real, virtual"}},
    {"version_string",
     "version = \"1\"\ngltf = \"roles.gltf\"\n",
     {"line 1", "'version'", "integer", "a string"}},
    {"version_unsupported",
     "version = 2\ngltf = \"roles.gltf\"\n",
     {"'version' is 2", "version 1"}},
    {"version_missing", "gltf = \"roles.gltf\"\n", {"'version'", "version = 1"}},
    {"gltf_missing_key", "version = 1\n", {"'gltf'"}},
    {"gltf_wrong_type", "version = 1\ngltf = 3\n", {"'gltf'", "string", "an integer"}},
    {"gltf_missing_file",
     "version = 1\ngltf = \"nowhere.gltf\"\n",
     {"line 2", "'gltf'", "nowhere.gltf", "does not exist"}},
    {"gltf_wrong_extension",
     "version = 1\ngltf = \"scene.obj\"\n",
     {"'gltf'", "scene.obj", ".gltf, .glb"}},
    {"gltf_empty", "version = 1\ngltf = \"\"\n", {"'gltf'", "empty"}},
    {"gltf_malformed", "version = 1\ngltf = \"broken.gltf\"\n", {"broken.gltf", "JSON"}},
    {"environment_not_table",
     "version = 1\ngltf = \"roles.gltf\"\nenvironment = \"env.exr\"\n",
     {"'environment'", "table", "a string"}},
    {"environment_no_map",
     "version = 1\ngltf = \"roles.gltf\"\n[environment]\nscale = 1\n",
     {"[environment]", "'map'"}},
    {"environment_missing_map",
     "version = 1\ngltf = \"roles.gltf\"\n[environment]\nmap = \"gone.exr\"\n",
     {"'environment.map'", "gone.exr", "does not exist"}},
    {"environment_map_png",
     "version = 1\ngltf = \"roles.gltf\"\n[environment]\nmap = \"sky.png\"\n",
     {"'environment.map'", "sky.png", ".exr, .hdr"}},
    {"environment_map_corrupt",
     "version = 1\ngltf = \"roles.gltf\"\n[environment]\nmap = \"notanexr.exr\"\n",
     {"'environment.map'", "notanexr.exr"}},
    {"environment_negative_scale",
     "version = 1\ngltf = \"roles.gltf\"\n[environment]\nmap = \"env.exr\"\nscale = -1\n",
     {"line 5", "'environment.scale'", "-1", ">= 0"}},
    {"environment_scale_string",
     "version = 1\ngltf = \"roles.gltf\"\n[environment]\nmap = \"env.exr\"\nscale = \"big\"\n",
     {"'environment.scale'", "number", "a string"}},
    {"environment_rotation_nan",
     "version = 1\ngltf = \"roles.gltf\"\n[environment]\nmap = \"env.exr\"\nrotation_deg = nan\n",
     {"'environment.rotation_deg'", "finite"}},
    {"roles_not_array",
     "version = 1\ngltf = \"roles.gltf\"\n[roles]\nreal = \"Table\"\n",
     {"line 4", "'roles.real'", "array"}},
    {"roles_element_not_string",
     "version = 1\ngltf = \"roles.gltf\"\n[roles]\nvirtual = [\"A\", 1]\n",
     {"'roles.virtual[1]'", "string", "an integer"}},
    {"roles_empty_pattern",
     "version = 1\ngltf = \"roles.gltf\"\n[roles]\nreal = [\"\"]\n",
     {"'roles.real[0]'", "empty"}},
    {"camera_unknown_name",
     "version = 1\ngltf = \"roles.gltf\"\n[camera]\nname = \"Nope\"\n",
     {"line 4", "'camera.name'", "'Nope'", "'CamA', 'CamB'"}},
    {"camera_negative_aperture",
     "version = 1\ngltf = \"roles.gltf\"\n[camera]\naperture_radius_m = -0.1\n",
     {"'camera.aperture_radius_m'", ">= 0"}},
    {"camera_zero_focus",
     "version = 1\ngltf = \"roles.gltf\"\n[camera]\nfocus_distance_m = 0\n",
     {"'camera.focus_distance_m'", "> 0"}},
    {"camera_not_table",
     "version = 1\ngltf = \"roles.gltf\"\ncamera = \"CamA\"\n",
     {"'camera'", "table"}},
    {"materials_not_table",
     "version = 1\ngltf = \"roles.gltf\"\n[materials]\nGlass = false\n",
     {"line 4", "'materials.\"Glass\"'", "table", "thin_walled = false"}},
    {"materials_thin_walled_string",
     "version = 1\ngltf = \"roles.gltf\"\n[materials.Glass]\nthin_walled = \"no\"\n",
     {"line 4", "thin_walled", "true or false"}},
    {"materials_unknown_key",
     "version = 1\ngltf = \"roles.gltf\"\n[materials.Glass]\nthin = false\n",
     {"'thin'", "thin_walled"}},
    {"materials_empty",
     "version = 1\ngltf = \"roles.gltf\"\n[materials.Glass]\n",
     {"[materials.\"Glass\"]", "needs thin_walled"}},
    {"syntax_error", "version = 1\ngltf = \n", {"line 2", "not valid TOML"}},
    {"duplicate_key",
     "version = 1\nversion = 1\ngltf = \"roles.gltf\"\n",
     {"line 2", "not valid TOML"}},
    {"binary_garbage", "\x01\x02\xff\xfe version", {"not valid TOML"}},
};

INSTANTIATE_TEST_SUITE_P(Cases, BadDescription, ::testing::ValuesIn(kBadCases),
                         [](const ::testing::TestParamInfo<BadCase>& param) {
                             return std::string(param.param.name);
                         });

TEST(SceneDescription, MissingOrFolderDescription) {
    const std::string missing = (descriptionDir() / "absent.toml").string();
    Result<Scene> a = loadSceneDescription(missing);
    ASSERT_FALSE(a.ok());
    EXPECT_NE(a.message().find(missing), std::string::npos) << a.message();
    const std::string folder = (descriptionDir() / "folder.toml").string();
    fs::create_directories(folder);
    Result<Scene> b = loadScene(folder);
    ASSERT_FALSE(b.ok());
    EXPECT_NE(b.message().find(folder), std::string::npos) << b.message();
}

}  // namespace
}  // namespace previs
