#pragma once

// A small PLY reader (ascii and binary little endian) for test and benchmark meshes: vertex
// x, y, z and face vertex-index lists; polygons are fan-triangulated, other properties and
// elements are skipped.

#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

struct PlyMesh {
    std::vector<glm::vec3> positions;
    std::vector<glm::uvec3> triangles;
};

Result<PlyMesh> readPly(const std::string& path);

}  // namespace previs
