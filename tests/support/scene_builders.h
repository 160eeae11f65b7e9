#pragma once

// Scenes with known answers, built in code for the renderer's tests and benchmarks, and the
// render settings they are traced with.

#include <glm/glm.hpp>

#include "render/render_settings.h"
#include "scene/scene.h"

namespace previs::testing {

Material lambert(glm::vec3 albedo);    // metallic 0, specular 0: exactly Lambertian
Material mirror();                     // metallic 1, roughness 0, white
Material glass(float ior);             // transmission 1, roughness 0, white
Material emitter(glm::vec3 radiance);  // black, emitting `radiance` from its front side

uint32_t addMaterial(Scene& scene, const Material& material);

// Appends triangles (indices into `positions`), transformed by worldFromObject.
void addMesh(Scene& scene, const std::vector<glm::vec3>& positions,
             const std::vector<glm::vec3>& normals, const std::vector<glm::uvec3>& triangles,
             uint32_t material, bool real, const glm::mat4& worldFromObject = glm::mat4(1.0f));
void addSphere(Scene& scene, glm::vec3 center, float radius, uint32_t material, bool real = false,
               int rings = 48, int segments = 96);
// A parallelogram centred at `center` spanned by ±u, ±v; its front faces cross(u, v).
void addQuad(Scene& scene, glm::vec3 center, glm::vec3 u, glm::vec3 v, uint32_t material,
             bool real = false);
// An axis-aligned box; outward faces (insideOut: faces point inward).
void addBox(Scene& scene, glm::vec3 lo, glm::vec3 hi, uint32_t material, bool real = false,
            bool insideOut = false);

EnvironmentMap uniformEnvironment(glm::vec3 radiance, uint32_t width = 16, uint32_t height = 8);

// A point light at `position` of `intensity` W/sr; `real`: of the real set (it lights both
// solutions), else a virtual light (the mixed solution only).
PunctualLight pointLight(glm::vec3 position, float intensity, bool real = false);

// A directional light of the real set shining along `direction` (normalised here), `irradiance`
// W/m².
PunctualLight realSun(glm::vec3 direction, float irradiance);

Camera lookAt(glm::vec3 eye, glm::vec3 target, glm::vec3 up, float fovYRad);

// A real grey floor (albedo 0.5), 2 m square, seen from 1.5 m straight above: all of the image.
Scene realFloorSeenFromAbove();

// A virtual Lambertian ball on a real grey floor under a uniform sky of radiance `sky`, seen
// from above and in front; the top rows of the image see the sky.
Scene ballOnRealFloor(glm::vec3 sky);

// A real table top and a real red box under a real sun (and a uniform sky of 0.3 when withSky),
// seen from above: the real set of the differential-rendering and denoiser tests.
Scene realTableUnderSun(bool withSky);

}  // namespace previs::testing
