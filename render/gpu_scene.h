#pragma once

// The scene as the path tracer's shaders read it, apart from the sample loop that reads it
// (pbrt-v4 keeps its aggregate and lights apart from the integrator): geometry and BVH,
// materials and textures, lights and the environment, uploaded once by create(). Live lighting
// (setEnvironment, setEstimatedLights) and the camera-relative origin (recentre) replace parts
// of it later without rebuilding the BVH.
//
// Camera-relative rendering (Renderer::setCameraPose): world = sceneOriginM + scene position;
// GPU position = float(world − renderOriginM), computed in double.

#include <array>
#include <cstdint>
#include <glm/glm.hpp>
#include <memory>
#include <span>
#include <vector>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/shaders/shared/scene_types.h"
#include "render/bvh.h"
#include "render/photon_map.h"
#include "render/render_settings.h"
#include "scene/environment_map.h"
#include "scene/scene.h"

namespace previs {

// What the scene uses, which decides the pipelines' specialisation constants (PV_SPEC_*).
SceneFeatures detectSceneFeatures(const Scene& scene, const Camera& camera);

// A scene-frame position in the GPU's frame: the offset (scene origin − render origin) is added
// in double, then rounded once to float.
inline glm::vec3 toRenderFrame(const glm::vec3& p, const glm::dvec3& offset) {
    return glm::vec3(glm::dvec3(p) + offset);
}

// A box in world coordinates (metres).
struct WorldBox {
    glm::dvec3 lo, hi;
};

// The scene's device buffers, one per PV_BINDING_* the scene owns.
struct GpuSceneBuffers {
    // Geometry in BVH order (each leaf's triangles contiguous), one 16-byte texel an entry.
    GpuBuffer triangleVertices;   // xyz in the GPU's frame, 3 per triangle
    GpuBuffer normals;            // per vertex
    GpuBuffer uvs;                // per vertex
    GpuBuffer triangles;          // vertex indices + material
    GpuBuffer triangleMaterials;  // per triangle
    GpuBuffer bvhNodes;           // the wide BVH (refitted by recentre)
    // The specular albedo table, then the materials (shared/specular_albedo.h).
    GpuBuffer materials;
    GpuBuffer textures;           // shader::TextureInfo per texture
    GpuBuffer texels;             // every texture's RGBA8 texels
    GpuBuffer lights;             // the scene's lights, then the estimated (cone) lights
    GpuBuffer emissiveTriangles;  // chosen in proportion to their power
    GpuBuffer triangleLightPdf;   // per triangle: its probability as a light (0: not one)
    GpuBuffer envRadiance;
    GpuBuffer envMarginalCdf;
    GpuBuffer envConditionalCdf;
    GpuBuffer photonLights;  // the photon light table (buildPhotonLights)
};

class GpuScene {
public:
    // Uploads `scene`, whose geometry in the GPU's frame is `g` (scene.geometry moved by
    // sceneOriginM − renderOriginM) with `bvh` built from it. `features` are
    // detectSceneFeatures'; the scene turns off emissive where no emitter has area and power.
    // `aim` is photonAimFor(g). Writes the scene's fields of `params` (lights, emitters, BVH
    // roots, environment, photon aim). The photon light table is empty until
    // updatePhotonLights.
    static Result<GpuScene> create(GpuContext& ctx, const Scene& scene, const Geometry& g,
                                   SceneBvh bvh, const SceneFeatures& features,
                                   const PhotonAim& aim, const glm::dvec3& sceneOriginM,
                                   const glm::dvec3& renderOriginM, shader::FrameParams& params);

    // Live lighting (Renderer::setEnvironment, setEstimatedLights): each writes its fields of
    // `params`; buffers are reallocated only where a size changes.
    Status setEnvironment(std::shared_ptr<const EnvironmentMap> map, shader::FrameParams& params);
    Status setEstimatedLights(std::span<const EstimatedLightSource> lights,
                              shader::FrameParams& params);
    // Moves the GPU's origin to `originM` (world): re-uploads vertices, BVH boxes and lights
    // (no BVH rebuild) and moves the photon aim. The caller moves the camera.
    Status recentre(const glm::dvec3& originM, shader::FrameParams& params);
    // Rebuilds the photon light table from allLights() (empty while params.photonCount is 0)
    // and sets params.photonLightCount: photons run where it is above 0.
    Status updatePhotonLights(shader::FrameParams& params);

    // Boxes around the virtual geometry (world frame): its BVH's nodes `levels` below the
    // root, so that separate objects get separate boxes; none without virtual geometry.
    std::vector<WorldBox> virtualBoxes(uint32_t levels) const;

    const SceneFeatures& features() const { return features_; }
    const SceneBvh& bvh() const { return bvh_; }
    const PhotonAim& photonAim() const { return photonAim_; }
    // The world position of the GPU's coordinate origin.
    const glm::dvec3& renderOriginM() const { return renderOriginM_; }
    // How often the GPU's origin moved since create().
    uint64_t recentreCount() const { return recentres_; }
    const GpuSceneBuffers& buffers() const { return buffers_; }
    // Puts the scene's buffers at their PV_BINDING_* in `table` (the other entries untouched).
    void bindInto(std::array<GpuBuffer*, PV_BINDING_COUNT>& table);
    uint64_t deviceBytes() const;

private:
    GpuScene(GpuSceneBuffers buffers) : buffers_(std::move(buffers)) {}
    // The lights buffer: the scene's lights, then the estimated (cone) lights.
    std::vector<shader::GpuLight> allLights() const;

    GpuContext* ctx_ = nullptr;
    GpuSceneBuffers buffers_;
    SceneFeatures features_;
    SceneBvh bvh_;
    PhotonAim photonAim_;
    std::vector<EmissivePhotonSource> emissivePhotonSources_;
    // The environment's power as a photon light (environmentPhotonLuminance; 0: none).
    double environmentPhotonLuminance_ = 0.0;
    std::vector<shader::GpuLight> sceneLights_;      // the scene's own; estimated ones follow them
    std::vector<shader::GpuLight> estimatedLights_;  // cone lights (directions only)
    glm::dvec3 sceneOriginM_{0.0};
    glm::dvec3 renderOriginM_{0.0};
    std::vector<glm::vec3> sceneTriangleVertices_;  // scene frame, 3 per triangle, BVH order
    std::vector<glm::vec3> sceneLightPositions_;    // scene frame, per scene light
    uint64_t recentres_ = 0;
};

}  // namespace previs
