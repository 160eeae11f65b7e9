#include "render/cpu_tracer.h"

#include <utility>

#include "base/log.h"

namespace previs {

namespace {

// The shared traversal reads the scene through accessor macros; on the CPU they read these
// pointers, which each call sets for its own thread, so tracers on different threads do not
// interfere and the header stays the one the shaders compile.
struct BoundScene {
    const shader::BvhNode* nodes = nullptr;
    const glm::uvec3* triangles = nullptr;
    const glm::vec3* positions = nullptr;
};
thread_local BoundScene gBound;

}  // namespace

}  // namespace previs

#define PV_BVH_NODE(i) (::previs::gBound.nodes[i])
#define PV_TRIANGLE(i) (::previs::gBound.triangles[i])
#define PV_POSITION(i) (::previs::gBound.positions[i])
#include "shared/ray_tracing.h"

namespace previs {

Result<CpuTracer> CpuTracer::create(const Geometry& geometry, const BvhBuildOptions& options) {
    auto bvh = buildSceneBvh(geometry, options);
    if (!bvh) return bvh.error();
    return CpuTracer(std::move(bvh.value()), geometry);
}

CpuTracer::CpuTracer(SceneBvh bvh, const Geometry& geometry)
    : bvh_(std::move(bvh)), positions_(geometry.positions) {
    PV_ASSERT(bvh_.triangleOrder.size() == geometry.triangles.size());
    triangles_.resize(geometry.triangles.size());
    for (size_t i = 0; i < triangles_.size(); ++i) {
        uint32_t src = bvh_.triangleOrder[i];
        triangles_[i] = geometry.triangles[src];
        if (!geometry.triangleIsReal.empty() && geometry.triangleIsReal[src]) realCount_ = i + 1;
    }
}

std::optional<shader::Hit> CpuTracer::closestHit(const shader::Ray& ray, bool realOnly) const {
    gBound = {bvh_.nodes.data(), triangles_.data(), positions_.data()};
    shader::Hit hit{ray.tMax, kBvhNoRoot, 0.0f, 0.0f};
    bool found = shader::traceClosest(bvh_.realRoot, ray, hit);
    if (!realOnly) found = shader::traceClosest(bvh_.virtualRoot, ray, hit) || found;
    if (!found) return std::nullopt;
    return hit;
}

bool CpuTracer::occluded(const shader::Ray& ray, bool realOnly) const {
    gBound = {bvh_.nodes.data(), triangles_.data(), positions_.data()};
    if (shader::traceAny(bvh_.realRoot, ray)) return true;
    return !realOnly && shader::traceAny(bvh_.virtualRoot, ray);
}

}  // namespace previs
