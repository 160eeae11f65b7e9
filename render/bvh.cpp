#include "render/bvh.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <thread>

#include "base/log.h"
#include "gpu/shaders/shared/ray_tracing.h"

namespace previs {

namespace {

using shader::BvhNode;

// Deepest leaf (root at depth 0). Near-first traversal needs one stack entry per level, so this
// leaves the shaders' stack a margin; at the cap a node becomes a leaf whatever its size.
constexpr uint32_t kMaxDepth = 56;
// A wide node is at least one binary level below its parent, a leaf too large for one reference
// adds at most log4(2^24 / 128) < 9 levels (leafReference), and traversal keeps one stack entry
// per node of its path (ray_tracing.h).
static_assert(kMaxDepth + 9 <= PV_BVH_STACK_SIZE, "traversal stack cannot hold the deepest path");
// A traversal stack entry keeps a node index in the bits above PV_BVH_ENTRY_NODE_SHIFT.
constexpr size_t kMaxWideNodes = size_t(1) << (32 - PV_BVH_ENTRY_NODE_SHIFT);

// Centroid bins per axis (Wald 2007, "On fast Construction of SAH-based Bounding Volume
// Hierarchies": 16–32 bins lose little against a full sweep).
constexpr int kBins = 32;
// A node at least this large in the top kParallelDepth levels builds its right child on another
// thread (at most 2^kParallelDepth threads; the target has 2 cores).
constexpr uint32_t kParallelThreshold = 1u << 16;
constexpr uint32_t kParallelDepth = 2;

// SAH constants (MacDonald & Booth 1990): the cost of visiting a node and of one triangle test,
// in the same unit. 1 and 1 match the reported sahCost; their ratio, not their values, steers
// the build.
constexpr float kTraversalCost = 1.0f;
constexpr float kIntersectionCost = 1.0f;

struct PrimRef {
    glm::vec3 lo;
    uint32_t triangle;
    glm::vec3 hi;
};

struct Box {
    glm::vec3 lo{PV_FLOAT_MAX};
    glm::vec3 hi{-PV_FLOAT_MAX};

    void grow(glm::vec3 p) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    void grow(const Box& b) {
        lo = glm::min(lo, b.lo);
        hi = glm::max(hi, b.hi);
    }
    // Half the surface area (only ratios matter); 0 for an empty or flat-to-a-line box.
    float halfArea() const {
        glm::vec3 d = glm::max(hi - lo, glm::vec3(0.0f));
        return d.x * d.y + d.y * d.z + d.z * d.x;
    }
};

glm::vec3 centroid(const PrimRef& p) { return 0.5f * p.lo + 0.5f * p.hi; }

struct BuildStats {
    uint32_t maxDepth = 0;
    uint32_t maxLeafSize = 0;
};

// Top-down builder over prims_[begin, end): reorders the prims so that each leaf's are
// contiguous and appends nodes. Leaves store offsets into the prim array (== BVH order).
class Builder {
public:
    Builder(std::vector<PrimRef>& prims, const BvhBuildOptions& options,
            std::vector<BvhNode>& nodes)
        : prims_(prims), options_(options), nodes_(nodes) {}

    void build(uint32_t node, uint32_t begin, uint32_t end, uint32_t depth);
    const BuildStats& stats() const { return stats_; }

private:
    void makeLeaf(uint32_t node, uint32_t begin, uint32_t end, uint32_t depth);
    // Where to split [begin, end), or 0 for a leaf. Reorders the range.
    uint32_t split(uint32_t begin, uint32_t end, const Box& bounds, const Box& centroids);
    uint32_t splitSah(uint32_t begin, uint32_t end, const Box& bounds, const Box& centroids);
    uint32_t splitMedian(uint32_t begin, uint32_t end, const Box& centroids);

    std::vector<PrimRef>& prims_;
    const BvhBuildOptions& options_;
    std::vector<BvhNode>& nodes_;
    BuildStats stats_;
};

void Builder::makeLeaf(uint32_t node, uint32_t begin, uint32_t end, uint32_t depth) {
    nodes_[node].leftOrFirst = begin;
    nodes_[node].count = end - begin;
    stats_.maxDepth = std::max(stats_.maxDepth, depth);
    stats_.maxLeafSize = std::max(stats_.maxLeafSize, end - begin);
}

uint32_t Builder::splitMedian(uint32_t begin, uint32_t end, const Box& centroids) {
    glm::vec3 extent = centroids.hi - centroids.lo;
    int axis =
        extent.x >= extent.y ? (extent.x >= extent.z ? 0 : 2) : (extent.y >= extent.z ? 1 : 2);
    uint32_t mid = begin + (end - begin) / 2;
    if (extent[axis] > 0.0f) {
        std::nth_element(prims_.begin() + begin, prims_.begin() + mid, prims_.begin() + end,
                         [axis](const PrimRef& a, const PrimRef& b) {
                             return centroid(a)[axis] < centroid(b)[axis];
                         });
    }
    return mid;
}

uint32_t Builder::splitSah(uint32_t begin, uint32_t end, const Box& bounds, const Box& centroids) {
    uint32_t count = end - begin;
    struct Bin {
        Box box;
        uint32_t count = 0;
    };
    float bestCost = PV_FLOAT_MAX;
    int bestAxis = -1;
    int bestBin = 0;
    glm::vec3 scale(0.0f);
    bool active[3];
    for (int axis = 0; axis < 3; ++axis) {
        float extent = centroids.hi[axis] - centroids.lo[axis];
        // Zero extent: every centroid in one bin. A denormal extent can make the scale infinite.
        float s = float(kBins) / extent;
        active[axis] = extent > 0.0f && std::isfinite(s);
        scale[axis] = active[axis] ? s : 0.0f;
    }
    // One pass bins all three axes (an inactive axis puts everything in bin 0, unused).
    std::array<std::array<Bin, kBins>, 3> bins{};
    for (uint32_t i = begin; i < end; ++i) {
        const PrimRef& p = prims_[i];
        glm::vec3 c = centroid(p);
        for (int axis = 0; axis < 3; ++axis) {
            int b = std::min(kBins - 1, int((c[axis] - centroids.lo[axis]) * scale[axis]));
            Bin& bin = bins[axis][b];
            bin.count++;
            bin.box.grow(p.lo);
            bin.box.grow(p.hi);
        }
    }
    for (int axis = 0; axis < 3; ++axis) {
        if (!active[axis]) continue;
        // Sweep from the right for the area·count of every suffix, then from the left.
        std::array<float, kBins> rightCost{};
        Box right;
        uint32_t rightCount = 0;
        for (int b = kBins - 1; b > 0; --b) {
            right.grow(bins[axis][b].box);
            rightCount += bins[axis][b].count;
            rightCost[b] = rightCount ? right.halfArea() * float(rightCount) : PV_FLOAT_MAX;
        }
        Box left;
        uint32_t leftCount = 0;
        for (int b = 1; b < kBins; ++b) {
            left.grow(bins[axis][b - 1].box);
            leftCount += bins[axis][b - 1].count;
            if (leftCount == 0 || leftCount == count) continue;
            float cost = left.halfArea() * float(leftCount) + rightCost[b];
            if (cost < bestCost) {
                bestCost = cost;
                bestAxis = axis;
                bestBin = b;
            }
        }
    }
    if (bestAxis < 0) {
        // All centroids equal (or too close to bin): nothing separates the triangles. A leaf if
        // it is small enough, else halves in any order so the depth stays logarithmic.
        return count <= options_.maxLeafSize ? 0 : begin + count / 2;
    }
    // Split only if it pays: Ct·A(node) + Ci·Σ A(child)·N(child) < Ci·A(node)·N, all areas
    // un-normalised (a zero-area node then keeps its leaf while it is small enough).
    float nodeArea = bounds.halfArea();
    float splitCost = kTraversalCost * nodeArea + kIntersectionCost * bestCost;
    float leafCost = kIntersectionCost * nodeArea * float(count);
    if (count <= options_.maxLeafSize && !(splitCost < leafCost)) return 0;
    float lo = centroids.lo[bestAxis];
    float s = scale[bestAxis];
    auto midIt =
        std::partition(prims_.begin() + begin, prims_.begin() + end, [&](const PrimRef& p) {
            int b = std::min(kBins - 1, int((centroid(p)[bestAxis] - lo) * s));
            return b < bestBin;
        });
    uint32_t mid = uint32_t(midIt - prims_.begin());
    // Binning and partitioning use the same expression, so both sides are non-empty.
    if (mid == begin || mid == end) mid = begin + count / 2;
    return mid;
}

uint32_t Builder::split(uint32_t begin, uint32_t end, const Box& bounds, const Box& centroids) {
    uint32_t count = end - begin;
    if (options_.split == BvhSplit::Median) {
        return count <= options_.maxLeafSize ? 0 : splitMedian(begin, end, centroids);
    }
    return splitSah(begin, end, bounds, centroids);
}

void Builder::build(uint32_t node, uint32_t begin, uint32_t end, uint32_t depth) {
    Box bounds;
    Box centroids;
    for (uint32_t i = begin; i < end; ++i) {
        bounds.grow(prims_[i].lo);
        bounds.grow(prims_[i].hi);
        centroids.grow(centroid(prims_[i]));
    }
    nodes_[node].boundsMin = bounds.lo;
    nodes_[node].boundsMax = bounds.hi;
    uint32_t count = end - begin;
    uint32_t mid = (count <= 1 || depth >= kMaxDepth) ? 0 : split(begin, end, bounds, centroids);
    if (mid == 0 || mid == begin) {
        makeLeaf(node, begin, end, depth);
        return;
    }
    uint32_t left = uint32_t(nodes_.size());
    nodes_.resize(nodes_.size() + 2);
    nodes_[node].leftOrFirst = left;
    nodes_[node].count = 0;

    if (count < kParallelThreshold || depth >= kParallelDepth) {
        build(left, begin, mid, depth + 1);
        build(left + 1, mid, end, depth + 1);
        return;
    }
    // Large subtree: the right child is built on another thread into its own node array (root at
    // 0), then spliced in. The two halves touch disjoint prim ranges.
    std::vector<BvhNode> rightNodes(1);
    rightNodes.reserve(2 * size_t(end - mid));
    Builder rightBuilder(prims_, options_, rightNodes);
    std::thread worker([&] { rightBuilder.build(0, mid, end, depth + 1); });
    build(left, begin, mid, depth + 1);
    worker.join();
    // Local index j >= 1 moves to base + j - 1; local 0 goes to slot left + 1.
    uint32_t base = uint32_t(nodes_.size());
    auto relocate = [base](BvhNode n) {
        if (n.count == 0) n.leftOrFirst = base + n.leftOrFirst - 1;
        return n;
    };
    nodes_[left + 1] = relocate(rightNodes[0]);
    for (size_t j = 1; j < rightNodes.size(); ++j) nodes_.push_back(relocate(rightNodes[j]));
    stats_.maxDepth = std::max(stats_.maxDepth, rightBuilder.stats().maxDepth);
    stats_.maxLeafSize = std::max(stats_.maxLeafSize, rightBuilder.stats().maxLeafSize);
}

}  // namespace

double bvhSahCost(const std::vector<BvhNode>& nodes, uint32_t root) {
    if (root == kBvhNoRoot || root >= nodes.size()) return 0.0;
    auto area = [&](uint32_t i) {
        Box b{nodes[i].boundsMin, nodes[i].boundsMax};
        return double(b.halfArea());
    };
    double rootArea = area(root);
    double cost = 0.0;
    std::vector<uint32_t> stack{root};
    while (!stack.empty()) {
        uint32_t i = stack.back();
        stack.pop_back();
        double weight = rootArea > 0.0 ? area(i) / rootArea : 1.0;
        const BvhNode& n = nodes[i];
        if (n.count > 0) {
            cost += kIntersectionCost * double(n.count) * weight;
        } else {
            cost += kTraversalCost * weight;
            stack.push_back(n.leftOrFirst);
            stack.push_back(n.leftOrFirst + 1);
        }
    }
    return cost;
}

namespace {

shader::WideBvhNode emptyWideNode() {
    shader::WideBvhNode w;
    w.loX = w.loY = w.loZ = glm::vec4(PV_FLOAT_MAX);
    w.hiX = w.hiY = w.hiZ = glm::vec4(-PV_FLOAT_MAX);
    w.child = glm::uvec4(kBvhNoRoot);
    return w;
}

void setSlot(shader::WideBvhNode& w, int slot, const glm::vec3& lo, const glm::vec3& hi,
             uint32_t ref) {
    w.loX[slot] = lo.x;
    w.loY[slot] = lo.y;
    w.loZ[slot] = lo.z;
    w.hiX[slot] = hi.x;
    w.hiY[slot] = hi.y;
    w.hiZ[slot] = hi.z;
    w.child[slot] = ref;
}

// The reference to triangles [first, first + count) with box (lo, hi): one leaf reference, or,
// for a leaf larger than a reference holds (the depth cap can make one), nodes whose slots split
// the range, all with the leaf's box.
uint32_t leafReference(uint32_t first, uint32_t count, const glm::vec3& lo, const glm::vec3& hi,
                       std::vector<shader::WideBvhNode>& wide) {
    if (count <= PV_WIDE_LEAF_MAX_COUNT) return shader::wideLeafReference(first, count);
    const uint32_t index = uint32_t(wide.size());
    wide.push_back(emptyWideNode());
    const uint32_t part = (count + 3) / 4;
    shader::WideBvhNode w = emptyWideNode();
    int slot = 0;
    for (uint32_t begin = first; begin < first + count; begin += part) {
        uint32_t n = std::min(part, first + count - begin);
        setSlot(w, slot++, lo, hi, leafReference(begin, n, lo, hi, wide));
    }
    wide[index] = w;
    return index;
}

// Collapses the binary subtree at `node` into wide nodes appended to `wide` (Wald et al. 2008,
// "Getting Rid of Packets": open the child of largest surface area until four remain) and
// returns the index of its root. A binary leaf at the root becomes a node with one leaf child.
uint32_t collapseToWide(const std::vector<BvhNode>& binary, uint32_t node, uint32_t depth,
                        std::vector<shader::WideBvhNode>& wide, uint32_t& maxDepth) {
    maxDepth = std::max(maxDepth, depth);
    auto area = [&](uint32_t i) {
        Box b;
        b.lo = binary[i].boundsMin;
        b.hi = binary[i].boundsMax;
        return b.halfArea();
    };
    std::vector<uint32_t> slots;
    if (binary[node].count > 0) {
        slots = {node};
    } else {
        slots = {binary[node].leftOrFirst, binary[node].leftOrFirst + 1};
        while (slots.size() < 4) {
            int open = -1;
            for (size_t i = 0; i < slots.size(); ++i) {
                if (binary[slots[i]].count == 0 && (open < 0 || area(slots[i]) > area(slots[open])))
                    open = int(i);
            }
            if (open < 0) break;
            uint32_t left = binary[slots[open]].leftOrFirst;
            slots[open] = left;
            slots.push_back(left + 1);
        }
    }
    const uint32_t index = uint32_t(wide.size());
    wide.push_back(emptyWideNode());
    shader::WideBvhNode w = emptyWideNode();
    for (size_t i = 0; i < slots.size(); ++i) {
        const BvhNode& b = binary[slots[i]];
        uint32_t ref = b.count > 0
                           ? leafReference(b.leftOrFirst, b.count, b.boundsMin, b.boundsMax, wide)
                           : collapseToWide(binary, slots[i], depth + 1, wide, maxDepth);
        setSlot(w, int(i), b.boundsMin, b.boundsMax, ref);
    }
    wide[index] = w;  // after the recursion, which may have reallocated `wide`
    return index;
}

}  // namespace

Result<SceneBvh> buildSceneBvh(const Geometry& geometry, const BvhBuildOptions& options) {
    auto start = std::chrono::steady_clock::now();
    size_t triangleCount = geometry.triangles.size();
    if (triangleCount >= size_t(kBvhNoRoot) / 2)
        return makeError("scene has {} triangles; the BVH supports fewer than {}", triangleCount,
                         kBvhNoRoot / 2);
    if (!geometry.triangleIsReal.empty() && geometry.triangleIsReal.size() != triangleCount)
        return makeError("geometry has {} triangles but {} real/virtual flags", triangleCount,
                         geometry.triangleIsReal.size());
    if (options.maxLeafSize == 0) return makeError("BVH maxLeafSize must be at least 1");
    // A wide leaf reference keeps its first triangle in PV_WIDE_LEAF_FIRST_BITS bits.
    if (triangleCount > (size_t(1) << PV_WIDE_LEAF_FIRST_BITS))
        return makeError("scene has {} triangles; the BVH supports at most {}", triangleCount,
                         size_t(1) << PV_WIDE_LEAF_FIRST_BITS);

    // Real triangles first, then virtual: each tree owns one contiguous prim range.
    std::vector<PrimRef> prims(triangleCount);
    size_t realCount = 0;
    for (size_t i = 0; i < triangleCount; ++i)
        realCount += geometry.triangleIsReal.empty() ? 0 : (geometry.triangleIsReal[i] != 0);
    size_t nextReal = 0;
    size_t nextVirtual = realCount;
    for (size_t i = 0; i < triangleCount; ++i) {
        const glm::uvec3& t = geometry.triangles[i];
        PrimRef p;
        p.triangle = uint32_t(i);
        p.lo = glm::vec3(PV_FLOAT_MAX);
        p.hi = glm::vec3(-PV_FLOAT_MAX);
        for (int k = 0; k < 3; ++k) {
            if (t[k] >= geometry.positions.size())
                return makeError("triangle {} uses vertex {}, but there are only {} vertices", i,
                                 t[k], geometry.positions.size());
            glm::vec3 v = geometry.positions[t[k]];
            if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z))
                return makeError(
                    "triangle {} has a non-finite vertex {} ({}, {}, {}); the scene "
                    "loader should have rejected it",
                    i, t[k], v.x, v.y, v.z);
            p.lo = glm::min(p.lo, v);
            p.hi = glm::max(p.hi, v);
        }
        bool real = !geometry.triangleIsReal.empty() && geometry.triangleIsReal[i] != 0;
        prims[real ? nextReal++ : nextVirtual++] = p;
    }

    SceneBvh bvh;
    bvh.nodes.reserve(2 * triangleCount + 2);
    BuildStats stats;
    auto buildTree = [&](uint32_t begin, uint32_t end) {
        if (begin == end) return kBvhNoRoot;
        uint32_t root = uint32_t(bvh.nodes.size());
        bvh.nodes.emplace_back();
        Builder builder(prims, options, bvh.nodes);
        builder.build(root, begin, end, 0);
        stats.maxDepth = std::max(stats.maxDepth, builder.stats().maxDepth);
        stats.maxLeafSize = std::max(stats.maxLeafSize, builder.stats().maxLeafSize);
        return root;
    };
    bvh.realRoot = buildTree(0, uint32_t(realCount));
    bvh.virtualRoot = buildTree(uint32_t(realCount), uint32_t(triangleCount));

    bvh.triangleOrder.resize(triangleCount);
    for (size_t i = 0; i < triangleCount; ++i) bvh.triangleOrder[i] = prims[i].triangle;
    bvh.maxDepth = stats.maxDepth;
    bvh.maxLeafSize = stats.maxLeafSize;
    bvh.sahCost = bvhSahCost(bvh.nodes, bvh.realRoot) + bvhSahCost(bvh.nodes, bvh.virtualRoot);
    bvh.wideNodes.reserve(bvh.nodes.size() / 2 + 2);
    if (bvh.realRoot != kBvhNoRoot)
        bvh.wideRealRoot =
            collapseToWide(bvh.nodes, bvh.realRoot, 0, bvh.wideNodes, bvh.wideMaxDepth);
    if (bvh.virtualRoot != kBvhNoRoot)
        bvh.wideVirtualRoot =
            collapseToWide(bvh.nodes, bvh.virtualRoot, 0, bvh.wideNodes, bvh.wideMaxDepth);
    if (bvh.wideNodes.size() > kMaxWideNodes)
        return makeError("scene has {} triangles, which need {} BVH nodes; traversal supports {}",
                         triangleCount, bvh.wideNodes.size(), kMaxWideNodes);
    bvh.buildSeconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return bvh;
}

namespace {

struct RefitBox {
    glm::vec3 lo{PV_FLOAT_MAX};
    glm::vec3 hi{-PV_FLOAT_MAX};
};

// The box of the wide reference `ref` from the vertices, refitting the nodes below it.
RefitBox refitReference(SceneBvh& bvh, const std::vector<glm::vec4>& vertices, uint32_t ref,
                        uint32_t depth) {
    RefitBox box;
    if (ref & PV_WIDE_LEAF) {
        const uint32_t first = shader::wideLeafFirst(ref);
        const uint32_t count = shader::wideLeafCount(ref);
        for (uint32_t i = 3 * first; i < 3 * (first + count); ++i) {
            box.lo = glm::min(box.lo, glm::vec3(vertices[i]));
            box.hi = glm::max(box.hi, glm::vec3(vertices[i]));
        }
        return box;
    }
    PV_ASSERT(depth <= 4 * PV_BVH_STACK_SIZE);
    // Copy: the recursion writes other nodes of the same array.
    shader::WideBvhNode node = bvh.wideNodes[ref];
    for (int slot = 0; slot < 4; ++slot) {
        if (node.child[slot] == kBvhNoRoot) continue;
        const RefitBox child = refitReference(bvh, vertices, node.child[slot], depth + 1);
        setSlot(node, slot, child.lo, child.hi, node.child[slot]);
        box.lo = glm::min(box.lo, child.lo);
        box.hi = glm::max(box.hi, child.hi);
    }
    bvh.wideNodes[ref] = node;
    return box;
}

}  // namespace

void refitWideBvh(SceneBvh& bvh, const std::vector<glm::vec4>& triangleVertices) {
    PV_ASSERT(triangleVertices.size() == 3 * bvh.triangleOrder.size());
    for (uint32_t root : {bvh.wideRealRoot, bvh.wideVirtualRoot})
        if (root != kBvhNoRoot) refitReference(bvh, triangleVertices, root, 0);
}

}  // namespace previs
