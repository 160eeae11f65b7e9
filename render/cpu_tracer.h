#pragma once

// The CPU reference for the shaders' ray casting: the shared code of
// gpu/shaders/shared/ray_tracing.h run on the same BVH and triangle order the renderer uploads.
// Tests of the BVH and of the GPU path tracer compare against it.

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <vector>

#include "base/result.h"
#include "gpu/shaders/shared/ray_tracing.h"
#include "render/bvh.h"
#include "scene/scene.h"

namespace previs {

class CpuTracer {
public:
    // Builds the BVH of `geometry` and copies what tracing needs.
    static Result<CpuTracer> create(const Geometry& geometry, const BvhBuildOptions& options = {});
    // Takes a BVH that buildSceneBvh made from this very `geometry`.
    CpuTracer(SceneBvh bvh, const Geometry& geometry);

    // Closest hit with t in (ray.tMin, ray.tMax). realOnly: only the real (phantom) geometry,
    // else real and virtual. Hit::triangle is in BVH order (see originalTriangle).
    std::optional<shader::Hit> closestHit(const shader::Ray& ray, bool realOnly = false) const;
    // Whether anything lies on the ray with t in (ray.tMin, ray.tMax).
    bool occluded(const shader::Ray& ray, bool realOnly = false) const;

    const SceneBvh& bvh() const { return bvh_; }
    // Triangles in BVH order (as uploaded to the GPU), indexing positions().
    const std::vector<glm::uvec3>& triangles() const { return triangles_; }
    const std::vector<glm::vec3>& positions() const { return positions_; }
    uint32_t originalTriangle(uint32_t bvhIndex) const { return bvh_.triangleOrder[bvhIndex]; }
    // Real triangles come first in BVH order.
    bool isReal(uint32_t bvhIndex) const { return bvhIndex < realCount_; }

private:
    SceneBvh bvh_;
    std::vector<glm::uvec3> triangles_;
    std::vector<glm::vec3> positions_;
    std::vector<glm::vec3> triangleVertices_;  // what traversal reads: 3 per triangle, BVH order
    uint32_t realCount_ = 0;
};

}  // namespace previs
