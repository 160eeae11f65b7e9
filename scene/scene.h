#pragma once

// The scene on the CPU, as loaded from glTF (and later the previs.toml scene description):
// world-space triangles with their materials, textures, punctual lights, cameras and an optional
// environment map. Everything here is in glTF conventions (DESIGN.md §4): right-handed, +Y up,
// metres; cameras look along -Z of their node.

#include <cstdint>
#include <glm/glm.hpp>
#include <limits>
#include <optional>
#include <string>
#include <vector>

namespace previs {

struct Material {
    std::string name;
    glm::vec4 baseColor{1.0f};  // linear
    glm::vec3 emission{0.0f};   // emissiveFactor * emissive_strength
    float metallic = 1.0f;      // glTF defaults
    float roughness = 1.0f;
    float transmission = 0.0f;
    float ior = 1.5f;
    float specular = 1.0f;
    glm::vec3 specularColor{1.0f};
    // KHR_materials_volume. Transmission through a thin wall (no volume: glTF's default) or
    // into a solid whose inside absorbs by Beer–Lambert, attenuationColor being the colour
    // white light has after attenuationDistance metres inside (infinite: clear).
    bool thinWalled = false;
    glm::vec3 attenuationColor{1.0f};
    float attenuationDistanceM = std::numeric_limits<float>::infinity();
    int baseColorTexture = -1;  // index into Scene::textures, -1 = none
    int metallicRoughnessTexture = -1;
    int normalTexture = -1;
    int emissiveTexture = -1;
    bool doubleSided = false;
};

// How texture coordinates outside [0, 1] map to texels: glTF's sampler wrapS/wrapT.
enum class TextureWrap { Repeat, MirroredRepeat, ClampToEdge };

// 8-bit RGBA texels, row 0 at the top (glTF UV origin), with the glTF sampler's wrap modes and
// filter (no mipmaps: a minification filter only chooses nearest or linear).
struct Texture {
    std::string name;
    uint32_t width = 0;
    uint32_t height = 0;
    bool srgb = true;                         // colour data; false for linear data
    TextureWrap wrapS = TextureWrap::Repeat;  // glTF's default sampler
    TextureWrap wrapT = TextureWrap::Repeat;
    bool nearest = false;         // true: nearest texel; false: bilinear
    std::vector<uint32_t> rgba8;  // packed R | G<<8 | B<<16 | A<<24
};

// Triangles of all meshes, transformed to world space. Vertex attributes are per vertex;
// triangles index them. normals/uvs are always filled (geometric normal / zero when absent).
struct Geometry {
    std::vector<glm::vec3> positions;
    std::vector<glm::vec3> normals;
    std::vector<glm::vec2> uvs;
    std::vector<glm::uvec3> triangles;
    std::vector<uint32_t> triangleMaterials;
    std::vector<uint8_t> triangleIsReal;  // 1: phantom of a real object; 0: virtual
};

// The real (phantom) triangles of `geometry` alone, its vertices kept as they are: what a plate
// shows of the set, and what the lighting fit casts against.
inline Geometry realGeometry(const Geometry& geometry) {
    Geometry real;
    real.positions = geometry.positions;
    real.normals = geometry.normals;
    real.uvs = geometry.uvs;
    for (size_t t = 0; t < geometry.triangles.size(); ++t)
        if (geometry.triangleIsReal[t]) {
            real.triangles.push_back(geometry.triangles[t]);
            real.triangleMaterials.push_back(geometry.triangleMaterials[t]);
            real.triangleIsReal.push_back(1);
        }
    return real;
}

enum class LightType { Point, Spot, Directional };

struct PunctualLight {
    std::string name;
    LightType type = LightType::Point;
    glm::vec3 position{0.0f};
    glm::vec3 direction{0.0f, 0.0f, -1.0f};  // where it points (unit)
    glm::vec3 color{1.0f};
    // Radiometric: W/sr (point/spot) or W/m² (directional). glTF files give candela or lux;
    // loadGltf divides by 683 lm/W as Blender's glTF importer does (docs/scene-format.md).
    float intensity = 1.0f;
    float innerConeAngleRad = 0.0f;
    float outerConeAngleRad = 0.7853981633974483f;
    float range = 0.0f;  // 0 = infinite
    // A light of the real set (its node's role is real): it lights both solutions of
    // differential rendering. Otherwise a virtual (artistic) light: the mixed solution only.
    bool isReal = false;
};

struct Camera {
    std::string name;
    glm::mat4 worldFromCamera{1.0f};
    float fovYRad = 0.8f;
    float aspectRatio = 0.0f;  // 0 = from the image size
    float apertureRadiusM = 0.0f;
    float focusDistanceM = 1.0f;
};

// Equirectangular linear HDR map (DESIGN.md §4 orientation), row 0 at the top.
struct EnvironmentMap {
    std::string path;
    uint32_t width = 0;
    uint32_t height = 0;
    std::vector<glm::vec3> radiance;
    float rotationRad = 0.0f;
    float scale = 1.0f;
};

struct Scene {
    std::string path;
    // Where this scene's frame sits in the world (metres, double): every position below
    // (geometry, lights, cameras) is relative to it, world = originM + p, so that float keeps
    // sub-millimetre precision for a set far from the world origin (a georeferenced model).
    // The glTF loader composes node transforms in double and sets it (gltf_loader.h); 0 for
    // scenes within about 500 m of the origin, whose positions are then world positions.
    glm::dvec3 originM{0.0};
    Geometry geometry;
    std::vector<Material> materials;
    std::vector<Texture> textures;
    std::vector<PunctualLight> lights;
    std::vector<Camera> cameras;
    std::optional<EnvironmentMap> environment;  // none: black background
    // The camera to render from when the caller names none (a scene description's
    // camera.name, already checked to exist in `cameras`); empty: the first camera.
    std::string cameraName;
};

// Whether anything in the scene emits light: a punctual light or a triangle with an emissive
// material (the environment map aside).
inline bool hasLightSource(const Scene& scene) {
    for (const PunctualLight& l : scene.lights)
        if (l.intensity > 0.0f && glm::any(glm::greaterThan(l.color, glm::vec3(0.0f)))) return true;
    for (uint32_t m : scene.geometry.triangleMaterials)
        if (m < scene.materials.size() &&
            glm::any(glm::greaterThan(scene.materials[m].emission, glm::vec3(0.0f))))
            return true;
    return false;
}

}  // namespace previs
