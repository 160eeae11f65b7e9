#include "render/gpu_scene.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <utility>

#include "base/log.h"
#include "gpu/shaders/shared/specular_albedo.h"
#include "gpu/shaders/shared/texture_sampling.h"
#include "scene/environment_sampler.h"
#include "scene/material.h"

namespace previs {

namespace {

constexpr float kFourPi = 4.0f * std::numbers::pi_v<float>;

bool materialHasSpecular(const Material& m) { return m.metallic > 0.0f || m.specular > 0.0f; }

bool finiteNonNegative(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) && v.x >= 0.0f &&
           v.y >= 0.0f && v.z >= 0.0f;
}

// The environment's FrameParams fields; all zero without one (as a fresh renderer has them).
void setEnvironmentParams(shader::FrameParams& p, const EnvironmentMap* map,
                          const EnvironmentDistribution& dist) {
    p.envWidth = map ? map->width : 0;
    p.envHeight = map ? map->height : 0;
    p.envScale = map ? map->scale : 0.0f;
    // As shader::envRotationCosSin (env_sampling.h), which the CPU sampler uses.
    p.envRotationCos = map ? std::cos(map->rotationRad) : 0.0f;
    p.envRotationSin = map ? std::sin(map->rotationRad) : 0.0f;
    p.envIntegral = map ? dist.integral : 0.0f;
}

template <typename V>
Result<GpuBuffer> uploadVector(GpuContext& ctx, const V& v, const char* label) {
    return GpuBuffer::createWith(ctx, std::span(v.data(), v.size()), label);
}

// The first error among `results`; none when all hold a buffer.
template <typename... R>
Status firstError(const R&... results) {
    Status s;
    ((s = s && !results ? Status(results.error()) : s), ...);
    return s;
}

// The geometry as the shaders' texels (trace_paths.comp), triangles in BVH order so that each
// leaf's triangles are contiguous.
struct GeometryTexels {
    std::vector<glm::vec4> vertices;  // xyz = position, w unused
    std::vector<glm::vec4> normals;
    std::vector<glm::vec4> uvs;
    std::vector<glm::uvec4> triangles;  // vertex indices + material
    std::vector<uint32_t> materials;
    std::vector<glm::uvec3> indices;  // as triangles, without the material
};

GeometryTexels geometryTexels(const Geometry& g, const SceneBvh& bvh) {
    GeometryTexels t;
    const size_t triCount = g.triangles.size();
    t.normals.resize(g.normals.size());
    t.uvs.resize(g.uvs.size());
    for (size_t v = 0; v < g.normals.size(); ++v) t.normals[v] = glm::vec4(g.normals[v], 0.0f);
    for (size_t v = 0; v < g.uvs.size(); ++v) t.uvs[v] = glm::vec4(g.uvs[v], 0.0f, 0.0f);
    t.triangles.resize(triCount);
    t.materials.resize(triCount);
    t.indices.resize(triCount);
    t.vertices.resize(3 * triCount);
    for (size_t i = 0; i < triCount; ++i) {
        const uint32_t src = bvh.triangleOrder[i];
        t.indices[i] = g.triangles[src];
        t.materials[i] = g.triangleMaterials[src];
        t.triangles[i] = glm::uvec4(t.indices[i], t.materials[i]);
        for (int k = 0; k < 3; ++k)
            t.vertices[3 * i + k] = glm::vec4(g.positions[t.indices[i][k]], 0.0f);
    }
    return t;
}

shader::GpuMaterial gpuMaterial(const Material& m) {
    shader::GpuMaterial gm{};
    gm.baseColor = m.baseColor;
    gm.emission = m.emission;
    gm.metallic = m.metallic;
    gm.roughness = m.roughness;
    gm.transmission = m.transmission;
    gm.ior = m.ior;
    gm.specular = m.specular;
    gm.specularColor = m.specularColor;
    auto tex = [](int i) { return i < 0 ? PV_NO_TEXTURE : uint32_t(i); };
    gm.baseColorTexture = tex(m.baseColorTexture);
    gm.metallicRoughnessTexture = tex(m.metallicRoughnessTexture);
    gm.normalTexture = tex(m.normalTexture);
    gm.emissiveTexture = tex(m.emissiveTexture);
    gm.flags = (m.doubleSided ? PV_MATERIAL_DOUBLE_SIDED : 0u) |
               (m.thinWalled ? PV_MATERIAL_THIN_WALLED : 0u);
    // Beer–Lambert: attenuationColor remains after attenuationDistanceM, so the absorption
    // coefficient is −ln(colour) / distance (a black colour absorbs within a micrometre).
    if (!m.thinWalled && std::isfinite(m.attenuationDistanceM))
        gm.attenuation =
            -glm::log(glm::max(m.attenuationColor, glm::vec3(1e-6f))) / m.attenuationDistanceM;
    return gm;
}

// The materials binding's words: the specular albedo table (shared/specular_albedo.h), then
// the materials.
std::vector<uint32_t> materialWords(std::span<const Material> materials) {
    std::vector<shader::GpuMaterial> gpu;
    for (const Material& m : materials) gpu.push_back(gpuMaterial(m));
    static_assert(sizeof(shader::kSpecularAlbedo) == 16 * PV_SPECULAR_ALBEDO_TEXELS);
    std::vector<uint32_t> words(
        (sizeof(shader::kSpecularAlbedo) + gpu.size() * sizeof(shader::GpuMaterial)) / 4);
    std::memcpy(words.data(), shader::kSpecularAlbedo, sizeof(shader::kSpecularAlbedo));
    if (!gpu.empty())  // memcpy from an empty vector's null data() is undefined
        std::memcpy(words.data() + sizeof(shader::kSpecularAlbedo) / 4, gpu.data(),
                    gpu.size() * sizeof(shader::GpuMaterial));
    return words;
}

uint32_t textureFlags(const Texture& t) {
    auto wrap = [](TextureWrap w) {
        return w == TextureWrap::MirroredRepeat ? PV_WRAP_MIRRORED_REPEAT
               : w == TextureWrap::ClampToEdge  ? PV_WRAP_CLAMP_TO_EDGE
                                                : PV_WRAP_REPEAT;
    };
    return (t.srgb ? PV_TEXTURE_SRGB : 0u) | wrap(t.wrapS) << PV_TEXTURE_WRAP_S_SHIFT |
           wrap(t.wrapT) << PV_TEXTURE_WRAP_T_SHIFT | (t.nearest ? PV_TEXTURE_NEAREST : 0u);
}

shader::GpuLight gpuLight(const PunctualLight& l, const glm::dvec3& offset) {
    shader::GpuLight gl{};
    gl.position = toRenderFrame(l.position, offset);
    gl.type = l.type == LightType::Point  ? PV_LIGHT_POINT
              : l.type == LightType::Spot ? PV_LIGHT_SPOT
                                          : PV_LIGHT_DIRECTIONAL;
    if (l.isReal) gl.type |= PV_LIGHT_REAL;
    gl.direction = glm::normalize(l.direction);
    gl.intensity = l.color * l.intensity;
    gl.cosInnerCone = std::cos(l.innerConeAngleRad);
    gl.cosOuterCone = std::cos(l.outerConeAngleRad);
    return gl;
}

// Emissive triangles, chosen in proportion to their power (area × luminance), with each
// triangle's probability and the photon pass's sources.
struct Emitters {
    std::vector<shader::EmissiveTriangle> triangles;
    std::vector<float> triangleLightPdf;  // per triangle, BVH order
    std::vector<EmissivePhotonSource> photonSources;
};

Emitters findEmitters(const Scene& scene, const Geometry& g, const SceneBvh& bvh,
                      const GeometryTexels& t) {
    Emitters e;
    const size_t triCount = t.indices.size();
    e.triangleLightPdf.assign(triCount, 0.0f);
    double total = 0.0;
    std::vector<double> power;
    for (uint32_t i = 0; i < triCount; ++i) {
        const Material& m = scene.materials[t.materials[i]];
        const float lum = luminance(m.emission);
        if (!(lum > 0.0f)) continue;
        const glm::uvec3 tri = t.indices[i];
        const glm::vec3 p0 = g.positions[tri.x];
        const float area =
            0.5f * glm::length(glm::cross(g.positions[tri.y] - p0, g.positions[tri.z] - p0));
        if (!(area > 0.0f)) continue;
        e.triangles.push_back({i, area, 0.0f, 0.0f});
        const glm::vec3 centroid = (p0 + g.positions[tri.y] + g.positions[tri.z]) / 3.0f;
        e.photonSources.push_back(
            {i, lum, area, centroid, g.triangleIsReal[bvh.triangleOrder[i]] != 0});
        power.push_back(double(area) * lum);
        total += power.back();
    }
    double running = 0.0;
    for (size_t k = 0; k < e.triangles.size(); ++k) {
        running += power[k];
        e.triangles[k].pdf = float(power[k] / total);
        e.triangles[k].cdf = float(running / total);
        e.triangleLightPdf[e.triangles[k].triangle] = e.triangles[k].pdf;
    }
    if (!e.triangles.empty()) e.triangles.back().cdf = 1.0f;
    return e;
}

struct GeometryBuffers {
    GpuBuffer vertices, normals, uvs, triangles, materials, bvhNodes;
};

Result<GeometryBuffers> uploadGeometry(GpuContext& ctx, const GeometryTexels& t,
                                       const SceneBvh& bvh) {
    auto vertices = uploadVector(ctx, t.vertices, "triangleVertices");
    auto normals = uploadVector(ctx, t.normals, "normals");
    auto uvs = uploadVector(ctx, t.uvs, "uvs");
    auto triangles = uploadVector(ctx, t.triangles, "triangles");
    auto materials = uploadVector(ctx, t.materials, "triangleMaterials");
    auto nodes = uploadVector(ctx, bvh.wideNodes, "bvhNodes");
    if (Status s = firstError(vertices, normals, uvs, triangles, materials, nodes); !s)
        return s.error();
    return GeometryBuffers{std::move(*vertices),  std::move(*normals),   std::move(*uvs),
                           std::move(*triangles), std::move(*materials), std::move(*nodes)};
}

struct MaterialBuffers {
    GpuBuffer materials, textures, texels;
};

Result<MaterialBuffers> uploadMaterials(GpuContext& ctx, const Scene& scene) {
    std::vector<shader::TextureInfo> infos;
    std::vector<uint32_t> texels;
    for (const Texture& t : scene.textures) {
        infos.push_back({uint32_t(texels.size()), t.width, t.height, textureFlags(t)});
        texels.insert(texels.end(), t.rgba8.begin(), t.rgba8.end());
    }
    auto materials = uploadVector(ctx, materialWords(scene.materials), "materials");
    auto textures = uploadVector(ctx, infos, "textures");
    auto texelBuffer = uploadVector(ctx, texels, "texels");
    if (Status s = firstError(materials, textures, texelBuffer); !s) return s.error();
    return MaterialBuffers{std::move(*materials), std::move(*textures), std::move(*texelBuffer)};
}

struct LightBuffers {
    GpuBuffer lights, emissiveTriangles, triangleLightPdf, photonLights;
};

Result<LightBuffers> uploadLights(GpuContext& ctx, std::span<const shader::GpuLight> lights,
                                  const Emitters& emitters) {
    auto lightBuffer = uploadVector(ctx, lights, "lights");
    auto emissive = uploadVector(ctx, emitters.triangles, "emissiveTriangles");
    auto pdf = uploadVector(ctx, emitters.triangleLightPdf, "triangleLightPdf");
    // Filled by updatePhotonLights once the renderer knows its photon budget.
    auto photonLights = GpuBuffer::create(ctx, 0, "photonLights");
    if (Status s = firstError(lightBuffer, emissive, pdf, photonLights); !s) return s.error();
    return LightBuffers{std::move(*lightBuffer), std::move(*emissive), std::move(*pdf),
                        std::move(*photonLights)};
}

struct EnvironmentBuffers {
    GpuBuffer radiance, marginalCdf, conditionalCdf;
};

Result<EnvironmentBuffers> uploadEnvironment(GpuContext& ctx, std::span<const glm::vec3> radiance,
                                             const EnvironmentDistribution& dist) {
    auto texels = uploadVector(ctx, radiance, "envRadiance");
    auto marginal = uploadVector(ctx, dist.marginalCdf, "envMarginal");
    auto conditional = uploadVector(ctx, dist.conditionalCdf, "envConditional");
    if (Status s = firstError(texels, marginal, conditional); !s) return s.error();
    return EnvironmentBuffers{std::move(*texels), std::move(*marginal), std::move(*conditional)};
}

// A copy of `map` with NaN, Inf and negative texels (a bad camera frame would poison every
// pixel that samples them) set to 0, as loadEnvironmentMap does for files; `map` itself where
// all are fine.
std::shared_ptr<const EnvironmentMap> withoutBadTexels(std::shared_ptr<const EnvironmentMap> map) {
    const size_t bad = std::count_if(map->radiance.begin(), map->radiance.end(),
                                     [](const glm::vec3& v) { return !finiteNonNegative(v); });
    if (bad == 0) return map;
    logWarning("environment map '{}': {} NaN, infinite or negative texel(s) set to 0", map->path,
               bad);
    auto clean = std::make_shared<EnvironmentMap>(*map);
    for (glm::vec3& v : clean->radiance)
        if (!finiteNonNegative(v)) v = glm::vec3(0.0f);
    return clean;
}

Result<shader::GpuLight> coneLight(const EstimatedLightSource& e, size_t index) {
    const float len = glm::length(e.direction);
    if (!(len > 0.0f) || !std::isfinite(len) || !(e.solidAngleSr > 0.0f) ||
        !(e.solidAngleSr <= kFourPi) || !finiteNonNegative(e.radiance))
        return makeError(
            "estimated light {} is invalid (direction length {}, solid angle {} "
            "sr, radiance {} {} {}): it needs a direction, a solid angle in "
            "(0, 4pi] and finite non-negative radiance",
            index, len, e.solidAngleSr, e.radiance.r, e.radiance.g, e.radiance.b);
    shader::GpuLight gl{};
    gl.type = PV_LIGHT_CONE | PV_LIGHT_REAL;
    gl.direction = -e.direction / len;  // where the light points
    gl.intensity = e.radiance;
    // Ω = 2π(1 − cos θmax).
    gl.cosInnerCone = e.solidAngleSr / (2.0f * std::numbers::pi_v<float>);
    gl.cosOuterCone = 1.0f - gl.cosInnerCone;
    return gl;
}

// Each scene buffer's binding.
constexpr std::pair<int, GpuBuffer GpuSceneBuffers::*> kSceneBindings[] = {
    {PV_BINDING_TRIANGLE_VERTICES, &GpuSceneBuffers::triangleVertices},
    {PV_BINDING_NORMALS, &GpuSceneBuffers::normals},
    {PV_BINDING_UVS, &GpuSceneBuffers::uvs},
    {PV_BINDING_TRIANGLES, &GpuSceneBuffers::triangles},
    {PV_BINDING_TRIANGLE_MATERIALS, &GpuSceneBuffers::triangleMaterials},
    {PV_BINDING_BVH_NODES, &GpuSceneBuffers::bvhNodes},
    {PV_BINDING_MATERIALS, &GpuSceneBuffers::materials},
    {PV_BINDING_TEXTURES, &GpuSceneBuffers::textures},
    {PV_BINDING_TEXELS, &GpuSceneBuffers::texels},
    {PV_BINDING_LIGHTS, &GpuSceneBuffers::lights},
    {PV_BINDING_EMISSIVE_TRIANGLES, &GpuSceneBuffers::emissiveTriangles},
    {PV_BINDING_TRIANGLE_LIGHT_PDF, &GpuSceneBuffers::triangleLightPdf},
    {PV_BINDING_ENV_RADIANCE, &GpuSceneBuffers::envRadiance},
    {PV_BINDING_ENV_MARGINAL_CDF, &GpuSceneBuffers::envMarginalCdf},
    {PV_BINDING_ENV_CONDITIONAL_CDF, &GpuSceneBuffers::envConditionalCdf},
    {PV_BINDING_PHOTON_LIGHTS, &GpuSceneBuffers::photonLights},
};

template <typename T>
Status replaceWith(GpuBuffer& buffer, const std::vector<T>& v, const char* label) {
    return buffer.replaceContents(v.data(), v.size() * sizeof(T), label);
}

}  // namespace

SceneFeatures detectSceneFeatures(const Scene& scene, const Camera& camera) {
    SceneFeatures f;
    f.environment = scene.environment.has_value();
    f.punctual = !scene.lights.empty();
    f.thinLens = camera.apertureRadiusM > 0.0f;
    f.textures = !scene.textures.empty();
    // Only materials some triangle uses count.
    std::vector<bool> used(scene.materials.size(), false);
    for (uint32_t m : scene.geometry.triangleMaterials)
        if (m < used.size()) used[m] = true;
    for (size_t i = 0; i < scene.materials.size(); ++i) {
        if (!used[i]) continue;
        const Material& m = scene.materials[i];
        f.specular |= materialHasSpecular(m);
        f.transmission |= m.transmission > 0.0f;
        f.emissive |= glm::length(m.emission) > 0.0f;
        f.glossy |= glossyMaterial(m);
    }
    return f;
}

Result<GpuScene> GpuScene::create(GpuContext& ctx, const Scene& scene, const Geometry& g,
                                  SceneBvh bvh, const SceneFeatures& features, const PhotonAim& aim,
                                  const glm::dvec3& sceneOriginM, const glm::dvec3& renderOriginM,
                                  shader::FrameParams& params) {
    const glm::dvec3 offset = sceneOriginM - renderOriginM;
    const GeometryTexels texels = geometryTexels(g, bvh);
    std::vector<shader::GpuLight> lights;
    for (const PunctualLight& l : scene.lights) lights.push_back(gpuLight(l, offset));
    Emitters emitters;
    if (features.emissive) emitters = findEmitters(scene, g, bvh, texels);
    EnvironmentDistribution envDist;
    if (scene.environment) envDist = buildEnvironmentDistribution(*scene.environment);
    static const std::vector<glm::vec3> kNoTexels;

    auto geometry = uploadGeometry(ctx, texels, bvh);
    if (!geometry) return geometry.error();
    auto materials = uploadMaterials(ctx, scene);
    if (!materials) return materials.error();
    auto lightBuffers = uploadLights(ctx, lights, emitters);
    if (!lightBuffers) return lightBuffers.error();
    auto env = uploadEnvironment(ctx, scene.environment ? scene.environment->radiance : kNoTexels,
                                 envDist);
    if (!env) return env.error();
    GpuScene s(GpuSceneBuffers{std::move(geometry->vertices), std::move(geometry->normals),
                               std::move(geometry->uvs), std::move(geometry->triangles),
                               std::move(geometry->materials), std::move(geometry->bvhNodes),
                               std::move(materials->materials), std::move(materials->textures),
                               std::move(materials->texels), std::move(lightBuffers->lights),
                               std::move(lightBuffers->emissiveTriangles),
                               std::move(lightBuffers->triangleLightPdf), std::move(env->radiance),
                               std::move(env->marginalCdf), std::move(env->conditionalCdf),
                               std::move(lightBuffers->photonLights)});
    s.ctx_ = &ctx;
    s.features_ = features;
    if (emitters.triangles.empty()) s.features_.emissive = false;
    s.photonAim_ = aim;
    s.emissivePhotonSources_ = std::move(emitters.photonSources);
    s.sceneLights_ = lights;
    for (const PunctualLight& l : scene.lights) s.sceneLightPositions_.push_back(l.position);
    s.sceneOriginM_ = sceneOriginM;
    s.renderOriginM_ = renderOriginM;
    s.sceneTriangleVertices_.resize(texels.vertices.size());
    for (size_t v = 0; v < texels.vertices.size(); ++v)
        s.sceneTriangleVertices_[v] = scene.geometry.positions[texels.indices[v / 3][v % 3]];

    params.lightCount = uint32_t(lights.size());
    params.emissiveTriangleCount = uint32_t(emitters.triangles.size());
    params.realRoot = bvh.wideRealRoot;
    params.virtualRoot = bvh.wideVirtualRoot;
    setEnvironmentParams(params, scene.environment ? &*scene.environment : nullptr, envDist);
    s.environmentPhotonLuminance_ =
        scene.environment ? environmentPhotonLuminance(*scene.environment, envDist) : 0.0;
    params.coneLightFirst = uint32_t(lights.size());
    // The BVH puts real triangles first.
    params.realTriangleCount =
        uint32_t(std::count(g.triangleIsReal.begin(), g.triangleIsReal.end(), uint8_t(1)));
    params.photonAimCenter = aim.center;
    params.photonAimRadius = aim.radius;
    params.photonSceneRadius = aim.sceneRadius;
    s.bvh_ = std::move(bvh);
    return s;
}

Status GpuScene::setEnvironment(std::shared_ptr<const EnvironmentMap> map,
                                shader::FrameParams& params) {
    if (map && map->width == 0 && map->height == 0) map.reset();
    if (map && (map->width == 0 || map->height == 0 ||
                map->radiance.size() != size_t(map->width) * map->height))
        return makeError(
            "environment map '{}' is {}x{} but has {} texels; expected width x "
            "height RGB texels",
            map->path, map->width, map->height, map->radiance.size());
    if (map) map = withoutBadTexels(std::move(map));

    EnvironmentDistribution dist;
    if (map) dist = buildEnvironmentDistribution(*map);
    static const std::vector<glm::vec3> kNoTexels;
    Status s = replaceWith(buffers_.envRadiance, map ? map->radiance : kNoTexels, "envRadiance");
    if (s) s = replaceWith(buffers_.envMarginalCdf, dist.marginalCdf, "envMarginal");
    if (s) s = replaceWith(buffers_.envConditionalCdf, dist.conditionalCdf, "envConditional");
    // A half-replaced environment is no environment (black) rather than a wrong one.
    setEnvironmentParams(params, s ? map.get() : nullptr, dist);
    features_.environment = s && map;
    environmentPhotonLuminance_ = s && map ? environmentPhotonLuminance(*map, dist) : 0.0;
    // The environment is a photon light: its power changed.
    if (Status p = updatePhotonLights(params); !p && s) return p;
    return s;
}

Status GpuScene::setEstimatedLights(std::span<const EstimatedLightSource> estimated,
                                    shader::FrameParams& params) {
    std::vector<shader::GpuLight> lights = sceneLights_;
    std::vector<shader::GpuLight> cones;
    for (size_t i = 0; i < estimated.size(); ++i) {
        Result<shader::GpuLight> cone = coneLight(estimated[i], i);
        if (!cone) return cone.error();
        lights.push_back(*cone);
        cones.push_back(*cone);
    }
    Status s = replaceWith(buffers_.lights, lights, "lights");
    const bool ok = s.ok();
    estimatedLights_ = ok ? std::move(cones) : std::vector<shader::GpuLight>{};
    if (Status p = updatePhotonLights(params); !p) return p;
    params.lightCount = uint32_t(ok ? lights.size() : sceneLights_.size());
    features_.coneLights = ok && !estimated.empty();
    // Keep at least the scene's lights.
    if (!ok && !replaceWith(buffers_.lights, sceneLights_, "lights")) params.lightCount = 0;
    return s;
}

std::vector<shader::GpuLight> GpuScene::allLights() const {
    std::vector<shader::GpuLight> lights = sceneLights_;
    lights.insert(lights.end(), estimatedLights_.begin(), estimatedLights_.end());
    return lights;
}

Status GpuScene::recentre(const glm::dvec3& originM, shader::FrameParams& params) {
    // What moves by `shift` in the GPU's frame; exact geometry comes from the scene frame.
    const glm::dvec3 shift = renderOriginM_ - originM;
    renderOriginM_ = originM;
    ++recentres_;
    const glm::dvec3 offset = sceneOriginM_ - renderOriginM_;
    std::vector<glm::vec4> vertices(sceneTriangleVertices_.size());
    for (size_t i = 0; i < vertices.size(); ++i)
        vertices[i] = glm::vec4(toRenderFrame(sceneTriangleVertices_[i], offset), 0.0f);
    refitWideBvh(bvh_, vertices);
    for (size_t i = 0; i < sceneLights_.size(); ++i)
        sceneLights_[i].position = toRenderFrame(sceneLightPositions_[i], offset);
    // The aim sphere and emitter centroids only steer photons (they bound, never define, the
    // geometry): moved in double from where they were.
    photonAim_.center = toRenderFrame(photonAim_.center, shift);
    for (EmissivePhotonSource& e : emissivePhotonSources_)
        e.centroid = toRenderFrame(e.centroid, shift);
    params.photonAimCenter = photonAim_.center;
    Status s = replaceWith(buffers_.triangleVertices, vertices, "triangleVertices");
    if (s) s = replaceWith(buffers_.bvhNodes, bvh_.wideNodes, "bvhNodes");
    if (s) s = replaceWith(buffers_.lights, allLights(), "lights");
    if (s) s = updatePhotonLights(params);
    return s;
}

Status GpuScene::updatePhotonLights(shader::FrameParams& params) {
    std::vector<glm::uvec4> table;
    const double environment = params.envWidth > 0 ? environmentPhotonLuminance_ : 0.0;
    if (params.photonCount > 0)
        table = buildPhotonLights(photonAim_, emissivePhotonSources_, allLights(), environment);
    Status s = replaceWith(buffers_.photonLights, table, "photonLights");
    params.photonLightCount = s ? uint32_t(table.size()) : 0u;
    params.photonEnvironment =
        params.photonLightCount > 0 && (table[0].x & 0xffu) == PV_PHOTON_LIGHT_ENVIRONMENT;
    return s;
}

std::vector<WorldBox> GpuScene::virtualBoxes(uint32_t levels) const {
    std::vector<WorldBox> boxes;
    if (bvh_.virtualRoot == kBvhNoRoot) return boxes;
    // The virtual tree's nodes `levels` below its root: separate objects part at the top
    // splits, and a few levels more fit each one's shape.
    std::vector<uint32_t> frontier{bvh_.virtualRoot};
    for (uint32_t level = 0; level < levels; ++level) {
        std::vector<uint32_t> next;
        for (uint32_t n : frontier) {
            const shader::BvhNode& node = bvh_.nodes[n];
            if (node.count > 0) {
                next.push_back(n);
            } else {
                next.push_back(node.leftOrFirst);
                next.push_back(node.leftOrFirst + 1);
            }
        }
        frontier = std::move(next);
    }
    for (uint32_t n : frontier) {
        // A subtree's triangles are contiguous in BVH order: its leaves' extremes bound them.
        uint32_t first = std::numeric_limits<uint32_t>::max(), end = 0;
        std::vector<uint32_t> stack{n};
        while (!stack.empty()) {
            const shader::BvhNode& node = bvh_.nodes[stack.back()];
            stack.pop_back();
            if (node.count > 0) {
                first = std::min(first, node.leftOrFirst);
                end = std::max(end, node.leftOrFirst + node.count);
            } else {
                stack.push_back(node.leftOrFirst);
                stack.push_back(node.leftOrFirst + 1);
            }
        }
        WorldBox box{glm::dvec3(std::numeric_limits<double>::max()),
                     glm::dvec3(-std::numeric_limits<double>::max())};
        for (size_t v = 3 * size_t(first); v < 3 * size_t(end); ++v) {
            const glm::dvec3 p = sceneOriginM_ + glm::dvec3(sceneTriangleVertices_[v]);
            box.lo = glm::min(box.lo, p);
            box.hi = glm::max(box.hi, p);
        }
        if (first < end) boxes.push_back(box);
    }
    return boxes;
}

void GpuScene::bindInto(std::array<GpuBuffer*, PV_BINDING_COUNT>& table) {
    for (auto [binding, buffer] : kSceneBindings) table[binding] = &(buffers_.*buffer);
}

uint64_t GpuScene::deviceBytes() const {
    uint64_t total = 0;
    for (auto [binding, buffer] : kSceneBindings) total += (buffers_.*buffer).size();
    return total;
}

}  // namespace previs
