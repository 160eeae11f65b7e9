#include "bench/bench_scenes.h"

#include <algorithm>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <map>

#include "scene/environment_map.h"

namespace previs::bench {

namespace {

Material lambertMaterial(glm::vec3 albedo) {
    Material m;
    m.baseColor = glm::vec4(albedo, 1.0f);
    m.metallic = 0.0f;
    m.specular = 0.0f;
    return m;
}

void appendMesh(Scene& scene, const TriangleMesh& mesh, const glm::mat4& worldFromMesh,
                uint32_t material) {
    Geometry& g = scene.geometry;
    uint32_t base = uint32_t(g.positions.size());
    for (const auto& p : mesh.positions) {
        g.positions.push_back(glm::vec3(worldFromMesh * glm::vec4(p, 1.0f)));
        g.normals.emplace_back(0.0f);
        g.uvs.emplace_back(0.0f);
    }
    // Smooth vertex normals (area-weighted), as a scanned mesh would be shaded.
    for (const auto& t : mesh.triangles) {
        glm::vec3 n = glm::cross(g.positions[base + t.y] - g.positions[base + t.x],
                                 g.positions[base + t.z] - g.positions[base + t.x]);
        for (int k = 0; k < 3; ++k) g.normals[base + t[k]] += n;
        g.triangles.push_back(t + glm::uvec3(base));
        g.triangleMaterials.push_back(material);
        g.triangleIsReal.push_back(0);
    }
    for (uint32_t i = base; i < g.normals.size(); ++i) {
        float len = glm::length(g.normals[i]);
        g.normals[i] = len > 0.0f ? g.normals[i] / len : glm::vec3(0, 1, 0);
    }
}

}  // namespace

TriangleMesh subdivide(const TriangleMesh& mesh) {
    TriangleMesh out;
    out.positions = mesh.positions;
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> midpoints;
    auto mid = [&](uint32_t a, uint32_t b) {
        auto key = std::minmax(a, b);
        auto [it, inserted] = midpoints.try_emplace({key.first, key.second}, 0);
        if (inserted) {
            it->second = uint32_t(out.positions.size());
            out.positions.push_back(0.5f * (mesh.positions[a] + mesh.positions[b]));
        }
        return it->second;
    };
    for (const auto& t : mesh.triangles) {
        uint32_t ab = mid(t.x, t.y), bc = mid(t.y, t.z), ca = mid(t.z, t.x);
        out.triangles.emplace_back(t.x, ab, ca);
        out.triangles.emplace_back(ab, t.y, bc);
        out.triangles.emplace_back(ca, bc, t.z);
        out.triangles.emplace_back(ab, bc, ca);
    }
    return out;
}

Scene meshOnPlaneScene(const TriangleMesh& mesh, const std::string& envPath, float heightM,
                       bool glossy) {
    glm::vec3 lo(1e30f), hi(-1e30f);
    for (const auto& p : mesh.positions) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    float scale = heightM / std::max(hi.y - lo.y, 1e-9f);
    glm::vec3 center = 0.5f * (lo + hi);
    glm::mat4 worldFromMesh = glm::scale(glm::mat4(1.0f), glm::vec3(scale)) *
                              glm::translate(glm::mat4(1.0f), -glm::vec3(center.x, lo.y, center.z));
    Scene s;
    s.materials.push_back(lambertMaterial(glm::vec3(0.5f)));
    Material object = lambertMaterial(glm::vec3(0.8f));
    if (glossy) {
        object.metallic = 1.0f;
        object.roughness = 0.3f;
    }
    s.materials.push_back(object);
    TriangleMesh plane{{{-1, 0, -1}, {1, 0, -1}, {1, 0, 1}, {-1, 0, 1}}, {{0, 2, 1}, {0, 3, 2}}};
    appendMesh(s, plane, glm::mat4(1.0f), 0);
    appendMesh(s, mesh, worldFromMesh, 1);
    Camera cam;
    cam.name = "bench";
    cam.fovYRad = glm::radians(40.0f);
    cam.worldFromCamera =
        glm::inverse(glm::lookAt(glm::vec3(0, 0.55f, 1.45f) * heightM,
                                 glm::vec3(0, 0.45f, 0) * heightM, glm::vec3(0, 1, 0)));
    s.cameras.push_back(cam);
    if (!envPath.empty()) {
        auto env = loadEnvironmentMap(envPath);
        if (env) s.environment = std::move(env.value());
    } else {
        EnvironmentMap sky;
        sky.width = 4;
        sky.height = 2;
        sky.radiance.assign(8, glm::vec3(1.0f));
        s.environment = sky;
    }
    return s;
}

Result<Scene> bunnyScene(const std::string& dataDir, const std::string& envPath) {
    auto mesh = readPly(dataDir + "/meshes/stanford_bunny.ply");
    if (!mesh) return mesh.error();
    float floorY = 1e30f;
    for (const auto& p : mesh->positions) floorY = std::min(floorY, p.y);
    Scene s;
    s.materials.push_back(lambertMaterial(glm::vec3(0.5f)));
    s.materials.push_back(lambertMaterial(glm::vec3(0.8f)));
    TriangleMesh plane{{{-1, floorY, -1}, {1, floorY, -1}, {1, floorY, 1}, {-1, floorY, 1}},
                       {{0, 2, 1}, {0, 3, 2}}};
    appendMesh(s, plane, glm::mat4(1.0f), 0);
    appendMesh(s, *mesh, glm::mat4(1.0f), 1);
    Camera cam;
    cam.name = "bench";
    cam.fovYRad = glm::radians(40.0f);
    // Same eye and target as bench/blender_cycles_bunny.py.
    cam.worldFromCamera = glm::inverse(glm::lookAt(
        glm::vec3(0.0f, 0.16f, 0.42f), glm::vec3(-0.015f, 0.1f, 0.0f), glm::vec3(0, 1, 0)));
    s.cameras.push_back(cam);
    auto env = loadEnvironmentMap(envPath);
    if (!env) return env.error();
    s.environment = std::move(env.value());
    return s;
}

}  // namespace previs::bench
