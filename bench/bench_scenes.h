#pragma once

// The benchmark scenes, built in code from the meshes in ../shared/data/meshes so that the same
// command runs unchanged on any machine that has the data (and on a hardware Vulkan GPU).

#include <string>

#include "base/result.h"
#include "render/ply_reader.h"
#include "scene/scene.h"

namespace previs::bench {

using TriangleMesh = PlyMesh;

// Splits every triangle into four at its edge midpoints (×4 triangles, same surface).
TriangleMesh subdivide(const TriangleMesh& mesh);

// `mesh` scaled to `heightM` tall, standing on a 2 m Lambertian plane (albedo 0.5), itself
// Lambertian (albedo 0.8, specular 0), lit by `envPath` (none: a uniform sky of radiance 1),
// camera looking at it from the front. When `glossy` is set the mesh is rough metal instead, so
// the scene needs the specular code.
Scene meshOnPlaneScene(const TriangleMesh& mesh, const std::string& envPath, float heightM,
                       bool glossy = false);

// The scene bench/blender_cycles_bunny.py rebuilds in Blender: the bunny at its own scale
// (metres) on the plane, the same camera.
Result<Scene> bunnyScene(const std::string& dataDir, const std::string& envPath);

}  // namespace previs::bench
