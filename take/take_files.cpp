#include "take/take_files.h"

#include <toml++/toml.h>

#include <cstring>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "base/atomic_file.h"
#include "base/bounded_file.h"
#include "base/log.h"
#include "colour/ocio_colour.h"
#include "io/session.h"

namespace previs {

namespace fs = std::filesystem;

namespace {

std::string lowerExtension(const fs::path& p) {
    std::string ext = p.extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext;
}

// A glTF URI as a relative path: percent-escapes decoded (glTF 2.0 §3.3: URIs are RFC 3986).
std::string decodeUri(const std::string& uri) {
    std::string out;
    for (size_t i = 0; i < uri.size(); ++i) {
        if (uri[i] == '%' && i + 2 < uri.size() && std::isxdigit(uint8_t(uri[i + 1])) &&
            std::isxdigit(uint8_t(uri[i + 2]))) {
            out += char(std::stoi(uri.substr(i + 1, 2), nullptr, 16));
            i += 2;
        } else {
            out += uri[i];
        }
    }
    return out;
}

// The JSON of a .gltf, or the JSON chunk of a .glb (glTF 2.0 §4.4: 12-byte header, then chunks
// of length, type, data; the first is JSON).
Result<nlohmann::json> gltfJson(const std::string& path) {
    Result<std::vector<uint8_t>> bytes = readSessionFile(path);
    if (!bytes) return bytes.error();
    const std::vector<uint8_t>& b = *bytes;
    std::string_view text(reinterpret_cast<const char*>(b.data()), b.size());
    if (lowerExtension(path) == ".glb") {
        auto u32 = [&](size_t at) {
            uint32_t v = 0;
            std::memcpy(&v, b.data() + at, 4);
            return v;
        };
        if (b.size() < 20 || u32(0) != 0x46546C67u || u32(16) != 0x4E4F534Au ||
            u32(12) > b.size() - 20)
            return makeError("{}: not a glTF binary (.glb) with a JSON chunk", path);
        text = text.substr(20, u32(12));
    }
    nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
    if (j.is_discarded()) return makeError("{}: not valid glTF JSON", path);
    return j;
}

// A file the scene names, checked inside `takeDir` (when given) before anything reads it.
Status checkScenePath(const fs::path& file, const std::string& takeDir, const std::string& by) {
    if (takeDir.empty()) return {};
    const fs::path root = fs::absolute(takeDir).lexically_normal();
    const std::string rel = file.lexically_relative(root).string();
    Result<std::string> p = containedPath(takeDir, rel.empty() ? file.string() : rel, by);
    if (!p) return p.error();
    return {};
}

Status addGltfFiles(const fs::path& gltf, const std::string& takeDir,
                    std::vector<std::string>& files) {
    Result<nlohmann::json> j = gltfJson(gltf.string());
    if (!j) return j.error();
    for (const char* list : {"buffers", "images"}) {
        const auto it = j->find(list);
        if (it == j->end() || !it->is_array()) continue;
        for (const nlohmann::json& item : *it) {
            if (!item.is_object() || !item.contains("uri") || !item["uri"].is_string()) continue;
            const std::string uri = item["uri"].get<std::string>();
            if (uri.rfind("data:", 0) == 0) continue;
            const fs::path file = (gltf.parent_path() / decodeUri(uri)).lexically_normal();
            if (Status s = checkScenePath(file, takeDir, gltf.string()); !s) return s;
            files.push_back(file.string());
        }
    }
    return {};
}

}  // namespace

Result<std::vector<std::string>> sceneFiles(const std::string& scenePath,
                                            const std::string& takeDir) {
    const fs::path scene = fs::absolute(scenePath).lexically_normal();
    std::vector<std::string> files{scene.string()};
    if (Status s = checkScenePath(scene, takeDir, scenePath); !s) return s.error();
    try {
        if (lowerExtension(scene) == ".toml") {
            Result<std::string> text = readBoundedText(scene.string(), kMaxSessionFileBytes,
                                                       FileLinks::Follow, "scene description");
            if (!text) return text.error();
            const toml::table t = toml::parse(*text, scene.string());
            const std::optional<std::string> gltf = t["gltf"].value<std::string>();
            if (!gltf) return makeError("{}: the description names no 'gltf'", scene.string());
            const fs::path gltfPath = (scene.parent_path() / *gltf).lexically_normal();
            if (Status s = checkScenePath(gltfPath, takeDir, scene.string()); !s) return s.error();
            files.push_back(gltfPath.string());
            if (Status s = addGltfFiles(gltfPath, takeDir, files); !s) return s.error();
            const std::optional<std::string> map = t["environment"]["map"].value<std::string>();
            if (map && *map != "studio") {
                const fs::path mapPath = (scene.parent_path() / *map).lexically_normal();
                if (Status s = checkScenePath(mapPath, takeDir, scene.string()); !s)
                    return s.error();
                files.push_back(mapPath.string());
            }
        } else if (Status s = addGltfFiles(scene, takeDir, files); !s) {
            return s.error();
        }
    } catch (const std::exception& e) {
        return makeError("{}: {}", scene.string(), e.what());
    }
    return files;
}

namespace {

// The deepest folder holding every one of `files`.
fs::path commonFolder(const std::vector<std::string>& files) {
    fs::path common = fs::path(files.front()).parent_path();
    for (const std::string& f : files) {
        const fs::path folder = fs::path(f).parent_path();
        fs::path shared;
        auto a = common.begin(), b = folder.begin();
        for (; a != common.end() && b != folder.end() && *a == *b; ++a, ++b) shared /= *a;
        common = shared;
    }
    return common;
}

Status copyInto(const std::string& from, const fs::path& to) {
    Result<std::vector<uint8_t>> bytes = readSessionFile(from);
    if (!bytes)
        return makeError("recording: cannot copy {} into the take: {}", from, bytes.message());
    std::error_code ec;
    fs::create_directories(to.parent_path(), ec);
    if (ec) return makeError("{}: cannot create: {}", to.parent_path().string(), ec.message());
    return writeFileAtomic(to.string(), *bytes);
}

// An OCIO config and the LUTs it names, copied to `into` (relative to the take) keeping their
// layout relative to each other, so the copy's search_path finds the copies; returns where the
// config's copy is, relative to the take.
Result<fs::path> copyOcioConfig(const std::string& configPath, const fs::path& take,
                                const fs::path& into) {
    Result<std::vector<std::string>> luts = ocioConfigFiles(configPath);
    if (!luts) return makeError("recording: {}", luts.message());
    const std::string config = fs::absolute(configPath).lexically_normal().string();
    std::vector<std::string> all{config};
    all.insert(all.end(), luts->begin(), luts->end());
    const fs::path root = commonFolder(all);
    for (const std::string& lut : *luts)
        if (Status s = copyInto(lut, take / into / fs::path(lut).lexically_relative(root)); !s)
            return s.error();
    Result<std::string> text = relocatableOcioConfig(configPath);
    if (!text) return makeError("recording: {}", text.message());
    const fs::path copy = into / fs::path(config).lexically_relative(root);
    std::error_code ec;
    fs::create_directories((take / copy).parent_path(), ec);
    if (ec)
        return makeError("{}: cannot create: {}", (take / copy).parent_path().string(),
                         ec.message());
    const std::span<const uint8_t> bytes(reinterpret_cast<const uint8_t*>(text->data()),
                                         text->size());
    if (Status s = writeFileAtomic((take / copy).string(), bytes); !s) return s.error();
    return copy;
}

// [output] belongs to the box (its KMS card, its frames' folder), but not its colour: a take
// shows as the box showed it (issue 54). Keeps [output.colour] alone, its OCIO config copied.
Status keepOutputColour(toml::table& t, const ServiceConfig& config, const fs::path& take) {
    toml::table* colour = t["output"]["colour"].as_table();
    if (!colour) {
        t.erase("output");
        return {};
    }
    toml::table kept = *colour;
    if (!config.output.colourConfigPath.empty()) {
        Result<fs::path> copy =
            copyOcioConfig(config.output.colourConfigPath, take, "config/colour/output");
        if (!copy) return copy.error();
        kept.insert_or_assign("ocio_config", copy->string());
    }
    toml::table output;
    output.insert("colour", std::move(kept));
    t.insert_or_assign("output", std::move(output));
    return {};
}

}  // namespace

Result<std::string> copyConfigIntoTake(const ServiceConfig& config, const std::string& takeDir) {
    toml::table t;
    try {
        t = toml::parse_file(config.path);
    } catch (const std::exception& e) {
        return makeError("recording: cannot read the config '{}' again: {}", config.path, e.what());
    }
    const fs::path take(takeDir);
    // The scene and what it names keep their layout, so their relative references hold.
    Result<std::vector<std::string>> scene = sceneFiles(config.scenePath);
    if (!scene) return makeError("recording: {}", scene.message());
    const fs::path sceneRoot = commonFolder(*scene);
    for (const std::string& f : *scene)
        if (Status s =
                copyInto(f, take / "config/scene" / fs::path(f).lexically_relative(sceneRoot));
            !s)
            return s.error();
    t.insert_or_assign(
        "scene",
        ("config/scene" / fs::path(scene->front()).lexically_relative(sceneRoot)).string());

    std::vector<std::string> cameras;
    if (toml::table* cams = t["cameras"].as_table())
        for (auto& [name, node] : *cams) {
            toml::table* cam = node.as_table();
            if (!cam) continue;
            const std::string camName(name.str());
            const CameraConfig* c = camName == "scene" ? &config.sceneCamera
                                    : config.fisheyeCamera && camName == "fisheye"
                                        ? &*config.fisheyeCamera
                                        : nullptr;
            if (!c) continue;
            const fs::path calibration =
                fs::path("config/cameras") / camName / fs::path(c->calibrationPath).filename();
            if (Status s = copyInto(c->calibrationPath, take / calibration); !s) return s.error();
            cam->insert_or_assign("calibration", calibration.string());
            // The camera's OCIO config too, with the LUTs it names.
            if (toml::table* colour = (*cam)["colour"].as_table();
                colour && !c->colourConfigPath.empty()) {
                Result<fs::path> ocio =
                    copyOcioConfig(c->colourConfigPath, take, fs::path("config/colour") / camName);
                if (!ocio) return ocio.error();
                colour->insert_or_assign("ocio_config", ocio->string());
            }
            cam->insert_or_assign("source", "session");
            cam->insert_or_assign("device", "cameras/" + camName);
            cam->erase("format");
            cam->erase("controls");
        }
    const fs::path board =
        fs::path("config/board") / fs::path(config.tracking.boardPath).filename();
    if (Status s = copyInto(config.tracking.boardPath, take / board); !s) return s.error();
    if (toml::table* tracking = t["tracking"].as_table())
        tracking->insert_or_assign("board", board.string());
    // A FreeD tracker's calibration too: a take names nothing outside itself (issue 52).
    if (!config.tracking.freedCalibrationPath.empty()) {
        const fs::path freed =
            fs::path("config/freed") / fs::path(config.tracking.freedCalibrationPath).filename();
        if (Status s = copyInto(config.tracking.freedCalibrationPath, take / freed); !s)
            return s.error();
        if (toml::table* tracking = t["tracking"].as_table())
            tracking->insert_or_assign("freed_calibration", freed.string());
    }
    if (toml::table* lighting = t["lighting"].as_table()) lighting->erase("saved");
    if (Status s = keepOutputColour(t, config, take); !s) return s.error();
    for (const char* boxOnly : {"button", "control", "record", "session"}) t.erase(boxOnly);

    if (Status s = copyInto(config.path, take / "config/recorded-from.toml"); !s) return s.error();
    // The copies' folder entries, deepest first, then the take's own.
    std::vector<std::string> folders;
    std::error_code ec;
    for (auto it = fs::recursive_directory_iterator(take / "config", ec);
         !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
        if (it->is_directory()) folders.push_back(it->path().string());
    folders.push_back((take / "config").string());
    for (auto f = folders.rbegin(); f != folders.rend(); ++f)
        if (Status s = syncFolder(*f); !s) return s.error();
    std::ostringstream text;
    text << "# previsd's config as this take was recorded (docs/session-format.md, config.toml):\n"
         << "# the original is config/recorded-from.toml; paths here name the copies in config/\n"
         << "# and the take's own cameras, relative to the take's folder.\n"
         << t << "\n";
    return text.str();
}

Status checkTakeContained(const std::string& takeDir, const std::string& configPath,
                          const std::string& configDirInTake) {
    const fs::path root = fs::absolute(takeDir).lexically_normal();
    const std::string configRel =
        fs::absolute(configPath).lexically_normal().lexically_relative(root).string();
    if (Result<std::string> self = containedPath(takeDir, configRel, configPath); !self)
        return self.error();
    Result<std::string> text =
        readBoundedText(configPath, kMaxSessionFileBytes, FileLinks::Refuse, "take config");
    if (!text) return text.error();
    toml::table t;
    try {
        t = toml::parse(*text, configPath);
    } catch (const std::exception& e) {
        return makeError("{}: {}", configPath, e.what());
    }
    // The config's relative paths start at config_dir, itself inside the take (openSession).
    auto check = [&](const toml::node_view<toml::node>& node, bool folder) -> Result<std::string> {
        const std::optional<std::string> v = node.value<std::string>();
        if (!v) return std::string();
        // An absolute path stays absolute when joined, and is refused.
        return containedPath(takeDir, (fs::path(configDirInTake) / *v).string(), configPath,
                             folder);
    };
    Result<std::string> scene = check(t["scene"], false);
    if (!scene) return scene.error();
    if (toml::table* cams = t["cameras"].as_table())
        for (auto& [name, node] : *cams) {
            for (auto [key, folder] : {std::pair{"calibration", false}, std::pair{"device", true}})
                if (Result<std::string> p = check(toml::node_view<toml::node>(node)[key], folder);
                    !p)
                    return p.error();
            if (Result<std::string> p =
                    check(toml::node_view<toml::node>(node)["colour"]["ocio_config"], false);
                !p)
                return p.error();
        }
    // Every file the config loader reads: a FreeD calibration is checked as the board is.
    for (const toml::node_view<toml::node> node :
         {t["tracking"]["board"], t["tracking"]["freed_calibration"], t["lighting"]["saved"],
          t["output"]["colour"]["ocio_config"]})
        if (Result<std::string> p = check(node, false); !p) return p.error();
    if (scene->empty()) return {};
    Result<std::vector<std::string>> files = sceneFiles(*scene, takeDir);
    if (!files) return files.error();
    return {};
}

Result<ServiceConfig> loadSessionConfig(const SessionInfo& session) {
    if (session.configPath.empty())
        return makeError("{}: the session has no config.toml; give one with --config", session.dir);
    // Whatever version it declares: a v2 label must not switch the checks off.
    if (Status s = checkTakeContained(session.dir, session.configPath, session.configDirInTake); !s)
        return s.error();
    return loadServiceConfig(session.configPath, session.configDir);
}

}  // namespace previs
