#include "scene/gltf_loader.h"

#include <fcntl.h>
#include <fnmatch.h>
#include <sys/stat.h>
#include <tiny_gltf.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <exception>
#include <filesystem>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <span>
#include <tuple>
#include <utility>

#include "base/log.h"
#include "base/strings.h"
#include "base/unique_fd.h"
#include "image/image.h"

namespace previs {
namespace {

// Extensions this loader implements. Any other one listed in extensionsRequired means the file
// cannot be shown correctly, so loading fails (glTF 2.0 spec §3.12); any other one merely used is
// ignored, with one warning listing them all. KHR_texture_transform is deliberately absent:
// ignoring it misplaces textures, which the warning says.
const std::set<std::string> kSupportedExtensions = {
    "KHR_materials_transmission",      "KHR_materials_ior",    "KHR_materials_specular",
    "KHR_materials_emissive_strength", "KHR_materials_volume", "KHR_lights_punctual",
};

// KHR_lights_punctual gives photometric intensities (candela for point and spot lights, lux for
// directional ones); previs renders radiometric ones (W/sr, W/m², DESIGN.md §4 "radiance in the
// scene's units"). 683 lm/W is the factor Blender's glTF importer and exporter use
// (io_scene_gltf2 PBR_WATTS_TO_LUMENS, lighting mode "Standard", their default): a Blender point
// light of P watts is exported as P / 4π × 683 cd, a sun of S W/m² as S × 683 lx, so dividing by
// 683 gives back Blender's P / 4π W/sr and S W/m² (docs/scene-format.md, "Units of light").
constexpr double kLumensPerWatt = 683.0;

// Deeper hierarchies than this are treated as malformed (a cycle, or a hostile file trying to
// exhaust the stack).
constexpr int kMaxNodeDepth = 256;

// What a glTF may make previs read (DESIGN.md §7: a scene is a file someone sends). tinygltf's
// own file callbacks read a folder as if it were a file of absurd size (an image URI that decodes
// to a NUL byte, tinygltf's tests/issue-416.gltf, ends in std::bad_alloc), block on a FIFO,
// expand `~` and `$VARIABLES`, follow `../` and absolute URIs anywhere on the machine and look
// in the working folder too. These resolve a URI against the glTF's folder only, refuse one that
// leaves it, read regular files only, and keep every byte read and every pixel decoded within
// GltfLoadOptions::maxDataBytes.
class SceneFiles {
public:
    SceneFiles(std::filesystem::path folder, uint64_t budget)
        : folder_(std::move(folder)), budget_(budget), left_(budget) {}

    // The file a URI names inside the glTF's folder, symbolic links and `..` resolved; nullopt
    // when there is none (a missing file is the caller's fallback; a refused URI is recorded).
    std::optional<std::filesystem::path> resolve(const std::string& uri);
    // The whole file `uri` names, counted against the budget; an error text when it cannot be.
    Result<std::vector<unsigned char>> read(const std::string& uri);
    // Takes `bytes` from the budget for `what` (an image's decoded pixels, the glTF itself);
    // false, with the refusal recorded, when they do not fit.
    bool take(uint64_t bytes, const std::string& what);

    // The first URI refused or budget exceeded: the load fails with this, whatever tinygltf
    // made of the missing file.
    const std::string& refusal() const { return refusal_; }
    std::map<int, std::string> imageFailures;  // glTF image index -> why it did not decode

private:
    void refuse(std::string why) {
        if (refusal_.empty()) refusal_ = std::move(why);
    }

    std::filesystem::path folder_;  // canonical
    uint64_t budget_;
    uint64_t left_;
    std::string refusal_;
};

// "scheme:" of an absolute URI (RFC 3986 §3.1); empty for a relative reference.
std::string uriScheme(const std::string& uri) {
    if (uri.empty() || !std::isalpha(static_cast<unsigned char>(uri[0]))) return {};
    for (size_t i = 1; i < uri.size(); ++i) {
        const unsigned char c = static_cast<unsigned char>(uri[i]);
        if (c == ':') return uri.substr(0, i);
        if (!std::isalnum(c) && c != '+' && c != '-' && c != '.') return {};
    }
    return {};
}

std::string byteSize(uint64_t bytes) {
    if (bytes < (uint64_t(16) << 10)) return fmt::format("{} bytes", bytes);
    if (bytes < (uint64_t(16) << 20)) return fmt::format("{} KiB", bytes >> 10);
    return fmt::format("{} MiB", bytes >> 20);
}

std::optional<std::filesystem::path> SceneFiles::resolve(const std::string& uri) {
    namespace fs = std::filesystem;
    const std::string fix = fmt::format(
        "previs reads a scene's buffers and images only from inside the glTF's folder '{}' (or "
        "from data: URIs): copy the file there and name it by a path relative to the glTF",
        folder_.string());
    // A name with a NUL byte names no file: the texture falls back (TinygltfIssue416).
    if (uri.empty() || uri.find('\0') != std::string::npos) return std::nullopt;
    if (uri.front() == '/') {
        refuse(fmt::format("the URI '{}' is an absolute path; {}", uri, fix));
        return std::nullopt;
    }
    if (const std::string scheme = uriScheme(uri); !scheme.empty()) {
        // A data: URI of a media type tinygltf does not decode: no file, the texture falls back.
        if (scheme != "data")
            refuse(fmt::format("the URI '{}' is a {}: URI; {}", uri, scheme, fix));
        return std::nullopt;
    }
    std::error_code ec;
    const fs::path target = fs::weakly_canonical(folder_ / uri, ec);
    if (ec) return std::nullopt;
    const fs::path inside = target.lexically_relative(folder_);
    if (inside.empty() || *inside.begin() == "..") {
        refuse(fmt::format(
            "the URI '{}' leads outside the glTF's folder (after resolving '..' and symbolic "
            "links); {}",
            uri, fix));
        return std::nullopt;
    }
    return target;
}

bool SceneFiles::take(uint64_t bytes, const std::string& what) {
    if (bytes <= left_) {
        left_ -= bytes;
        return true;
    }
    refuse(fmt::format(
        "its buffers and images need more than the {} previs gives a scene ({} needs {}, {} "
        "left); make the textures smaller or split the scene",
        byteSize(budget_), what, byteSize(bytes), byteSize(left_)));
    return false;
}

// A GLB's 32-bit length bounds every valid buffer or image file.
constexpr uint64_t kMaxExternalFileBytes = uint64_t(1) << 32;

// The regular file at `path`, whole, if it holds at most `maxBytes`: opened without waiting (a
// FIFO is refused, not read) and, unless `followLink`, without following a link.
Result<std::vector<unsigned char>> readRegularFile(const std::string& path, bool followLink,
                                                   uint64_t maxBytes, uint64_t* size) {
    const int flags = O_RDONLY | O_CLOEXEC | O_NONBLOCK | (followLink ? 0 : O_NOFOLLOW);
    UniqueFD fd(::open(path.c_str(), flags));
    if (!fd.isValid()) return makeError("{}", std::strerror(errno));
    struct stat st {};
    if (::fstat(fd.get(), &st) != 0) return makeError("{}", std::strerror(errno));
    if (!S_ISREG(st.st_mode)) return makeError("not a regular file");
    *size = uint64_t(st.st_size);
    if (*size > maxBytes) return makeError("{} bytes, more than {}", *size, maxBytes);
    std::vector<unsigned char> bytes(size_t(st.st_size));
    size_t got = 0;
    while (got < bytes.size()) {
        const ssize_t n = ::read(fd.get(), bytes.data() + got, bytes.size() - got);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) return makeError("{}", std::strerror(errno));
        if (n == 0) return makeError("cut short while reading");
        got += size_t(n);
    }
    return bytes;
}

Result<std::vector<unsigned char>> SceneFiles::read(const std::string& uri) {
    const std::optional<std::filesystem::path> path = resolve(uri);
    if (!path) return makeError("{}", refusal_.empty() ? "no such file" : refusal_);
    const uint64_t most = std::min(kMaxExternalFileBytes, left_);
    uint64_t size = 0;
    // The path is canonical: a link found there now was swapped in since, it is not the scene's.
    Result<std::vector<unsigned char>> bytes = readRegularFile(path->string(), false, most, &size);
    if (!bytes && size > most && size <= kMaxExternalFileBytes)
        take(size, fmt::format("'{}'", uri));  // over the budget: records why
    if (bytes) take(size, fmt::format("'{}'", uri));
    return bytes;
}

bool externalFileExists(const std::string& uri, void* user) {
    std::optional<std::filesystem::path> path = static_cast<SceneFiles*>(user)->resolve(uri);
    std::error_code ec;
    return path && std::filesystem::is_regular_file(*path, ec);
}

std::string expandNothing(const std::string& path, void* /*user*/) { return path; }

bool readExternalFile(std::vector<unsigned char>* out, std::string* err, const std::string& uri,
                      void* user) {
    Result<std::vector<unsigned char>> bytes = static_cast<SceneFiles*>(user)->read(uri);
    if (!bytes) {
        *err = bytes.message();
        return false;
    }
    *out = std::move(*bytes);
    return true;
}

// Decodes every image to RGBA8. A texture that does not decode is not fatal: the image is left
// empty and the material loses that texture (fallback "no texture", i.e. the material's factors
// alone), with a warning. On set, a preview with a missing texture beats no preview. An image
// whose declared size does not fit the scene's budget fails the load, before it is decoded.
bool decodeImage(tinygltf::Image* image, const int imageIndex, std::string* /*err*/,
                 std::string* /*warn*/, int /*reqWidth*/, int /*reqHeight*/,
                 const unsigned char* bytes, int size, void* user) {
    auto* files = static_cast<SceneFiles*>(user);
    const std::span<const uint8_t> encoded(bytes, size > 0 ? size_t(size) : 0);
    const std::string name = fmt::format("image {}", imageIndex);
    auto what = [&](uint32_t width, uint32_t height) {
        return fmt::format("image {} ('{}', {}x{} pixels decoded)", imageIndex,
                           image->name.empty() ? image->uri : image->name, width, height);
    };
    uint64_t taken = 0;
    if (const Result<ImageSize> declared = encodedImageSize(encoded, name); declared) {
        taken = uint64_t(declared->width) * declared->height * 4;
        if (!files->take(taken, what(declared->width, declared->height))) return false;
    }
    // Through image/'s checks (content type, size limit from the header), not straight to stb:
    // a hostile texture must not hang or exhaust the loader.
    Result<ImageRgba8> decoded = size > 0 ? decodePngOrJpeg(encoded, name)
                                          : Result<ImageRgba8>(makeError("{} is empty", name));
    if (!decoded) {
        files->imageFailures[imageIndex] = decoded.message();
        image->image.clear();
        image->width = image->height = 0;
        return true;
    }
    // A header that could not be sized does not decode either; counted once decoded all the same.
    if (decoded->pixels.size() > taken &&
        !files->take(decoded->pixels.size() - taken, what(decoded->width, decoded->height)))
        return false;
    image->width = int(decoded->width);
    image->height = int(decoded->height);
    image->component = 4;
    image->bits = 8;
    image->pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    image->image = std::move(decoded->pixels);
    return true;
}

// tinygltf reports several problems as newline-separated text; one line reads better.
std::string oneLine(std::string text) {
    while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
    std::replace(text.begin(), text.end(), '\n', ';');
    return text;
}

const tinygltf::Value* findPath(const tinygltf::Value& root,
                                std::initializer_list<const char*> keys) {
    const tinygltf::Value* v = &root;
    for (const char* key : keys) {
        if (!v->IsObject() || !v->Has(key)) return nullptr;
        v = &v->Get(key);
    }
    return v;
}

const tinygltf::Value* findExtension(const tinygltf::ExtensionMap& extensions,
                                     const std::string& name) {
    auto it = extensions.find(name);
    return it == extensions.end() ? nullptr : &it->second;
}

float numberOr(const tinygltf::Value* object, const char* key, float fallback) {
    if (!object) return fallback;
    const tinygltf::Value* v = findPath(*object, {key});
    return v && v->IsNumber() ? float(v->GetNumberAsDouble()) : fallback;
}

glm::vec3 vec3Or(const tinygltf::Value* object, const char* key, glm::vec3 fallback) {
    if (!object) return fallback;
    const tinygltf::Value* v = findPath(*object, {key});
    if (!v || !v->IsArray() || v->ArrayLen() != 3) return fallback;
    glm::vec3 out;
    for (int i = 0; i < 3; ++i) {
        if (!v->Get(i).IsNumber()) return fallback;
        out[i] = float(v->Get(i).GetNumberAsDouble());
    }
    return out;
}

class Loader {
public:
    Loader(std::string path, tinygltf::Model model, std::map<int, std::string> imageFailures,
           GltfLoadOptions options)
        : path_(std::move(path)),
          model_(std::move(model)),
          imageFailures_(std::move(imageFailures)),
          options_(std::move(options)),
          ruleMatched_(options_.roleRules.size(), 0) {}

    Result<Scene> run();

private:
    template <typename... Args>
    Error fail(fmt::format_string<Args...> format, Args&&... args) const {
        return Error{fmt::format("cannot load glTF '{}': {}", path_,
                                 fmt::format(format, std::forward<Args>(args)...))};
    }

    std::string originSuffix() const {
        return options_.roleRulesOrigin.empty() ? std::string() : " in " + options_.roleRulesOrigin;
    }
    Status checkExtensions() const;
    Result<std::optional<bool>> roleByName(const tinygltf::Node& node, int nodeIndex);
    Status loadMaterials();
    // Warns, once per material, when `material` is glTF's thin wall by default (no volume, no
    // previs.toml override) on the closed mesh `meshIndex`: what Blender writes for solid glass.
    void checkThinGlassOnClosedMesh(uint32_t material, int meshIndex);
    bool meshIsClosed(int meshIndex);
    void clampToSpecification(Material& m, glm::vec3& emissive, float& strength) const;
    Result<int> textureFor(int gltfTexture, bool srgb, const std::string& materialName);
    // Transforms are composed in double and are relative to scene_.originM (the "world" of
    // these names is the scene's frame): float keeps precision far from the world origin.
    Status visitNode(int nodeIndex, const glm::dmat4& parentWorld, bool parentReal, int depth);
    Status loadMesh(int meshIndex, const glm::dmat4& worldFromMesh, bool real);
    Status loadPrimitive(const tinygltf::Mesh& mesh, int meshIndex, size_t primIndex,
                         const glm::dmat4& worldFromMesh, bool real);
    // One primitive's vertex attributes as the file stores them (mesh space, flat arrays).
    struct PrimitiveVertices {
        std::vector<float> positions;  // xyz per vertex
        std::vector<float> normals;    // xyz per vertex, or empty (flat shading)
        std::vector<float> uvs;        // uv per vertex, or empty
        size_t count = 0;
        glm::vec3 position(uint32_t i) const {
            return glm::vec3(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]);
        }
        glm::vec2 uv(uint32_t i) const {
            return uvs.empty() ? glm::vec2(0.0f) : glm::vec2(uvs[2 * i], uvs[2 * i + 1]);
        }
    };
    // A primitive's triangles that are kept, with its vertices placed in the scene's frame.
    struct PrimitiveTriangles {
        const PrimitiveVertices& vertices;
        const std::vector<glm::vec3>& world;
        std::vector<glm::uvec3> triangles;
        uint32_t material = 0;
        bool real = false;
    };
    Result<PrimitiveVertices> readVertices(const tinygltf::Mesh& mesh, int meshIndex,
                                           const tinygltf::Primitive& prim,
                                           const std::string& what) const;
    struct VertexAttribute {
        const char* name;      // glTF attribute semantic
        int type;              // TINYGLTF_TYPE_VEC*
        bool allowNormalized;  // normalized unsigned integer components are accepted
        const char* noun;      // for the count mismatch message
    };
    // An optional per-vertex attribute: absent leaves `out` empty; present must match POSITION.
    Status readVertexAttribute(const tinygltf::Primitive& prim, const VertexAttribute& attribute,
                               const std::string& what, size_t vertexCount,
                               std::vector<float>& out) const;
    Result<std::vector<uint32_t>> readTriangleIndices(const tinygltf::Primitive& prim,
                                                      const std::string& what,
                                                      size_t vertexCount) const;
    Result<uint32_t> primitiveMaterial(const tinygltf::Primitive& prim, const std::string& what);
    // Drops repeated-index and degenerate triangles (counted), fixing the winding if mirrored.
    std::vector<glm::uvec3> keepTriangles(const std::vector<uint32_t>& indices,
                                          const PrimitiveVertices& vertices,
                                          const std::vector<glm::vec3>& world, bool mirrored);
    void appendFlatTriangles(const PrimitiveTriangles& prim);
    std::vector<glm::vec3> worldNormals(const PrimitiveTriangles& prim,
                                        const glm::mat3& normalMatrix);
    void appendSmoothTriangles(const PrimitiveTriangles& prim,
                               const std::vector<glm::vec3>& normals);
    Status loadCamera(const tinygltf::Node& node, const glm::dmat4& world);
    void shiftTextureCoordinates(std::vector<float>& uvs, const Material& material) const;
    Status loadLight(const tinygltf::Node& node, const glm::dmat4& world, bool real);
    // Scene::originM for the nodes under `roots` (see its definition).
    glm::dvec3 chooseOrigin(const std::vector<int>& roots) const;

    // Reads `count` elements of `components` floats (float, or normalized unsigned integer types
    // when allowNormalized) or of 1 unsigned integer (indices).
    Status readFloats(int accessorIndex, int type, bool allowNormalized, const std::string& what,
                      std::vector<float>& out, size_t& count) const;
    Status readIndices(int accessorIndex, const std::string& what,
                       std::vector<uint32_t>& out) const;
    Result<const unsigned char*> accessorData(int accessorIndex, const std::string& what,
                                              size_t elementSize, size_t& stride) const;

    std::string path_;
    tinygltf::Model model_;
    std::map<int, std::string> imageFailures_;
    GltfLoadOptions options_;
    std::vector<uint8_t> ruleMatched_;  // per role rule: did it match any visited node
    Scene scene_;
    int defaultMaterial_ = -1;
    // (glTF image, srgb, wrapS, wrapT, nearest) -> Scene texture
    using TextureKey = std::tuple<int, bool, int, int, bool>;
    std::map<TextureKey, int> textureMap_;
    std::set<int> warnedImages_;
    // Materials that are thin walls by glTF's default only (transmissive, no volume, no
    // override), until the warning about them is given.
    std::set<uint32_t> thinByDefault_;
    std::map<int, bool> closedMeshes_;  // glTF mesh -> whether it is closed (computed once)
    std::set<std::string> overriddenMaterials_;  // thinWalledByMaterial names that matched
    size_t degenerateTriangles_ = 0;
    size_t skippedPrimitives_ = 0;
    size_t replacedNormals_ = 0;
};

std::string supportedExtensionList() {
    std::string list;
    for (const std::string& e : kSupportedExtensions) list += (list.empty() ? "" : ", ") + e;
    return list;
}

Status Loader::checkExtensions() const {
    for (const std::string& ext : model_.extensionsRequired) {
        if (!kSupportedExtensions.count(ext))
            return fail(
                "it requires the extension '{}', which previs does not support "
                "(supported: {}); re-export without it",
                ext, supportedExtensionList());
    }
    // extensionsUsed should list every extension the file uses, but exporters forget (tinygltf's
    // Cube-textransform.gltf uses KHR_texture_transform without listing it): the objects that
    // carry extensions are searched too.
    std::set<std::string> used(model_.extensionsUsed.begin(), model_.extensionsUsed.end());
    auto collect = [&](const tinygltf::ExtensionMap& extensions) {
        for (const auto& [name, value] : extensions) used.insert(name);
    };
    collect(model_.extensions);
    for (const tinygltf::Material& m : model_.materials) {
        collect(m.extensions);
        collect(m.pbrMetallicRoughness.baseColorTexture.extensions);
        collect(m.pbrMetallicRoughness.metallicRoughnessTexture.extensions);
        collect(m.normalTexture.extensions);
        collect(m.occlusionTexture.extensions);
        collect(m.emissiveTexture.extensions);
    }
    for (const tinygltf::Mesh& mesh : model_.meshes) {
        collect(mesh.extensions);
        for (const tinygltf::Primitive& prim : mesh.primitives) collect(prim.extensions);
    }
    for (const tinygltf::Node& n : model_.nodes) collect(n.extensions);
    for (const tinygltf::Texture& t : model_.textures) collect(t.extensions);
    for (const tinygltf::Image& i : model_.images) collect(i.extensions);
    std::string ignored;
    for (const std::string& ext : used)
        if (!kSupportedExtensions.count(ext)) ignored += (ignored.empty() ? "" : ", ") + ext;
    if (!ignored.empty())
        logWarning(
            "glTF '{}': ignoring the extensions it uses that previs does not support: {} "
            "(the file renders as if they were absent)",
            path_, ignored);
    return {};
}

Result<int> Loader::textureFor(int gltfTexture, bool srgb, const std::string& materialName) {
    if (gltfTexture < 0) return -1;
    if (size_t(gltfTexture) >= model_.textures.size())
        return fail("material '{}' refers to texture {}, but the file has {} textures",
                    materialName, gltfTexture, model_.textures.size());
    const int source = model_.textures[gltfTexture].source;
    if (source < 0) return -1;  // e.g. only an extension source (KTX2, WebP) we do not read
    if (size_t(source) >= model_.images.size())
        return fail("texture {} refers to image {}, but the file has {} images", gltfTexture,
                    source, model_.images.size());
    // glTF 2.0 §5.26: a texture without a sampler repeats and filters as the viewer likes
    // (bilinear here); magFilter NEAREST, or no magFilter and a NEAREST* minFilter, is nearest.
    TextureWrap wrapS = TextureWrap::Repeat;
    TextureWrap wrapT = TextureWrap::Repeat;
    bool nearest = false;
    if (const int samplerIndex = model_.textures[gltfTexture].sampler; samplerIndex >= 0) {
        if (size_t(samplerIndex) >= model_.samplers.size())
            return fail("texture {} refers to sampler {}, but the file has {} samplers",
                        gltfTexture, samplerIndex, model_.samplers.size());
        const tinygltf::Sampler& sampler = model_.samplers[samplerIndex];
        auto wrap = [&](int mode, const char* axis) -> Result<TextureWrap> {
            switch (mode) {
                case TINYGLTF_TEXTURE_WRAP_REPEAT:
                    return TextureWrap::Repeat;
                case TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT:
                    return TextureWrap::MirroredRepeat;
                case TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE:
                    return TextureWrap::ClampToEdge;
                default:
                    return fail(
                        "sampler {} has {} {} (glTF allows 10497 REPEAT, 33648 "
                        "MIRRORED_REPEAT, 33071 CLAMP_TO_EDGE)",
                        samplerIndex, axis, mode);
            }
        };
        Result<TextureWrap> s = wrap(sampler.wrapS, "wrapS");
        if (!s) return s.error();
        Result<TextureWrap> t = wrap(sampler.wrapT, "wrapT");
        if (!t) return t.error();
        wrapS = *s;
        wrapT = *t;
        nearest = sampler.magFilter == TINYGLTF_TEXTURE_FILTER_NEAREST ||
                  (sampler.magFilter < 0 &&
                   (sampler.minFilter == TINYGLTF_TEXTURE_FILTER_NEAREST ||
                    sampler.minFilter == TINYGLTF_TEXTURE_FILTER_NEAREST_MIPMAP_NEAREST ||
                    sampler.minFilter == TINYGLTF_TEXTURE_FILTER_NEAREST_MIPMAP_LINEAR));
    }
    const tinygltf::Image& image = model_.images[source];
    if (image.image.empty() || image.width <= 0 || image.height <= 0 ||
        image.image.size() != size_t(image.width) * size_t(image.height) * 4) {
        // Fallback documented at decodeImage: the material keeps its factors only.
        if (warnedImages_.insert(source).second) {
            auto failure = imageFailures_.find(source);
            logWarning(
                "glTF '{}': image {} ('{}') {}; material '{}' is rendered without that "
                "texture",
                path_, source, image.uri.size() > 64 ? image.name : image.uri,
                failure != imageFailures_.end()
                    ? "does not decode (" + failure->second + ")"
                    : std::string("could not be loaded (missing file?)"),
                materialName);
        }
        return -1;
    }
    const TextureKey key{source, srgb, int(wrapS), int(wrapT), nearest};
    if (auto it = textureMap_.find(key); it != textureMap_.end()) return it->second;

    Texture texture;
    texture.name = image.name.empty() ? image.uri : image.name;
    texture.width = uint32_t(image.width);
    texture.height = uint32_t(image.height);
    texture.srgb = srgb;
    texture.wrapS = wrapS;
    texture.wrapT = wrapT;
    texture.nearest = nearest;
    texture.rgba8.resize(size_t(image.width) * size_t(image.height));
    for (size_t i = 0; i < texture.rgba8.size(); ++i) {
        const unsigned char* p = image.image.data() + i * 4;
        texture.rgba8[i] =
            uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
    }
    const int index = int(scene_.textures.size());
    scene_.textures.push_back(std::move(texture));
    textureMap_[key] = index;
    return index;
}

// Each factor's range in the glTF 2.0 schema (material.pbrMetallicRoughness, material) and in the
// extensions' schemas: colours and factors in [0, 1], specularColorFactor and emissiveStrength
// >= 0, ior >= 1 or exactly 0. A value outside is clamped to the nearest end of its range, a
// non-finite one (JSON numbers too large for a float) becomes the default; one warning per
// material lists every change. ior 0 is valid glTF (a Fresnel term of 1 at every angle, for
// specular-glossiness files), which previs's Fresnel cannot express: it is rendered with the
// default 1.5, and the warning says so.
void Loader::clampToSpecification(Material& m, glm::vec3& emissive, float& strength) const {
    std::string changes;
    auto note = [&](const std::string& what, float from, float to) {
        changes += fmt::format("{}{} {} → {}", changes.empty() ? "" : ", ", what, from, to);
    };
    auto clampValue = [&](float& v, float lo, float hi, float fallback, const std::string& what) {
        const float fixed = std::isfinite(v) ? std::clamp(v, lo, hi) : fallback;
        if (fixed != v) note(what, v, fixed);
        v = fixed;
    };
    const float kInf = std::numeric_limits<float>::infinity();
    static const char* const kRgba[] = {"[0]", "[1]", "[2]", "[3]"};
    for (int c = 0; c < 4; ++c)
        clampValue(m.baseColor[c], 0.0f, 1.0f, 1.0f, std::string("baseColorFactor") + kRgba[c]);
    clampValue(m.metallic, 0.0f, 1.0f, 1.0f, "metallicFactor");
    clampValue(m.roughness, 0.0f, 1.0f, 1.0f, "roughnessFactor");
    for (int c = 0; c < 3; ++c)
        clampValue(emissive[c], 0.0f, 1.0f, 0.0f, std::string("emissiveFactor") + kRgba[c]);
    clampValue(strength, 0.0f, kInf, 1.0f, "emissiveStrength");
    clampValue(m.transmission, 0.0f, 1.0f, 0.0f, "transmissionFactor");
    clampValue(m.specular, 0.0f, 1.0f, 1.0f, "specularFactor");
    for (int c = 0; c < 3; ++c)
        clampValue(m.specularColor[c], 0.0f, kInf, 1.0f,
                   std::string("specularColorFactor") + kRgba[c]);
    if (m.ior == 0.0f) {
        changes += std::string(changes.empty() ? "" : ", ") +
                   "ior 0 → 1.5 (0 means a Fresnel term of 1, which previs does not support)";
        m.ior = 1.5f;
    } else {
        clampValue(m.ior, 1.0f, kInf, 1.5f, "ior");
    }
    if (!changes.empty())
        logWarning(
            "glTF '{}': material '{}' has values outside the glTF specification's "
            "ranges; using {}",
            path_, m.name, changes);
}

Status Loader::loadMaterials() {
    for (size_t i = 0; i < model_.materials.size(); ++i) {
        const tinygltf::Material& m = model_.materials[i];
        Material out;
        out.name = m.name.empty() ? fmt::format("material{}", i) : m.name;
        const auto& pbr = m.pbrMetallicRoughness;
        if (pbr.baseColorFactor.size() == 4)
            out.baseColor = glm::vec4(pbr.baseColorFactor[0], pbr.baseColorFactor[1],
                                      pbr.baseColorFactor[2], pbr.baseColorFactor[3]);
        out.metallic = float(pbr.metallicFactor);
        out.roughness = float(pbr.roughnessFactor);
        glm::vec3 emissive(0.0f);
        if (m.emissiveFactor.size() == 3)
            emissive = glm::vec3(m.emissiveFactor[0], m.emissiveFactor[1], m.emissiveFactor[2]);
        float strength = numberOr(findExtension(m.extensions, "KHR_materials_emissive_strength"),
                                  "emissiveStrength", 1.0f);
        out.transmission = numberOr(findExtension(m.extensions, "KHR_materials_transmission"),
                                    "transmissionFactor", 0.0f);
        out.ior = numberOr(findExtension(m.extensions, "KHR_materials_ior"), "ior", 1.5f);
        const tinygltf::Value* specular = findExtension(m.extensions, "KHR_materials_specular");
        out.specular = numberOr(specular, "specularFactor", 1.0f);
        out.specularColor = vec3Or(specular, "specularColorFactor", glm::vec3(1.0f));
        clampToSpecification(out, emissive, strength);
        out.emission = emissive * strength;
        out.doubleSided = m.doubleSided;
        // glTF: transmission without a volume (no KHR_materials_volume, or thicknessFactor 0)
        // is a thin wall; with a thickness the mesh is the boundary of a refracting solid.
        // thicknessFactor's value only matters to rasterisers (a path tracer has the mesh).
        const tinygltf::Value* volume = findExtension(m.extensions, "KHR_materials_volume");
        out.thinWalled = !(numberOr(volume, "thicknessFactor", 0.0f) > 0.0f);
        if (auto it = options_.thinWalledByMaterial.find(out.name);
            it != options_.thinWalledByMaterial.end()) {
            out.thinWalled = it->second;  // the description, written for this shot, wins
            overriddenMaterials_.insert(out.name);
        } else if (out.thinWalled && out.transmission > 0.0f) {
            thinByDefault_.insert(uint32_t(i));
        }
        if (!out.thinWalled) {
            out.attenuationColor = vec3Or(volume, "attenuationColor", glm::vec3(1.0f));
            out.attenuationDistanceM =
                numberOr(volume, "attenuationDistance", std::numeric_limits<float>::infinity());
            if (!(out.attenuationDistanceM > 0.0f) ||
                glm::any(glm::lessThan(out.attenuationColor, glm::vec3(0.0f))) ||
                glm::any(glm::greaterThan(out.attenuationColor, glm::vec3(1.0f))))
                return fail(
                    "material '{}': KHR_materials_volume needs attenuationDistance > 0 "
                    "and attenuationColor in [0, 1]",
                    out.name);
        }

        // Colour textures hold sRGB-encoded values, data textures linear ones (glTF 2.0 §3.9).
        struct Slot {
            int gltf;
            bool srgb;
            int* target;
        };
        for (Slot slot :
             {Slot{pbr.baseColorTexture.index, true, &out.baseColorTexture},
              Slot{pbr.metallicRoughnessTexture.index, false, &out.metallicRoughnessTexture},
              Slot{m.normalTexture.index, false, &out.normalTexture},
              Slot{m.emissiveTexture.index, true, &out.emissiveTexture}}) {
            Result<int> t = textureFor(slot.gltf, slot.srgb, out.name);
            if (!t) return t.error();
            *slot.target = *t;
        }

        scene_.materials.push_back(std::move(out));
    }
    return {};
}

Result<const unsigned char*> Loader::accessorData(int accessorIndex, const std::string& what,
                                                  size_t elementSize, size_t& stride) const {
    if (accessorIndex < 0 || size_t(accessorIndex) >= model_.accessors.size())
        return fail("{} uses accessor {}, but the file has {} accessors", what, accessorIndex,
                    model_.accessors.size());
    const tinygltf::Accessor& a = model_.accessors[accessorIndex];
    if (a.sparse.isSparse)
        return fail("{} uses sparse accessor {} (sparse accessors are not supported)", what,
                    accessorIndex);
    if (a.bufferView < 0 || size_t(a.bufferView) >= model_.bufferViews.size())
        return fail("{}: accessor {} refers to buffer view {}, but the file has {}", what,
                    accessorIndex, a.bufferView, model_.bufferViews.size());
    const tinygltf::BufferView& view = model_.bufferViews[a.bufferView];
    if (view.buffer < 0 || size_t(view.buffer) >= model_.buffers.size())
        return fail("{}: buffer view {} refers to buffer {}, but the file has {}", what,
                    a.bufferView, view.buffer, model_.buffers.size());
    const tinygltf::Buffer& buffer = model_.buffers[view.buffer];
    // All sizes in 64 bits: a hostile file can make 32-bit products wrap.
    const uint64_t viewEnd = uint64_t(view.byteOffset) + uint64_t(view.byteLength);
    if (viewEnd > buffer.data.size())
        return fail("buffer {} is missing or too short: buffer view {} needs {} bytes, it has {}",
                    view.buffer, a.bufferView, viewEnd, buffer.data.size());
    stride = view.byteStride ? view.byteStride : elementSize;
    if (stride < elementSize)
        return fail("{}: buffer view {} has byteStride {} smaller than the element size {}", what,
                    a.bufferView, stride, elementSize);
    if (a.count > 0) {
        const uint64_t need =
            uint64_t(a.byteOffset) + uint64_t(stride) * (uint64_t(a.count) - 1) + elementSize;
        if (need > view.byteLength)
            return fail(
                "{}: accessor {} is out of range ({} elements need {} bytes, buffer view "
                "{} has {})",
                what, accessorIndex, a.count, need, a.bufferView, view.byteLength);
    }
    return buffer.data.data() + view.byteOffset + a.byteOffset;
}

Status Loader::readFloats(int accessorIndex, int type, bool allowNormalized,
                          const std::string& what, std::vector<float>& out, size_t& count) const {
    if (accessorIndex < 0 || size_t(accessorIndex) >= model_.accessors.size())
        return fail("{} uses accessor {}, but the file has {} accessors", what, accessorIndex,
                    model_.accessors.size());
    const tinygltf::Accessor& a = model_.accessors[accessorIndex];
    if (a.type != type)
        return fail("{}: accessor {} has the wrong type (expected {} components)", what,
                    accessorIndex, tinygltf::GetNumComponentsInType(uint32_t(type)));
    const int components = tinygltf::GetNumComponentsInType(uint32_t(type));
    size_t componentSize = 0;
    switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_FLOAT:
            componentSize = 4;
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            componentSize = 1;
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
            componentSize = 2;
            break;
        default:
            break;
    }
    const bool isFloat = a.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT;
    if (componentSize == 0 || (!isFloat && !(allowNormalized && a.normalized)))
        return fail("{}: accessor {} has unsupported component type {}", what, accessorIndex,
                    a.componentType);
    size_t stride = 0;
    Result<const unsigned char*> data =
        accessorData(accessorIndex, what, componentSize * size_t(components), stride);
    if (!data) return data.error();
    count = a.count;
    out.resize(count * size_t(components));
    for (size_t e = 0; e < count; ++e) {
        const unsigned char* p = *data + e * stride;
        for (int c = 0; c < components; ++c) {
            float v = 0.0f;
            if (componentSize == 4) {
                std::memcpy(&v, p + 4 * c, 4);
            } else if (componentSize == 1) {
                v = p[c] / 255.0f;
            } else {
                uint16_t s;
                std::memcpy(&s, p + 2 * c, 2);
                v = s / 65535.0f;
            }
            out[e * components + c] = v;
        }
    }
    return {};
}

Status Loader::readIndices(int accessorIndex, const std::string& what,
                           std::vector<uint32_t>& out) const {
    if (accessorIndex < 0 || size_t(accessorIndex) >= model_.accessors.size())
        return fail("{} uses index accessor {}, but the file has {} accessors", what, accessorIndex,
                    model_.accessors.size());
    const tinygltf::Accessor& a = model_.accessors[accessorIndex];
    size_t size = 0;
    switch (a.componentType) {
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
            size = 1;
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
            size = 2;
            break;
        case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
            size = 4;
            break;
        default:
            return fail("{}: index accessor {} has component type {} (need an unsigned integer)",
                        what, accessorIndex, a.componentType);
    }
    if (a.type != TINYGLTF_TYPE_SCALAR)
        return fail("{}: index accessor {} is not SCALAR", what, accessorIndex);
    size_t stride = 0;
    Result<const unsigned char*> data = accessorData(accessorIndex, what, size, stride);
    if (!data) return data.error();
    out.resize(a.count);
    for (size_t e = 0; e < a.count; ++e) {
        const unsigned char* p = *data + e * stride;
        if (size == 1) {
            out[e] = p[0];
        } else if (size == 2) {
            uint16_t v;
            std::memcpy(&v, p, 2);
            out[e] = v;
        } else {
            std::memcpy(&out[e], p, 4);
        }
    }
    return {};
}

// In double, as the file stores it: a translation of 1000 km keeps its millimetres.
glm::dmat4 localTransform(const tinygltf::Node& node) {
    if (node.matrix.size() == 16) {
        glm::dmat4 m;
        for (int i = 0; i < 16; ++i) glm::value_ptr(m)[i] = node.matrix[i];  // column-major
        return m;
    }
    glm::dmat4 t(1.0);
    if (node.translation.size() == 3)
        t = glm::translate(glm::dmat4(1.0), glm::dvec3(node.translation[0], node.translation[1],
                                                       node.translation[2]));
    glm::dmat4 r(1.0);
    if (node.rotation.size() == 4) {
        // glTF stores (x, y, z, w); glm::dquat's constructor takes w first.
        glm::dquat q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
        r = glm::mat4_cast(glm::normalize(q));
    }
    glm::dmat4 s(1.0);
    if (node.scale.size() == 3)
        s = glm::scale(glm::dmat4(1.0), glm::dvec3(node.scale[0], node.scale[1], node.scale[2]));
    return t * r * s;
}

// Scene::originM is a multiple of this (metres): a scene within about half of it from the world
// origin keeps origin 0 (positions are world positions, as before), and float positions
// relative to the origin stay within ~500 m plus the set's size (float spacing ~30 µm there).
constexpr double kOriginGridM = 1024.0;

bool finiteMatrix(const glm::dmat4& m) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
            if (!std::isfinite(m[c][r])) return false;
    return true;
}

Result<std::optional<bool>> Loader::roleByName(const tinygltf::Node& node, int nodeIndex) {
    std::optional<bool> role;
    size_t first = 0;
    for (size_t i = 0; i < options_.roleRules.size(); ++i) {
        const auto& [pattern, real] = options_.roleRules[i];
        if (::fnmatch(pattern.c_str(), node.name.c_str(), 0) != 0) continue;
        ruleMatched_[i] = 1;
        if (role && *role != real) {
            const auto& other = options_.roleRules[first];
            return fail(
                "node {} ('{}') matches both the {} role pattern '{}' and the {} role "
                "pattern '{}'{}; make the patterns exclusive",
                nodeIndex, node.name, other.second ? "real" : "virtual", other.first,
                real ? "real" : "virtual", pattern, originSuffix());
        }
        if (!role) first = i;
        role = real;
    }
    return role;
}

glm::dvec3 Loader::chooseOrigin(const std::vector<int>& roots) const {
    // The centre of the box around the origins of the nodes that place something (their world
    // translations), snapped to kOriginGridM. Malformed hierarchies are left to visitNode.
    glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi = -lo;
    std::vector<std::pair<int, glm::dmat4>> stack;
    for (int root : roots) stack.emplace_back(root, glm::dmat4(1.0));
    size_t visited = 0;
    while (!stack.empty() && visited++ < 16 * model_.nodes.size() + 16) {
        auto [index, parent] = stack.back();
        stack.pop_back();
        if (index < 0 || size_t(index) >= model_.nodes.size()) continue;
        const tinygltf::Node& node = model_.nodes[index];
        const glm::dmat4 world = parent * localTransform(node);
        if (!finiteMatrix(world)) continue;
        if (node.mesh >= 0 || node.camera >= 0 || !node.extensions.empty()) {
            lo = glm::min(lo, glm::dvec3(world[3]));
            hi = glm::max(hi, glm::dvec3(world[3]));
        }
        for (int child : node.children) stack.emplace_back(child, world);
    }
    if (!(lo.x <= hi.x)) return glm::dvec3(0.0);
    return glm::round(0.5 * (lo + hi) / kOriginGridM) * kOriginGridM;
}

Status Loader::visitNode(int nodeIndex, const glm::dmat4& parentWorld, bool parentReal, int depth) {
    if (nodeIndex < 0 || size_t(nodeIndex) >= model_.nodes.size())
        return fail("node index {} is out of range (the file has {} nodes)", nodeIndex,
                    model_.nodes.size());
    if (depth > kMaxNodeDepth)
        return fail("the node hierarchy is deeper than {} at node {} (a cycle?)", kMaxNodeDepth,
                    nodeIndex);
    const tinygltf::Node& node = model_.nodes[nodeIndex];
    const glm::dmat4 world = parentWorld * localTransform(node);
    if (!finiteMatrix(world))
        return fail("node {} ('{}') has a non-finite transform", nodeIndex, node.name);

    // DESIGN.md §4: extras.previs.role; children inherit unless they say otherwise.
    bool real = parentReal;
    if (const tinygltf::Value* role = findPath(node.extras, {"previs", "role"});
        role && role->IsString()) {
        const std::string& r = role->Get<std::string>();
        if (r == "real")
            real = true;
        else if (r == "virtual")
            real = false;
        else
            logWarning(
                "glTF '{}': node '{}' has unknown role '{}' (use \"real\" or "
                "\"virtual\"); it inherits its parent's",
                path_, node.name, r);
    }
    // Name rules come from the scene description, written for this shot by the person who
    // knows the set; they win over whatever the modelling tool exported.
    Result<std::optional<bool>> byName = roleByName(node, nodeIndex);
    if (!byName) return byName.error();
    if (byName->has_value()) real = **byName;

    if (node.mesh >= 0) {
        if (Status s = loadMesh(node.mesh, world, real); !s) return s;
    }
    if (node.camera >= 0) {
        if (Status s = loadCamera(node, world); !s) return s;
    }
    if (findExtension(node.extensions, "KHR_lights_punctual")) {
        if (Status s = loadLight(node, world, real); !s) return s;
    }
    for (int child : node.children) {
        if (Status s = visitNode(child, world, real, depth + 1); !s) return s;
    }
    return {};
}

Status Loader::loadMesh(int meshIndex, const glm::dmat4& worldFromMesh, bool real) {
    if (size_t(meshIndex) >= model_.meshes.size())
        return fail("mesh index {} is out of range (the file has {} meshes)", meshIndex,
                    model_.meshes.size());
    const tinygltf::Mesh& mesh = model_.meshes[meshIndex];
    for (size_t p = 0; p < mesh.primitives.size(); ++p) {
        if (Status s = loadPrimitive(mesh, meshIndex, p, worldFromMesh, real); !s) return s;
    }
    return {};
}

// |cross| in double: exact zero for collinear or coincident authored data; the relative
// threshold also catches float-rounded collinear points whose normal would be noise. Slivers
// (any aspect ratio above ~1e-7) are kept: they are legitimate geometry.
bool isDegenerate(const glm::vec3& a, const glm::vec3& b, const glm::vec3& c) {
    const glm::dvec3 e1 = glm::dvec3(b) - glm::dvec3(a);
    const glm::dvec3 e2 = glm::dvec3(c) - glm::dvec3(a);
    const glm::dvec3 e3 = glm::dvec3(c) - glm::dvec3(b);
    const double maxEdge2 = std::max({glm::dot(e1, e1), glm::dot(e2, e2), glm::dot(e3, e3)});
    const double area2 = glm::length(glm::cross(e1, e2));
    return !(area2 > 1e-14 * maxEdge2) || maxEdge2 == 0.0;
}

// Twice the area times the unit normal, in double (counter-clockwise winding).
glm::dvec3 areaNormal(const std::vector<glm::vec3>& world, const glm::uvec3& tri) {
    return glm::cross(glm::dvec3(world[tri.y]) - glm::dvec3(world[tri.x]),
                      glm::dvec3(world[tri.z]) - glm::dvec3(world[tri.x]));
}

Status Loader::readVertexAttribute(const tinygltf::Primitive& prim,
                                   const VertexAttribute& attribute, const std::string& what,
                                   size_t vertexCount, std::vector<float>& out) const {
    // A negative accessor index is glTF's "absent" as tinygltf parses it: flat or untextured.
    auto it = prim.attributes.find(attribute.name);
    if (it == prim.attributes.end() || it->second < 0) return {};
    size_t n = 0;
    if (Status s = readFloats(it->second, attribute.type, attribute.allowNormalized,
                              what + " " + attribute.name, out, n);
        !s)
        return s;
    if (n != vertexCount)
        return fail("{} has {} {} for {} positions", what, n, attribute.noun, vertexCount);
    return {};
}

Result<Loader::PrimitiveVertices> Loader::readVertices(const tinygltf::Mesh& mesh, int meshIndex,
                                                       const tinygltf::Primitive& prim,
                                                       const std::string& what) const {
    auto position = prim.attributes.find("POSITION");
    if (position == prim.attributes.end() || position->second < 0)
        return fail("{} has no POSITION attribute", what);
    PrimitiveVertices vertices;
    if (Status s = readFloats(position->second, TINYGLTF_TYPE_VEC3, false, what + " POSITION",
                              vertices.positions, vertices.count);
        !s)
        return s.error();
    for (float v : vertices.positions)
        if (!std::isfinite(v))
            return fail(
                "mesh '{}' (mesh {}) has NaN or infinite vertex positions; fix the "
                "mesh in the modelling tool",
                mesh.name, meshIndex);
    const VertexAttribute normal{"NORMAL", TINYGLTF_TYPE_VEC3, false, "normals"};
    if (Status s = readVertexAttribute(prim, normal, what, vertices.count, vertices.normals); !s)
        return s.error();
    // Texture coordinates may be stored as normalized unsigned integers (glTF §3.7.2.1).
    const VertexAttribute uv{"TEXCOORD_0", TINYGLTF_TYPE_VEC2, true, "texture coordinates"};
    if (Status s = readVertexAttribute(prim, uv, what, vertices.count, vertices.uvs); !s)
        return s.error();
    return vertices;
}

Result<std::vector<uint32_t>> Loader::readTriangleIndices(const tinygltf::Primitive& prim,
                                                          const std::string& what,
                                                          size_t vertexCount) const {
    std::vector<uint32_t> indices;
    if (prim.indices >= 0) {
        if (Status s = readIndices(prim.indices, what, indices); !s) return s.error();
        for (uint32_t i : indices)
            if (i >= vertexCount)
                return fail("{} has index {} out of range (it has {} vertices)", what, i,
                            vertexCount);
    } else {
        indices.resize(vertexCount);
        for (size_t i = 0; i < vertexCount; ++i) indices[i] = uint32_t(i);
    }
    if (indices.size() % 3 != 0)
        logWarning("glTF '{}': {} has {} indices, not a multiple of 3; the last {} are ignored",
                   path_, what, indices.size(), indices.size() % 3);
    return indices;
}

Result<uint32_t> Loader::primitiveMaterial(const tinygltf::Primitive& prim,
                                           const std::string& what) {
    if (prim.material >= 0) {
        if (size_t(prim.material) >= scene_.materials.size())
            return fail("{} uses material {}, but the file has {} materials", what, prim.material,
                        scene_.materials.size());
        return uint32_t(prim.material);
    }
    if (defaultMaterial_ < 0) {
        defaultMaterial_ = int(scene_.materials.size());
        Material m;
        m.name = "default";
        scene_.materials.push_back(m);
    }
    return uint32_t(defaultMaterial_);
}

std::vector<glm::uvec3> Loader::keepTriangles(const std::vector<uint32_t>& indices,
                                              const PrimitiveVertices& vertices,
                                              const std::vector<glm::vec3>& world, bool mirrored) {
    std::vector<glm::uvec3> tris;
    tris.reserve(indices.size() / 3);
    for (size_t t = 0; t + 2 < indices.size(); t += 3) {
        glm::uvec3 tri(indices[t], indices[t + 1], indices[t + 2]);
        if (tri.x == tri.y || tri.y == tri.z || tri.x == tri.z ||
            isDegenerate(vertices.position(tri.x), vertices.position(tri.y),
                         vertices.position(tri.z)) ||
            isDegenerate(world[tri.x], world[tri.y], world[tri.z])) {
            ++degenerateTriangles_;
            continue;
        }
        // A mirroring transform flips the winding; swap two indices so the geometric normal
        // (counter-clockwise, glTF §3.7.2.1) still points to the front face.
        if (mirrored) std::swap(tri.y, tri.z);
        tris.push_back(tri);
    }
    return tris;
}

// No normals: one vertex per corner so each triangle carries its own flat normal.
void Loader::appendFlatTriangles(const PrimitiveTriangles& prim) {
    Geometry& g = scene_.geometry;
    for (const glm::uvec3& tri : prim.triangles) {
        const glm::vec3 n = glm::vec3(glm::normalize(areaNormal(prim.world, tri)));
        const uint32_t first = uint32_t(g.positions.size());
        for (uint32_t k = 0; k < 3; ++k) {
            g.positions.push_back(prim.world[tri[k]]);
            g.normals.push_back(n);
            g.uvs.push_back(prim.vertices.uv(tri[k]));
        }
        g.triangles.emplace_back(first, first + 1, first + 2);
        g.triangleMaterials.push_back(prim.material);
        g.triangleIsReal.push_back(prim.real ? 1 : 0);
    }
}

std::vector<glm::vec3> Loader::worldNormals(const PrimitiveTriangles& prim,
                                            const glm::mat3& normalMatrix) {
    const std::vector<float>& normals = prim.vertices.normals;
    const size_t vertexCount = prim.vertices.count;
    std::vector<glm::vec3> worldNormals(vertexCount);
    std::vector<uint8_t> bad(vertexCount, 0);
    for (size_t i = 0; i < vertexCount; ++i) {
        const glm::vec3 n =
            normalMatrix * glm::vec3(normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]);
        const float len = glm::length(n);
        if (std::isfinite(len) && len > 0.0f && std::isfinite(n.x + n.y + n.z)) {
            worldNormals[i] = n / len;
        } else {
            bad[i] = 1;
            worldNormals[i] = glm::vec3(0.0f);
        }
    }
    // Unusable normals (NaN, Inf, zero) become the area-weighted geometric normal of the
    // triangles around the vertex.
    for (const glm::uvec3& tri : prim.triangles) {
        const glm::dvec3 n = areaNormal(prim.world, tri);
        for (int k = 0; k < 3; ++k)
            if (bad[tri[k]]) worldNormals[tri[k]] += glm::vec3(n);
    }
    for (size_t i = 0; i < vertexCount; ++i) {
        if (!bad[i]) continue;
        ++replacedNormals_;
        const float len = glm::length(worldNormals[i]);
        worldNormals[i] =
            std::isfinite(len) && len > 0.0f ? worldNormals[i] / len : glm::vec3(0.0f, 1.0f, 0.0f);
    }
    return worldNormals;
}

void Loader::appendSmoothTriangles(const PrimitiveTriangles& prim,
                                   const std::vector<glm::vec3>& normals) {
    Geometry& g = scene_.geometry;
    const uint32_t base = uint32_t(g.positions.size());
    for (size_t i = 0; i < prim.vertices.count; ++i) {
        g.positions.push_back(prim.world[i]);
        g.normals.push_back(normals[i]);
        g.uvs.push_back(prim.vertices.uv(uint32_t(i)));
    }
    for (const glm::uvec3& tri : prim.triangles) {
        g.triangles.push_back(tri + glm::uvec3(base));
        g.triangleMaterials.push_back(prim.material);
        g.triangleIsReal.push_back(prim.real ? 1 : 0);
    }
}

Status Loader::loadPrimitive(const tinygltf::Mesh& mesh, int meshIndex, size_t primIndex,
                             const glm::dmat4& worldFromMesh, bool real) {
    const tinygltf::Primitive& prim = mesh.primitives[primIndex];
    const std::string what =
        fmt::format("mesh {} ('{}') primitive {}", meshIndex, mesh.name, primIndex);
    if (prim.mode != TINYGLTF_MODE_TRIANGLES) {
        // Points and lines have no area to render; strips/fans are rare in exported files.
        logWarning("glTF '{}': {} has mode {} (only TRIANGLES is rendered); skipped", path_, what,
                   prim.mode);
        ++skippedPrimitives_;
        return {};
    }
    Result<PrimitiveVertices> vertices = readVertices(mesh, meshIndex, prim, what);
    if (!vertices) return vertices.error();
    Result<std::vector<uint32_t>> indices = readTriangleIndices(prim, what, vertices->count);
    if (!indices) return indices.error();
    Result<uint32_t> material = primitiveMaterial(prim, what);
    if (!material) return material.error();

    checkThinGlassOnClosedMesh(*material, meshIndex);
    shiftTextureCoordinates(vertices->uvs, scene_.materials[*material]);

    const glm::mat3 linear{glm::dmat3(worldFromMesh)};
    std::vector<glm::vec3> world(vertices->count);
    for (size_t i = 0; i < vertices->count; ++i)
        world[i] = glm::vec3(worldFromMesh * glm::dvec4(vertices->position(uint32_t(i)), 1.0));
    const bool mirrored = glm::determinant(linear) < 0.0f;
    PrimitiveTriangles triangles{
        *vertices, world, keepTriangles(*indices, *vertices, world, mirrored), *material, real};
    if (vertices->normals.empty()) {
        appendFlatTriangles(triangles);
        return {};
    }
    const glm::mat3 normalMatrix = glm::transpose(glm::inverse(linear));
    appendSmoothTriangles(triangles, worldNormals(triangles, normalMatrix));
    return {};
}

// Closed: every edge of its triangles, vertices welded by position (exporters split them along
// UV seams and sharp edges), is shared by an even number of them, so the mesh bounds a volume.
bool Loader::meshIsClosed(int meshIndex) {
    if (auto it = closedMeshes_.find(meshIndex); it != closedMeshes_.end()) return it->second;
    std::map<std::array<float, 3>, uint32_t> welded;
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> edgeUses;
    for (const tinygltf::Primitive& prim : model_.meshes[meshIndex].primitives) {
        auto position = prim.attributes.find("POSITION");
        if (prim.mode != TINYGLTF_MODE_TRIANGLES || position == prim.attributes.end()) continue;
        std::vector<float> positions;
        std::vector<uint32_t> indices;
        size_t count = 0;
        // A primitive that does not read is the primitive loader's error to report.
        if (!readFloats(position->second, TINYGLTF_TYPE_VEC3, false, "", positions, count) ||
            !std::all_of(positions.begin(), positions.end(),
                         [](float v) { return std::isfinite(v); }))
            return closedMeshes_[meshIndex] = false;
        if (prim.indices >= 0) {
            if (!readIndices(prim.indices, "", indices)) return closedMeshes_[meshIndex] = false;
        } else {
            for (size_t i = 0; i < count; ++i) indices.push_back(uint32_t(i));
        }
        std::vector<uint32_t> id(count);
        for (size_t v = 0; v < count; ++v)
            id[v] = welded
                        .emplace(std::array<float, 3>{positions[3 * v], positions[3 * v + 1],
                                                      positions[3 * v + 2]},
                                 uint32_t(welded.size()))
                        .first->second;
        for (size_t t = 0; t + 2 < indices.size(); t += 3) {
            for (int k = 0; k < 3; ++k) {
                const uint32_t a = indices[t + k], b = indices[t + (k + 1) % 3];
                if (a >= count || b >= count) return closedMeshes_[meshIndex] = false;
                if (id[a] != id[b]) ++edgeUses[std::minmax(id[a], id[b])];
            }
        }
    }
    bool closed = !edgeUses.empty();
    for (const auto& [edge, uses] : edgeUses) closed = closed && uses % 2 == 0;
    return closedMeshes_[meshIndex] = closed;
}

void Loader::checkThinGlassOnClosedMesh(uint32_t material, int meshIndex) {
    if (!thinByDefault_.count(material) || !meshIsClosed(meshIndex)) return;
    thinByDefault_.erase(material);  // once per material
    const std::string& name = scene_.materials[material].name;
    logWarning(
        "glTF '{}': material '{}' is transmissive without KHR_materials_volume, a thin wall by "
        "glTF's rule (light passes unbent), but it is on the closed mesh '{}', which is most "
        "often meant as solid glass (Blender's exporter writes its glass so unless the material "
        "has a thickness); if it is solid, give the material a thickness in Blender (glTF "
        "Material Output > Thickness) and export again, or write `thin_walled = false` under "
        "[materials.\"{}\"] in the scene's previs.toml; `thin_walled = true` keeps the thin wall "
        "and this warning quiet",
        path_, name, model_.meshes[meshIndex].name, name);
}

// Far from the origin a float texture coordinate keeps few fraction bits (at 1e7 none), and the
// interpolation at a hit point rounds to them. Shifting a primitive's coordinates by an even
// integer — a whole period of both REPEAT (1) and MIRRORED_REPEAT (2) — changes no texel a
// sampler reads and brings them near 0, where the interpolation keeps its precision. An axis that
// a CLAMP_TO_EDGE texture of the material reads is left as it is (there the shift would matter).
void Loader::shiftTextureCoordinates(std::vector<float>& uvs, const Material& material) const {
    if (uvs.empty()) return;
    bool clampS = false;
    bool clampT = false;
    for (int t : {material.baseColorTexture, material.metallicRoughnessTexture,
                  material.normalTexture, material.emissiveTexture}) {
        if (t < 0) continue;
        clampS |= scene_.textures[t].wrapS == TextureWrap::ClampToEdge;
        clampT |= scene_.textures[t].wrapT == TextureWrap::ClampToEdge;
    }
    for (int axis = 0; axis < 2; ++axis) {
        if (axis == 0 ? clampS : clampT) continue;
        double lowest = std::numeric_limits<double>::infinity();
        for (size_t i = axis; i < uvs.size(); i += 2)
            if (std::isfinite(uvs[i])) lowest = std::min(lowest, double(uvs[i]));
        if (!std::isfinite(lowest)) continue;
        const double shift = 2.0 * std::floor(0.5 * lowest);
        if (shift == 0.0) continue;
        for (size_t i = axis; i < uvs.size(); i += 2) uvs[i] = float(double(uvs[i]) - shift);
    }
}

Status Loader::loadCamera(const tinygltf::Node& node, const glm::dmat4& worldD) {
    const glm::mat4 world(worldD);  // relative to Scene::originM: small
    if (size_t(node.camera) >= model_.cameras.size())
        return fail("node '{}' refers to camera {}, but the file has {} cameras", node.name,
                    node.camera, model_.cameras.size());
    const tinygltf::Camera& c = model_.cameras[node.camera];
    if (c.type != "perspective") {
        logWarning("glTF '{}': camera '{}' is {}, only perspective cameras are supported; skipped",
                   path_, c.name, c.type);
        return {};
    }
    Camera camera;
    camera.name = !c.name.empty() ? c.name : node.name;
    camera.fovYRad = float(c.perspective.yfov);
    camera.aspectRatio = float(c.perspective.aspectRatio);
    if (!(camera.fovYRad > 0.0f && camera.fovYRad < 3.14159f))
        return fail("camera '{}' has yfov {} rad (need 0 < yfov < π)", camera.name, camera.fovYRad);
    // Cameras ignore scale (glTF §3.10.4 "camera ... transform ... shall not contain scale"
    // in spirit): rays need an orthonormal frame, so the columns are normalised.
    camera.worldFromCamera = world;
    for (int k = 0; k < 3; ++k) {
        const glm::vec3 axis(world[k]);
        const float len = glm::length(axis);
        if (!(len > 0.0f)) return fail("camera node '{}' has a degenerate transform", node.name);
        camera.worldFromCamera[k] = glm::vec4(axis / len, 0.0f);
    }
    const tinygltf::Value* previs = findPath(node.extras, {"previs"});
    camera.apertureRadiusM = numberOr(previs, "apertureRadiusM", 0.0f);
    camera.focusDistanceM = numberOr(previs, "focusDistanceM", 1.0f);
    if (!(camera.apertureRadiusM >= 0.0f) || !(camera.focusDistanceM > 0.0f) ||
        !std::isfinite(camera.apertureRadiusM) || !std::isfinite(camera.focusDistanceM))
        return fail(
            "camera node '{}' has invalid extras.previs apertureRadiusM {} / "
            "focusDistanceM {} (need >= 0 and > 0)",
            node.name, camera.apertureRadiusM, camera.focusDistanceM);
    scene_.cameras.push_back(camera);
    return {};
}

Status Loader::loadLight(const tinygltf::Node& node, const glm::dmat4& worldD, bool real) {
    const glm::mat4 world(worldD);  // relative to Scene::originM: small
    const tinygltf::Value* ext = findExtension(node.extensions, "KHR_lights_punctual");
    const tinygltf::Value* index = ext ? findPath(*ext, {"light"}) : nullptr;
    if (!index || !index->IsNumber())
        return fail("node '{}' has KHR_lights_punctual without a light index", node.name);
    const int i = index->GetNumberAsInt();
    if (i < 0 || size_t(i) >= model_.lights.size())
        return fail("node '{}' refers to light {}, but the file has {} lights", node.name, i,
                    model_.lights.size());
    const tinygltf::Light& l = model_.lights[i];
    PunctualLight light;
    light.name = !l.name.empty() ? l.name : node.name;
    if (l.type == "point")
        light.type = LightType::Point;
    else if (l.type == "spot")
        light.type = LightType::Spot;
    else if (l.type == "directional")
        light.type = LightType::Directional;
    else
        return fail("light '{}' has unknown type '{}'", light.name, l.type);
    light.position = glm::vec3(world[3]);
    const glm::vec3 dir = -glm::vec3(world[2]);
    const float len = glm::length(dir);
    if (!(len > 0.0f) && light.type != LightType::Point)
        return fail("light node '{}' has a degenerate transform", node.name);
    light.direction = len > 0.0f ? dir / len : glm::vec3(0.0f, 0.0f, -1.0f);
    if (l.color.size() == 3) light.color = glm::vec3(l.color[0], l.color[1], l.color[2]);
    // Photometric (cd, lx) to radiometric (W/sr, W/m²), as Blender's importer reads them.
    light.intensity = float(l.intensity / kLumensPerWatt);
    light.range = float(l.range);
    light.innerConeAngleRad = float(l.spot.innerConeAngle);
    light.outerConeAngleRad = float(l.spot.outerConeAngle);
    if (!std::isfinite(light.intensity) || light.intensity < 0.0f ||
        !std::isfinite(light.color.r + light.color.g + light.color.b))
        return fail("light '{}' has an invalid colour or intensity", light.name);
    light.isReal = real;
    scene_.lights.push_back(light);
    return {};
}

Result<Scene> Loader::run() {
    scene_.path = path_;
    // glTF 2.0 §5.2: asset.version is required; "2.0" (or a later 2.x) is what this reads.
    if (model_.asset.version.rfind("2.", 0) != 0)
        return fail(
            "asset.version is '{}', but previs reads glTF 2.0 files (version \"2.0\"); "
            "is it a glTF 1.0 file or not a glTF file at all?",
            model_.asset.version);
    if (Status s = checkExtensions(); !s) return s.error();
    if (Status s = loadMaterials(); !s) return s.error();

    std::vector<int> roots;
    if (!model_.scenes.empty()) {
        int sceneIndex = model_.defaultScene >= 0 ? model_.defaultScene : 0;
        if (size_t(sceneIndex) >= model_.scenes.size())
            return fail("default scene {} is out of range (the file has {} scenes)", sceneIndex,
                        model_.scenes.size());
        roots = model_.scenes[sceneIndex].nodes;
    } else {
        // No scenes: every node that is nobody's child is a root (glTF allows this for
        // libraries of assets; showing them beats showing nothing).
        std::vector<uint8_t> isChild(model_.nodes.size(), 0);
        for (const tinygltf::Node& n : model_.nodes)
            for (int c : n.children)
                if (c >= 0 && size_t(c) < isChild.size()) isChild[c] = 1;
        for (size_t i = 0; i < model_.nodes.size(); ++i)
            if (!isChild[i]) roots.push_back(int(i));
    }
    scene_.originM = chooseOrigin(roots);
    const glm::dmat4 sceneFromWorld = glm::translate(glm::dmat4(1.0), -scene_.originM);
    for (int root : roots) {
        if (Status s = visitNode(root, sceneFromWorld, false, 0); !s) return s.error();
    }
    for (size_t i = 0; i < ruleMatched_.size(); ++i) {
        if (!ruleMatched_[i])
            logWarning(
                "glTF '{}': the {} role pattern '{}'{} matches no node name; check its "
                "spelling (names are case-sensitive)",
                path_, options_.roleRules[i].second ? "real" : "virtual",
                options_.roleRules[i].first, originSuffix());
    }
    for (const auto& override : options_.thinWalledByMaterial) {
        const std::string& name = override.first;
        if (overriddenMaterials_.count(name)) continue;
        std::string names;
        for (const Material& m : scene_.materials)
            names += fmt::format("{}'{}'", names.empty() ? "" : ", ", m.name);
        logWarning(
            "glTF '{}': thin_walled is set for the material '{}'{}, but the file has no material "
            "of that name ({}); check its spelling (names are case-sensitive)",
            path_, name,
            options_.materialsOrigin.empty() ? std::string() : " in " + options_.materialsOrigin,
            names.empty() ? std::string("it has none") : "materials: " + names);
    }
    if (degenerateTriangles_ > 0)
        logWarning("glTF '{}': dropped {} degenerate triangles (zero area or repeated index)",
                   path_, degenerateTriangles_);
    if (replacedNormals_ > 0)
        logWarning(
            "glTF '{}': {} vertex normals were NaN, infinite or zero; replaced by the "
            "geometric normal",
            path_, replacedNormals_);
    return std::move(scene_);
}

}  // namespace

Result<Scene> loadGltf(const std::string& path, const GltfLoadOptions& options) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec))
        return makeError("cannot load glTF '{}': no such file (check the path)", path);
    if (std::filesystem::is_directory(path, ec))
        return makeError("cannot load glTF '{}': it is a folder, not a .gltf/.glb file", path);
    const std::string ext = lowerExtension(path);
    if (ext != ".gltf" && ext != ".glb")
        return makeError("cannot load glTF '{}': unsupported extension '{}' (use .gltf or .glb)",
                         path, ext);

    // URIs resolve against the glTF's own folder (SceneFiles), never the working folder.
    std::filesystem::path folder =
        std::filesystem::weakly_canonical(std::filesystem::absolute(path, ec).parent_path(), ec);
    if (ec) return makeError("cannot load glTF '{}': {}", path, ec.message());
    SceneFiles files(std::move(folder), options.maxDataBytes);
    uint64_t fileBytes = 0;
    Result<std::vector<unsigned char>> text = readRegularFile(
        path, true, std::min(kMaxExternalFileBytes - 1, options.maxDataBytes), &fileBytes);
    if (!text) return makeError("cannot load glTF '{}': {}", path, text.message());
    files.take(fileBytes, "the file itself");
    if (text->empty()) return makeError("cannot load glTF '{}': the file is empty", path);

    tinygltf::TinyGLTF gltf;
    gltf.SetImageLoader(&decodeImage, &files);
    gltf.SetFsCallbacks(tinygltf::FsCallbacks{&externalFileExists, &expandNothing,
                                              &readExternalFile, nullptr, &files});
    tinygltf::Model model;
    std::string err;
    std::string warn;
    bool ok = false;
    try {
        // No base folder: tinygltf hands the callbacks each URI as it is.
        ok = ext == ".glb" ? gltf.LoadBinaryFromMemory(&model, &err, &warn, text->data(),
                                                       unsigned(text->size()), "")
                           : gltf.LoadASCIIFromString(&model, &err, &warn,
                                                      reinterpret_cast<const char*>(text->data()),
                                                      unsigned(text->size()), "");
    } catch (const std::exception& e) {
        return makeError("cannot load glTF '{}': {}", path, e.what());
    }
    if (!files.refusal().empty())
        return makeError("cannot load glTF '{}': {}", path, files.refusal());
    if (!ok) {
        std::string reason = err.empty() ? std::string("malformed file") : oneLine(err);
        if (reason.find("json.exception") != std::string::npos)
            reason = "malformed JSON: " + reason;
        else if (ext == ".glb" && reason.find("magic") != std::string::npos)
            reason = "not a binary glTF file (" + reason + ")";
        return makeError("cannot load glTF '{}': {}", path, reason);
    }
    if (!warn.empty()) logDebug("glTF '{}': tinygltf: {}", path, oneLine(warn));

    Loader loader(path, std::move(model), std::move(files.imageFailures), options);
    return loader.run();
}

}  // namespace previs
