#include "tests/support/scene_builders.h"

#include <cmath>
#include <glm/gtc/matrix_transform.hpp>

namespace previs::testing {

Material lambert(glm::vec3 albedo) {
    Material m;
    m.name = "lambert";
    m.baseColor = glm::vec4(albedo, 1.0f);
    m.metallic = 0.0f;
    m.specular = 0.0f;
    m.roughness = 1.0f;
    return m;
}

Material mirror() {
    Material m;
    m.name = "mirror";
    m.metallic = 1.0f;
    m.roughness = 0.0f;
    return m;
}

Material glass(float ior) {
    Material m;
    m.name = "glass";
    m.metallic = 0.0f;
    m.roughness = 0.0f;
    m.transmission = 1.0f;
    m.ior = ior;
    return m;
}

Material emitter(glm::vec3 radiance) {
    Material m = lambert(glm::vec3(0.0f));
    m.name = "emitter";
    m.emission = radiance;
    return m;
}

uint32_t addMaterial(Scene& scene, const Material& material) {
    scene.materials.push_back(material);
    return uint32_t(scene.materials.size() - 1);
}

void addMesh(Scene& scene, const std::vector<glm::vec3>& positions,
             const std::vector<glm::vec3>& normals, const std::vector<glm::uvec3>& triangles,
             uint32_t material, bool real, const glm::mat4& worldFromObject) {
    Geometry& g = scene.geometry;
    uint32_t base = uint32_t(g.positions.size());
    glm::mat3 normalMatrix = glm::transpose(glm::inverse(glm::mat3(worldFromObject)));
    for (size_t i = 0; i < positions.size(); ++i) {
        g.positions.push_back(glm::vec3(worldFromObject * glm::vec4(positions[i], 1.0f)));
        g.normals.push_back(glm::normalize(normalMatrix * normals[i]));
        g.uvs.emplace_back(0.0f);
    }
    for (const auto& t : triangles) {
        g.triangles.push_back(t + glm::uvec3(base));
        g.triangleMaterials.push_back(material);
        g.triangleIsReal.push_back(real ? 1 : 0);
    }
}

void addSphere(Scene& scene, glm::vec3 center, float radius, uint32_t material, bool real,
               int rings, int segments) {
    std::vector<glm::vec3> p, n;
    std::vector<glm::uvec3> t;
    for (int i = 0; i <= rings; ++i) {
        float theta = float(M_PI) * float(i) / float(rings);
        for (int j = 0; j <= segments; ++j) {
            float phi = 2.0f * float(M_PI) * float(j) / float(segments);
            glm::vec3 d(std::sin(theta) * std::cos(phi), std::cos(theta),
                        std::sin(theta) * std::sin(phi));
            p.push_back(center + radius * d);
            n.push_back(d);
        }
    }
    for (int i = 0; i < rings; ++i) {
        for (int j = 0; j < segments; ++j) {
            uint32_t a = uint32_t(i * (segments + 1) + j);
            uint32_t b = a + uint32_t(segments + 1);
            // Counter-clockwise seen from outside.
            if (i != 0) t.emplace_back(a, a + 1, b);
            if (i != rings - 1) t.emplace_back(a + 1, b + 1, b);
        }
    }
    addMesh(scene, p, n, t, material, real);
}

void addQuad(Scene& scene, glm::vec3 center, glm::vec3 u, glm::vec3 v, uint32_t material,
             bool real) {
    glm::vec3 n = glm::normalize(glm::cross(u, v));
    addMesh(scene, {center - u - v, center + u - v, center + u + v, center - u + v}, {n, n, n, n},
            {{0, 1, 2}, {0, 2, 3}}, material, real);
}

void addBox(Scene& scene, glm::vec3 lo, glm::vec3 hi, uint32_t material, bool real,
            bool insideOut) {
    glm::vec3 c = 0.5f * (lo + hi);
    glm::vec3 h = 0.5f * (hi - lo);
    float s = insideOut ? -1.0f : 1.0f;
    for (int axis = 0; axis < 3; ++axis) {
        for (float sign : {-1.0f, 1.0f}) {
            glm::vec3 n(0.0f);
            n[axis] = sign;
            glm::vec3 u(0.0f), v(0.0f);
            u[(axis + 1) % 3] = h[(axis + 1) % 3];
            v[(axis + 2) % 3] = h[(axis + 2) % 3];
            // Orient so cross(u, v) points along s·n.
            if (glm::dot(glm::cross(u, v), n) * s < 0.0f) std::swap(u, v);
            addQuad(scene, c + n * h[axis], u, v, material, real);
        }
    }
}

EnvironmentMap uniformEnvironment(glm::vec3 radiance, uint32_t width, uint32_t height) {
    EnvironmentMap env;
    env.path = "uniform";
    env.width = width;
    env.height = height;
    env.radiance.assign(size_t(width) * height, radiance);
    return env;
}

Camera lookAt(glm::vec3 eye, glm::vec3 target, glm::vec3 up, float fovYRad) {
    Camera c;
    c.name = "test";
    c.worldFromCamera = glm::inverse(glm::lookAt(eye, target, up));
    c.fovYRad = fovYRad;
    c.focusDistanceM = glm::length(target - eye);
    return c;
}

Scene realFloorSeenFromAbove() {
    Scene s;
    addQuad(s, glm::vec3(0.0f), glm::vec3(2.0f, 0.0f, 0.0f), glm::vec3(0.0f, 0.0f, -2.0f),
            addMaterial(s, lambert(glm::vec3(0.5f))), /*real=*/true);
    s.cameras.push_back(lookAt(glm::vec3(-0.5f, 1.5f, 0.0f), glm::vec3(-0.5f, 0.0f, 0.0f),
                               glm::vec3(0.0f, 0.0f, -1.0f), glm::radians(40.0f)));
    return s;
}

Scene ballOnRealFloor(glm::vec3 sky) {
    Scene s;
    const uint32_t floor = addMaterial(s, lambert(glm::vec3(0.5f)));
    const uint32_t ball = addMaterial(s, lambert(glm::vec3(0.8f, 0.3f, 0.2f)));
    addQuad(s, glm::vec3(0.0f), glm::vec3(0.0f, 0.0f, 1.0f), glm::vec3(2.0f, 0.0f, 0.0f), floor,
            /*real=*/true);
    addSphere(s, glm::vec3(0.0f, 0.25f, 0.0f), 0.25f, ball);
    s.environment = uniformEnvironment(sky);
    s.cameras.push_back(lookAt(glm::vec3(0.0f, 0.6f, 1.8f), glm::vec3(0.0f, 0.25f, 0.0f),
                               glm::vec3(0.0f, 1.0f, 0.0f), 0.7f));
    return s;
}

Scene realTableUnderSun(bool withSky) {
    Scene s;
    addQuad(s, {0, 0, 0}, {0, 0, 2}, {2, 0, 0}, addMaterial(s, lambert(glm::vec3(0.7f))), true);
    addBox(s, {-0.9f, 0, -0.3f}, {-0.5f, 0.4f, 0.1f},
           addMaterial(s, lambert(glm::vec3(0.8f, 0.1f, 0.1f))), true);
    s.lights.push_back(realSun(glm::vec3(-1, -1, 0), 3.0f));
    if (withSky) s.environment = uniformEnvironment(glm::vec3(0.3f));
    s.cameras.push_back(lookAt({0, 3, 0.01f}, {0, 0, 0}, {0, 0, -1}, glm::radians(60.0f)));
    return s;
}

PunctualLight pointLight(glm::vec3 position, float intensity, bool real) {
    PunctualLight l;
    l.type = LightType::Point;
    l.position = position;
    l.intensity = intensity;
    l.isReal = real;
    return l;
}

PunctualLight realSun(glm::vec3 direction, float irradiance) {
    PunctualLight sun;
    sun.type = LightType::Directional;
    sun.direction = glm::normalize(direction);
    sun.intensity = irradiance;
    sun.isReal = true;
    return sun;
}

}  // namespace previs::testing
