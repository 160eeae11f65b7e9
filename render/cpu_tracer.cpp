#include "render/cpu_tracer.h"

#include <utility>

#include "base/log.h"

namespace previs {

namespace {

// The shared traversal reads the scene through accessor macros; on the CPU they read these
// pointers, which each call sets for its own thread, so tracers on different threads do not
// interfere and the header stays the one the shaders compile.
struct BoundScene {
    const shader::WideBvhNode* nodes = nullptr;
    const glm::vec3* triangleVertices = nullptr;  // 3 per triangle, BVH order
};
thread_local BoundScene gBound;

}  // namespace

}  // namespace previs

#define PV_BVH_NODE(i) (::previs::gBound.nodes[i])
#define PV_BVH_NODE_CHILDREN(i) (::previs::gBound.nodes[i].child)
#define PV_TRIANGLE_VERTEX(i, k) (::previs::gBound.triangleVertices[3 * (i) + (k)])
#include "gpu/shaders/shared/ray_tracing.h"

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
    triangleVertices_.reserve(3 * triangles_.size());
    for (size_t i = 0; i < triangles_.size(); ++i) {
        uint32_t src = bvh_.triangleOrder[i];
        triangles_[i] = geometry.triangles[src];
        for (int k = 0; k < 3; ++k) triangleVertices_.push_back(positions_[triangles_[i][k]]);
        if (!geometry.triangleIsReal.empty() && geometry.triangleIsReal[src]) realCount_ = i + 1;
    }
}

std::optional<shader::Hit> CpuTracer::closestHit(const shader::Ray& ray, bool realOnly) const {
    gBound = {bvh_.wideNodes.data(), triangleVertices_.data()};
    shader::Hit hit{ray.tMax, kBvhNoRoot, 0.0f, 0.0f};
    if (!shader::traceClosest(bvh_.wideRealRoot, realOnly ? kBvhNoRoot : bvh_.wideVirtualRoot, ray,
                              hit))
        return std::nullopt;
    return hit;
}

bool CpuTracer::occluded(const shader::Ray& ray, bool realOnly) const {
    gBound = {bvh_.wideNodes.data(), triangleVertices_.data()};
    return shader::traceAny(bvh_.wideRealRoot, realOnly ? kBvhNoRoot : bvh_.wideVirtualRoot, ray) !=
           PV_BVH_NO_TRIANGLE;
}

}  // namespace previs
