#include "scene/scene_description.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <exception>
#include <filesystem>
#include <initializer_list>
#include <numbers>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

#include "base/toml_reader.h"
#include "scene/environment_map.h"
#include "scene/gltf_loader.h"

namespace previs {
namespace {

// The only format version so far; a file must say which one it is written for, so a later
// format can change meanings without old files silently rendering differently.
constexpr int64_t kFormatVersion = 1;

// What the description asks for, validated, before any file is loaded.
struct Description {
    std::string gltfPath;
    GltfLoadOptions gltfOptions;
    const toml::node* gltfNode = nullptr;

    std::string environmentPath;  // empty: none
    const toml::node* environmentNode = nullptr;
    double environmentRotationDeg = 0.0;
    double environmentScale = 1.0;

    std::optional<std::string> cameraName;
    const toml::node* cameraNameNode = nullptr;
    std::optional<double> apertureRadiusM;
    std::optional<double> focusDistanceM;
    const toml::node* cameraTable = nullptr;
};

// Reads one description file. Every failure goes through fail(), so each message names the
// file, and the line when the problem has one.
class DescriptionReader {
public:
    explicit DescriptionReader(const std::string& path) : r_(path, "scene description") {}

    Result<Scene> read(const toml::table& root);

private:
    template <typename... Args>
    Error fail(const toml::node* at, fmt::format_string<Args...> format, Args&&... args) const {
        return r_.fail(at, format, std::forward<Args>(args)...);
    }

    Status parse(const toml::table& root, Description& d) const;
    Status parseRoles(const toml::table& roles, Description& d) const;
    Status parseMaterials(const toml::table& materials, Description& d) const;

    TomlReader r_;
};

Status DescriptionReader::parseRoles(const toml::table& roles, Description& d) const {
    if (Status s = r_.checkKeys(roles, "roles", {"real", "virtual"}); !s) return s;
    for (const auto& [key, real] : {std::pair<std::string_view, bool>{"real", true},
                                    std::pair<std::string_view, bool>{"virtual", false}}) {
        const toml::node* node = roles.get(key);
        if (!node) continue;
        const toml::array* patterns = node->as_array();
        if (!patterns)
            return fail(node,
                        "'roles.{}' must be an array of glob patterns (e.g. {} = "
                        "[\"Table*\"]), not {}",
                        key, key, tomlTypeName(*node));
        for (size_t i = 0; i < patterns->size(); ++i) {
            const toml::node& element = *patterns->get(i);
            const toml::value<std::string>* pattern = element.as_string();
            if (!pattern)
                return fail(&element, "'roles.{}[{}]' must be a string (a glob pattern), not {}",
                            key, i, tomlTypeName(element));
            if (pattern->get().empty())
                return fail(&element, "'roles.{}[{}]' is an empty pattern", key, i);
            d.gltfOptions.roleRules.emplace_back(pattern->get(), real);
        }
    }
    d.gltfOptions.roleRulesOrigin = fmt::format("[roles] of '{}'", r_.path());
    return {};
}

// [materials."<glTF material name>"] tables, each with thin_walled = true|false.
Status DescriptionReader::parseMaterials(const toml::table& materials, Description& d) const {
    for (const auto& [key, node] : materials) {
        const std::string name(key.str());
        const std::string section = fmt::format("materials.\"{}\"", name);
        const toml::table* material = node.as_table();
        if (!material)
            return fail(&node,
                        "'{}' must be a table naming a glTF material, e.g. [materials.\"Glass\"] "
                        "with thin_walled = false, not {}",
                        section, tomlTypeName(node));
        if (Status s = r_.checkKeys(*material, section, {"thin_walled"}); !s) return s;
        Result<std::optional<bool>> thin = r_.boolean(*material, section, "thin_walled");
        if (!thin) return thin.error();
        if (!*thin)
            return fail(&node, "[{}] needs thin_walled = true or false (or leave the table out)",
                        section);
        d.gltfOptions.thinWalledByMaterial[name] = **thin;
    }
    d.gltfOptions.materialsOrigin = fmt::format("[materials] of '{}'", r_.path());
    return {};
}

Status DescriptionReader::parse(const toml::table& root, Description& d) const {
    if (Status s = r_.checkKeys(root, "",
                                {"version", "gltf", "environment", "roles", "materials", "camera"});
        !s)
        return s;

    const toml::node* version = root.get("version");
    if (!version)
        return fail(nullptr, "missing key 'version' (start the file with `version = {}`)",
                    kFormatVersion);
    const toml::value<int64_t>* v = version->as_integer();
    if (!v) return fail(version, "'version' must be an integer, not {}", tomlTypeName(*version));
    if (v->get() != kFormatVersion)
        return fail(version,
                    "'version' is {}, but this previs reads version {} only (write the file for "
                    "version {}, or update previs)",
                    v->get(), kFormatVersion, kFormatVersion);

    Result<std::optional<std::string>> gltf = r_.string(root, "", "gltf");
    if (!gltf) return gltf.error();
    if (!*gltf)
        return fail(nullptr,
                    "missing key 'gltf' (the scene's .gltf/.glb file, e.g. "
                    "gltf = \"scene.gltf\")");
    d.gltfNode = root.get("gltf");
    Result<std::string> gltfPath = r_.file(*d.gltfNode, "gltf", **gltf, {".gltf", ".glb"}, "glTF");
    if (!gltfPath) return gltfPath.error();
    d.gltfPath = std::move(*gltfPath);

    Result<const toml::table*> environment = r_.table(root, "", "environment");
    if (!environment) return environment.error();
    if (const toml::table* env = *environment) {
        if (Status s = r_.checkKeys(*env, "environment", {"map", "rotation_deg", "scale"}); !s)
            return s;
        Result<std::optional<std::string>> map = r_.string(*env, "environment", "map");
        if (!map) return map.error();
        if (!*map)
            return fail(env, "[environment] needs 'map' (an equirectangular .exr or .hdr file)");
        if (**map == kStudioEnvironment) {
            d.environmentPath = kStudioEnvironment;  // the bundled one, not a file
        } else {
            Result<std::string> mapPath =
                r_.file(*env->get("map"), "environment.map", **map, {".exr", ".hdr"}, "linear HDR");
            if (!mapPath) return mapPath.error();
            d.environmentPath = std::move(*mapPath);
        }
        d.environmentNode = env->get("map");

        Result<std::optional<double>> rotation = r_.number(*env, "environment", "rotation_deg");
        if (!rotation) return rotation.error();
        d.environmentRotationDeg = rotation->value_or(0.0);

        Result<std::optional<double>> scale = r_.number(*env, "environment", "scale");
        if (!scale) return scale.error();
        if (*scale && **scale < 0.0)
            return fail(env->get("scale"),
                        "'environment.scale' is {}; it must be >= 0 (it multiplies the map's "
                        "radiance)",
                        **scale);
        d.environmentScale = scale->value_or(1.0);
    }

    Result<const toml::table*> roles = r_.table(root, "", "roles");
    if (!roles) return roles.error();
    if (*roles) {
        if (Status s = parseRoles(**roles, d); !s) return s;
    }

    Result<const toml::table*> materials = r_.table(root, "", "materials");
    if (!materials) return materials.error();
    if (*materials) {
        if (Status s = parseMaterials(**materials, d); !s) return s;
    }

    Result<const toml::table*> camera = r_.table(root, "", "camera");
    if (!camera) return camera.error();
    if (const toml::table* cam = *camera) {
        d.cameraTable = cam;
        if (Status s =
                r_.checkKeys(*cam, "camera", {"name", "aperture_radius_m", "focus_distance_m"});
            !s)
            return s;
        Result<std::optional<std::string>> name = r_.string(*cam, "camera", "name");
        if (!name) return name.error();
        d.cameraName = std::move(*name);
        d.cameraNameNode = cam->get("name");
        if (d.cameraName && d.cameraName->empty())
            return fail(d.cameraNameNode,
                        "'camera.name' is empty; name a camera of the glTF "
                        "file or leave the key out");

        Result<std::optional<double>> aperture = r_.number(*cam, "camera", "aperture_radius_m");
        if (!aperture) return aperture.error();
        if (*aperture && **aperture < 0.0)
            return fail(cam->get("aperture_radius_m"),
                        "'camera.aperture_radius_m' is {}; it must be >= 0 (0 = pinhole)",
                        **aperture);
        d.apertureRadiusM = *aperture;

        Result<std::optional<double>> focus = r_.number(*cam, "camera", "focus_distance_m");
        if (!focus) return focus.error();
        if (*focus && !(**focus > 0.0))
            return fail(cam->get("focus_distance_m"),
                        "'camera.focus_distance_m' is {}; it must be > 0 (metres)", **focus);
        d.focusDistanceM = *focus;
    }
    return {};
}

Result<Scene> DescriptionReader::read(const toml::table& root) {
    // Everything in the description is checked before the (slow) glTF and map loads, so a typo
    // is reported at once.
    Description d;
    if (Status s = parse(root, d); !s) return s.error();

    Result<Scene> scene = loadGltf(d.gltfPath, d.gltfOptions);
    if (!scene) return fail(nullptr, "{}", scene.message());

    if (d.cameraName) {
        const std::vector<Camera>& cameras = scene->cameras;
        auto it = std::find_if(cameras.begin(), cameras.end(),
                               [&](const Camera& c) { return c.name == *d.cameraName; });
        if (it == cameras.end()) {
            std::string names;
            for (const Camera& c : cameras) names += (names.empty() ? "'" : ", '") + c.name + "'";
            return fail(d.cameraNameNode, "'camera.name' is '{}', but '{}' has no such camera ({})",
                        *d.cameraName, d.gltfPath,
                        cameras.empty() ? std::string("it has no cameras") : "cameras: " + names);
        }
        scene->cameraName = *d.cameraName;
    }
    if (d.apertureRadiusM || d.focusDistanceM) {
        if (scene->cameras.empty())
            return fail(d.cameraTable,
                        "[camera] sets the lens, but '{}' has no camera to apply it to",
                        d.gltfPath);
        // The overrides belong to the camera the description chooses (the first one when it
        // names none); `--camera` picking another one renders with that camera's own lens.
        Camera* chosen = &scene->cameras.front();
        for (Camera& c : scene->cameras)
            if (d.cameraName && c.name == *d.cameraName) {
                chosen = &c;
                break;
            }
        if (d.apertureRadiusM) chosen->apertureRadiusM = float(*d.apertureRadiusM);
        if (d.focusDistanceM) chosen->focusDistanceM = float(*d.focusDistanceM);
    }

    if (!d.environmentPath.empty()) {
        Result<EnvironmentMap> map = loadEnvironmentMap(d.environmentPath);
        if (!map) return fail(d.environmentNode, "'environment.map': {}", map.message());
        map->rotationRad = float(d.environmentRotationDeg * (std::numbers::pi / 180.0));
        map->scale = float(d.environmentScale);
        scene->environment = std::move(*map);
    }
    return scene;
}

}  // namespace

Result<Scene> loadSceneDescription(const std::string& path) {
    Result<toml::table> root = parseTomlFile(path, "scene description");
    if (!root) return root.error();
    try {
        return DescriptionReader(path).read(*root);
    } catch (const std::exception& e) {  // toml++ and the standard library throw
        return makeError("cannot load scene description '{}': {}", path, e.what());
    }
}

Result<Scene> loadScene(const std::string& path) {
    const std::string ext = lowerExtension(path);
    if (ext == ".gltf" || ext == ".glb") return loadGltf(path);
    if (ext == ".toml") return loadSceneDescription(path);
    return makeError(
        "cannot load scene '{}': unsupported file type '{}' (accepted: .gltf, .glb "
        "or a previs.toml scene description)",
        path, ext.empty() ? std::string("(none)") : ext);
}

}  // namespace previs
