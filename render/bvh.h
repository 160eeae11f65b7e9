#pragma once

// Bounding volume hierarchies over a scene's triangles: a binary SAH tree (shader::BvhNode),
// collapsed into the 4-wide tree the shaders traverse (shader::WideBvhNode,
// gpu/shaders/shared/ray_tracing.h). Real (phantom) and virtual triangles get separate trees in
// one node array: a ray that may only see the real world traverses the real root, a ray that
// sees both traverses both roots.

#include <cstdint>
#include <vector>

#include "base/result.h"
#include "gpu/shaders/shared/scene_types.h"
#include "scene/scene.h"

namespace previs {

// Root index of an empty tree (PV_BVH_NO_ROOT in the shaders).
inline constexpr uint32_t kBvhNoRoot = 0xffffffffu;

struct SceneBvh {
    // The binary tree: what the SAH cost and the statistics below describe.
    std::vector<shader::BvhNode> nodes;
    // BVH-order index -> index into Geometry::triangles. Real triangles come first, so each
    // leaf's triangles are contiguous; shaders read triangles in this order.
    std::vector<uint32_t> triangleOrder;
    uint32_t realRoot = kBvhNoRoot;
    uint32_t virtualRoot = kBvhNoRoot;
    // The same trees collapsed to 4 children per node (shader::WideBvhNode): what the shaders and
    // CpuTracer traverse. Each wide child is a node or leaf of the binary tree, so leaves, triangle
    // order and boxes are the binary tree's.
    std::vector<shader::WideBvhNode> wideNodes;
    uint32_t wideRealRoot = kBvhNoRoot;
    uint32_t wideVirtualRoot = kBvhNoRoot;
    uint32_t wideMaxDepth = 0;
    // Expected cost of a ray that traverses both trees, by the surface area heuristic with
    // traversal cost 1 and intersection cost 1, each tree normalised by its root's area (see
    // bvhSahCost). Lower is better; a single leaf costs the triangle count.
    double sahCost = 0.0;
    uint32_t maxDepth = 0;      // of the deeper tree; the root is at depth 0
    uint32_t maxLeafSize = 0;   // most triangles in one leaf
    double buildSeconds = 0.0;  // wall time of buildSceneBvh
};

enum class BvhSplit {
    Sah,     // binned SAH (default)
    Median,  // object median on the longest centroid axis: a baseline for tests and benchmarks
};

struct BvhBuildOptions {
    BvhSplit split = BvhSplit::Sah;
    // Most triangles a leaf holds unless the depth cap forces more.
    uint32_t maxLeafSize = 8;
};

// Builds both trees. Fails (with a message naming the triangle) on a vertex index out of range,
// a non-finite vertex, or triangleIsReal/triangles of different sizes; an empty triangleIsReal
// means every triangle is virtual.
Result<SceneBvh> buildSceneBvh(const Geometry& geometry, const BvhBuildOptions& options = {});

// Recomputes every box of the wide trees from `triangleVertices` (3 per triangle, BVH order),
// keeping the topology: after the renderer moves its frame (camera-relative rendering,
// render/renderer.cpp) the same triangles sit at other float coordinates. The boxes are the
// exact bounds of their triangles' vertices, so traversal stays conservative.
void refitWideBvh(SceneBvh& bvh, const std::vector<glm::vec4>& triangleVertices);

// SAH cost of the tree at `root` (MacDonald & Booth 1990): sum over interior nodes of
// kTraversal·A(n)/A(root) plus over leaves of kIntersection·count·A(n)/A(root), with
// kTraversal = kIntersection = 1. 0 for an empty tree; a root of zero area counts every node
// with weight 1.
double bvhSahCost(const std::vector<shader::BvhNode>& nodes, uint32_t root);

}  // namespace previs
