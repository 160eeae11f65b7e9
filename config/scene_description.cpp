#include "config/scene_description.h"

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

#include <toml++/toml.h>

#include "scene/environment_map.h"
#include "scene/gltf_loader.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

// The only format version so far; a file must say which one it is written for, so a later
// format can change meanings without old files silently rendering differently.
constexpr int64_t kFormatVersion = 1;

std::string lowerExtension(const std::string& path) {
    std::string ext = fs::path(path).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return ext;
}

std::string joined(std::initializer_list<std::string_view> items) {
    std::string out;
    for (std::string_view item : items) {
        if (!out.empty()) out += ", ";
        out += item;
    }
    return out;
}

// For "'x' must be a number, not a string".
const char* typeName(const toml::node& node) {
    switch (node.type()) {
        case toml::node_type::table: return "a table";
        case toml::node_type::array: return "an array";
        case toml::node_type::string: return "a string";
        case toml::node_type::integer: return "an integer";
        case toml::node_type::floating_point: return "a floating-point number";
        case toml::node_type::boolean: return "a boolean";
        case toml::node_type::date: return "a date";
        case toml::node_type::time: return "a time";
        case toml::node_type::date_time: return "a date-time";
        case toml::node_type::none: break;
    }
    return "nothing";
}

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
    explicit DescriptionReader(std::string path)
        : path_(std::move(path)), folder_(fs::path(path_).parent_path()) {}

    Result<Scene> read(const toml::table& root);

private:
    template <typename... Args>
    Error fail(const toml::node* at, fmt::format_string<Args...> format, Args&&... args) const {
        const std::string what = fmt::format(format, std::forward<Args>(args)...);
        if (at && at->source().begin.line > 0)
            return makeError("cannot load scene description '{}': line {}: {}", path_,
                             at->source().begin.line, what);
        return makeError("cannot load scene description '{}': {}", path_, what);
    }

    Status parse(const toml::table& root, Description& d) const;
    Status checkKeys(const toml::table& table, std::string_view section,
                     std::initializer_list<std::string_view> valid) const;
    Result<const toml::table*> table(const toml::table& parent, std::string_view key) const;
    Result<std::optional<std::string>> string(const toml::table& table, std::string_view section,
                                              std::string_view key) const;
    Result<std::optional<double>> number(const toml::table& table, std::string_view section,
                                         std::string_view key) const;
    Result<std::string> file(const toml::node& node, const std::string& key,
                             const std::string& value, std::initializer_list<std::string_view>
                                 extensions, const char* what) const;
    Status parseRoles(const toml::table& roles, Description& d) const;

    static std::string dotted(std::string_view section, std::string_view key) {
        return section.empty() ? std::string(key) : fmt::format("{}.{}", section, key);
    }

    std::string path_;
    fs::path folder_;  // relative paths inside the description are relative to this
};

// An unknown key is most often a typo; silently ignoring it would render something else than
// the user asked for, so it is an error listing what is valid.
Status DescriptionReader::checkKeys(const toml::table& table, std::string_view section,
                                    std::initializer_list<std::string_view> valid) const {
    for (auto&& [key, node] : table) {
        if (std::find(valid.begin(), valid.end(), key.str()) != valid.end()) continue;
        if (section.empty())
            return fail(&node, "unknown key '{}' (valid top-level keys: {})", key.str(),
                        joined(valid));
        return fail(&node, "unknown key '{}' in [{}] (valid keys there: {})", key.str(), section,
                    joined(valid));
    }
    return {};
}

Result<const toml::table*> DescriptionReader::table(const toml::table& parent,
                                                    std::string_view key) const {
    const toml::node* node = parent.get(key);
    if (!node) return static_cast<const toml::table*>(nullptr);
    const toml::table* t = node->as_table();
    if (!t)
        return fail(node, "'{}' must be a table, written as a [{}] section, not {}", key, key,
                    typeName(*node));
    return t;
}

Result<std::optional<std::string>> DescriptionReader::string(const toml::table& table,
                                                             std::string_view section,
                                                             std::string_view key) const {
    const toml::node* node = table.get(key);
    if (!node) return std::optional<std::string>();
    const toml::value<std::string>* s = node->as_string();
    if (!s)
        return fail(node, "'{}' must be a string, not {}", dotted(section, key), typeName(*node));
    return std::optional<std::string>(s->get());
}

// TOML tells integers from floats; `scale = 1` is as valid as `scale = 1.0`.
Result<std::optional<double>> DescriptionReader::number(const toml::table& table,
                                                        std::string_view section,
                                                        std::string_view key) const {
    const toml::node* node = table.get(key);
    if (!node) return std::optional<double>();
    double v = 0.0;
    if (const toml::value<int64_t>* i = node->as_integer())
        v = double(i->get());
    else if (const toml::value<double>* f = node->as_floating_point())
        v = f->get();
    else
        return fail(node, "'{}' must be a number, not {}", dotted(section, key), typeName(*node));
    if (!std::isfinite(v))
        return fail(node, "'{}' is {}; it must be a finite number", dotted(section, key), v);
    return std::optional<double>(v);
}

Result<std::string> DescriptionReader::file(const toml::node& node, const std::string& key,
                                            const std::string& value,
                                            std::initializer_list<std::string_view> extensions,
                                            const char* what) const {
    if (value.empty()) return fail(&node, "'{}' is empty; give the {} file's path", key, what);
    const std::string ext = lowerExtension(value);
    if (std::find(extensions.begin(), extensions.end(), ext) == extensions.end())
        return fail(&node, "'{}' is '{}', not a {} file (accepted: {})", key, value, what,
                    joined(extensions));
    // fs::path's operator/ keeps an absolute right-hand side as it is.
    const fs::path resolved = folder_ / fs::path(value);
    std::error_code ec;
    if (!fs::is_regular_file(resolved, ec))
        return fail(&node, "'{}' is '{}', but '{}' {}{}", key, value, resolved.string(),
                    fs::exists(resolved, ec) ? "is not a file" : "does not exist",
                    fs::path(value).is_relative()
                        ? " (relative paths start at the description's folder)"
                        : "");
    return resolved.string();
}

Status DescriptionReader::parseRoles(const toml::table& roles, Description& d) const {
    if (Status s = checkKeys(roles, "roles", {"real", "virtual"}); !s) return s;
    for (const auto& [key, real] : {std::pair<std::string_view, bool>{"real", true},
                                    std::pair<std::string_view, bool>{"virtual", false}}) {
        const toml::node* node = roles.get(key);
        if (!node) continue;
        const toml::array* patterns = node->as_array();
        if (!patterns)
            return fail(node, "'roles.{}' must be an array of glob patterns (e.g. {} = "
                              "[\"Table*\"]), not {}",
                        key, key, typeName(*node));
        for (size_t i = 0; i < patterns->size(); ++i) {
            const toml::node& element = *patterns->get(i);
            const toml::value<std::string>* pattern = element.as_string();
            if (!pattern)
                return fail(&element, "'roles.{}[{}]' must be a string (a glob pattern), not {}",
                            key, i, typeName(element));
            if (pattern->get().empty())
                return fail(&element, "'roles.{}[{}]' is an empty pattern", key, i);
            d.gltfOptions.roleRules.emplace_back(pattern->get(), real);
        }
    }
    d.gltfOptions.roleRulesOrigin = fmt::format("[roles] of '{}'", path_);
    return {};
}

Status DescriptionReader::parse(const toml::table& root, Description& d) const {
    if (Status s = checkKeys(root, "", {"version", "gltf", "environment", "roles", "camera"}); !s)
        return s;

    const toml::node* version = root.get("version");
    if (!version)
        return fail(nullptr, "missing key 'version' (start the file with `version = {}`)",
                    kFormatVersion);
    const toml::value<int64_t>* v = version->as_integer();
    if (!v)
        return fail(version, "'version' must be an integer, not {}", typeName(*version));
    if (v->get() != kFormatVersion)
        return fail(version,
                    "'version' is {}, but this previs reads version {} only (write the file for "
                    "version {}, or update previs)",
                    v->get(), kFormatVersion, kFormatVersion);

    Result<std::optional<std::string>> gltf = string(root, "", "gltf");
    if (!gltf) return gltf.error();
    if (!*gltf)
        return fail(nullptr, "missing key 'gltf' (the scene's .gltf/.glb file, e.g. "
                             "gltf = \"scene.gltf\")");
    d.gltfNode = root.get("gltf");
    Result<std::string> gltfPath = file(*d.gltfNode, "gltf", **gltf, {".gltf", ".glb"}, "glTF");
    if (!gltfPath) return gltfPath.error();
    d.gltfPath = std::move(*gltfPath);

    Result<const toml::table*> environment = table(root, "environment");
    if (!environment) return environment.error();
    if (const toml::table* env = *environment) {
        if (Status s = checkKeys(*env, "environment", {"map", "rotation_deg", "scale"}); !s)
            return s;
        Result<std::optional<std::string>> map = string(*env, "environment", "map");
        if (!map) return map.error();
        if (!*map)
            return fail(env, "[environment] needs 'map' (an equirectangular .exr or .hdr file)");
        Result<std::string> mapPath =
            file(*env->get("map"), "environment.map", **map, {".exr", ".hdr"}, "linear HDR");
        if (!mapPath) return mapPath.error();
        d.environmentPath = std::move(*mapPath);
        d.environmentNode = env->get("map");

        Result<std::optional<double>> rotation = number(*env, "environment", "rotation_deg");
        if (!rotation) return rotation.error();
        d.environmentRotationDeg = rotation->value_or(0.0);

        Result<std::optional<double>> scale = number(*env, "environment", "scale");
        if (!scale) return scale.error();
        if (*scale && **scale < 0.0)
            return fail(env->get("scale"),
                        "'environment.scale' is {}; it must be >= 0 (it multiplies the map's "
                        "radiance)",
                        **scale);
        d.environmentScale = scale->value_or(1.0);
    }

    Result<const toml::table*> roles = table(root, "roles");
    if (!roles) return roles.error();
    if (*roles) {
        if (Status s = parseRoles(**roles, d); !s) return s;
    }

    Result<const toml::table*> camera = table(root, "camera");
    if (!camera) return camera.error();
    if (const toml::table* cam = *camera) {
        d.cameraTable = cam;
        if (Status s = checkKeys(*cam, "camera", {"name", "aperture_radius_m", "focus_distance_m"});
            !s)
            return s;
        Result<std::optional<std::string>> name = string(*cam, "camera", "name");
        if (!name) return name.error();
        d.cameraName = std::move(*name);
        d.cameraNameNode = cam->get("name");
        if (d.cameraName && d.cameraName->empty())
            return fail(d.cameraNameNode, "'camera.name' is empty; name a camera of the glTF "
                                          "file or leave the key out");

        Result<std::optional<double>> aperture = number(*cam, "camera", "aperture_radius_m");
        if (!aperture) return aperture.error();
        if (*aperture && **aperture < 0.0)
            return fail(cam->get("aperture_radius_m"),
                        "'camera.aperture_radius_m' is {}; it must be >= 0 (0 = pinhole)",
                        **aperture);
        d.apertureRadiusM = *aperture;

        Result<std::optional<double>> focus = number(*cam, "camera", "focus_distance_m");
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
    std::error_code ec;
    if (!fs::exists(path, ec))
        return makeError("cannot load scene description '{}': no such file (check the path)",
                         path);
    if (!fs::is_regular_file(path, ec))
        return makeError("cannot load scene description '{}': it is not a regular file", path);
    // toml++ reports syntax errors by throwing (Debian builds it with exceptions, see
    // config/CMakeLists.txt); they end here, as a Result.
    try {
        const toml::table root = toml::parse_file(path);
        return DescriptionReader(path).read(root);
    } catch (const toml::parse_error& e) {
        return makeError("cannot load scene description '{}': line {}, column {}: not valid "
                         "TOML: {}",
                         path, e.source().begin.line, e.source().begin.column, e.description());
    } catch (const std::exception& e) {
        return makeError("cannot load scene description '{}': {}", path, e.what());
    }
}

Result<Scene> loadScene(const std::string& path) {
    const std::string ext = lowerExtension(path);
    if (ext == ".gltf" || ext == ".glb") return loadGltf(path);
    if (ext == ".toml") return loadSceneDescription(path);
    return makeError("cannot load scene '{}': unsupported file type '{}' (accepted: .gltf, .glb "
                     "or a previs.toml scene description)",
                     path, ext.empty() ? std::string("(none)") : ext);
}

}  // namespace previs
