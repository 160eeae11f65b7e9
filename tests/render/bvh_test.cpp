// The BVH builder and the shared ray casting of gpu/shaders/shared/ray_tracing.h, run on the CPU
// through CpuTracer: traversal against brute force, watertightness on shared edges and vertices,
// self-intersection avoidance at millimetre and kilometre scales, SAH quality and degenerate input.
#include "render/bvh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <map>
#include <optional>
#include <random>
#include <tuple>

#include "render/cpu_tracer.h"
#include "render/ply_reader.h"
#include "tests/support/test_data.h"

namespace previs::testing {
namespace {

using shader::Hit;
using shader::Ray;

// Ray counts: each brute-force comparison makes >= 100K traversal queries (rays x {mixed,
// real-only}) in optimised builds; debug and sanitizer builds make a tenth so the suite stays
// fast there.
#ifdef NDEBUG
constexpr int kRayScale = 10;
#else
constexpr int kRayScale = 1;
#endif

// Unoptimised (sanitizer) builds build the BVH ~30x slower: they use the smaller scans.
#ifdef NDEBUG
constexpr const char* kBunny = "stanford_bunny.ply";
constexpr const char* kDragon = "dragon_vrip_res2.ply";
#else
constexpr const char* kBunny = "bunny_npm.ply";
constexpr const char* kDragon = "dragon_vrip_res4.ply";
#endif

std::string meshPath(const char* name) { return testing::sharedDataDir() + "meshes/" + name; }

uint32_t floatBits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, 4);
    return u;
}

bool finite(glm::vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

glm::vec3 randomDirection(std::mt19937& rng) {
    std::normal_distribution<float> n;
    while (true) {
        glm::vec3 d(n(rng), n(rng), n(rng));
        float l = glm::length(d);
        if (l > 1e-3f) return d / l;
    }
}

Geometry makeGeometry(std::vector<glm::vec3> positions, std::vector<glm::uvec3> triangles,
                      std::vector<uint8_t> real = {}) {
    Geometry g;
    g.positions = std::move(positions);
    g.triangles = std::move(triangles);
    g.triangleMaterials.assign(g.triangles.size(), 0);
    g.triangleIsReal = real.empty() ? std::vector<uint8_t>(g.triangles.size(), 0) : real;
    return g;
}

// Random triangles in [center - scale, center + scale]^3, half of them real; a few slivers.
Geometry randomSoup(int count, float scale, glm::vec3 center, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    std::vector<glm::vec3> p;
    std::vector<glm::uvec3> t;
    std::vector<uint8_t> real;
    for (int i = 0; i < count; ++i) {
        glm::vec3 c = center + scale * glm::vec3(u(rng), u(rng), u(rng));
        float size = scale * 0.15f;
        uint32_t base = uint32_t(p.size());
        glm::vec3 a = c + size * glm::vec3(u(rng), u(rng), u(rng));
        glm::vec3 b = c + size * glm::vec3(u(rng), u(rng), u(rng));
        glm::vec3 d = i % 10 == 0 ? a + 1e-4f * (b - a) + size * 1e-6f * glm::vec3(0, 1, 0)
                                  : c + size * glm::vec3(u(rng), u(rng), u(rng));
        p.insert(p.end(), {a, b, d});
        t.push_back({base, base + 1, base + 2});
        real.push_back(uint8_t(i % 2));
    }
    return makeGeometry(p, t, real);
}

// Closest hit by testing every triangle with the same intersection function, in BVH order.
std::optional<Hit> bruteForce(const CpuTracer& tracer, const Ray& ray, bool realOnly) {
    shader::TriangleRay tr = shader::makeTriangleRay(ray.origin, ray.direction);
    std::optional<Hit> best;
    float tMax = ray.tMax;
    const auto& tris = tracer.triangles();
    const auto& pos = tracer.positions();
    for (uint32_t i = 0; i < tris.size(); ++i) {
        if (realOnly && !tracer.isReal(i)) continue;
        float t, b1, b2;
        if (shader::intersectTriangle(tr, pos[tris[i].x], pos[tris[i].y], pos[tris[i].z], ray.tMin,
                                      tMax, t, b1, b2)) {
            tMax = t;
            best = Hit{t, i, b1, b2};
        }
    }
    return best;
}

// Random rays about a box: origins around it, directions random, some axis-aligned with +-0
// components, some with a finite tMax.
std::vector<Ray> randomRays(int count, glm::vec3 lo, glm::vec3 hi, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    glm::vec3 c = 0.5f * (lo + hi);
    glm::vec3 e = hi - lo;
    std::vector<Ray> rays;
    for (int i = 0; i < count; ++i) {
        Ray r;
        r.origin = c + (glm::vec3(u(rng), u(rng), u(rng)) - 0.5f) * e * 1.6f;
        glm::vec3 target = lo + glm::vec3(u(rng), u(rng), u(rng)) * e;
        r.direction = i % 3 == 0 ? randomDirection(rng) : glm::normalize(target - r.origin);
        if (i % 17 == 0) {
            int axis = i % 3;
            float s = (i / 17) % 2 ? 1.0f : -1.0f;
            r.direction = glm::vec3((i / 34) % 2 ? -0.0f : 0.0f);
            r.direction[axis] = s;
        }
        r.tMin = 0.0f;
        r.tMax = i % 5 == 0 ? u(rng) * glm::length(e) : PV_FLOAT_MAX;
        rays.push_back(r);
    }
    return rays;
}

// Structural checks: triangleOrder is a permutation, children nest in parents, leaves' triangles
// lie in their boxes, each tree covers its contiguous range, depth fits the traversal stack.
// The 4-wide tree the shaders traverse: every triangle in exactly one leaf reference, inside its
// slot's box; every child node's boxes inside its slot's box; empty slots never entered; depth
// within the traversal stack.
void checkWideStructure(const SceneBvh& bvh, const Geometry& g) {
    const size_t n = g.triangles.size();
    std::vector<int> seen(n, 0);
    const glm::vec3 lowest(-PV_FLOAT_MAX);
    const glm::vec3 highest(PV_FLOAT_MAX);
    for (uint32_t root : {bvh.wideRealRoot, bvh.wideVirtualRoot}) {
        if (root == kBvhNoRoot) continue;
        struct Visit {
            uint32_t node;
            uint32_t depth;
            glm::vec3 lo;
            glm::vec3 hi;
        };
        std::vector<Visit> stack{{root, 0, lowest, highest}};
        while (!stack.empty()) {
            Visit v = stack.back();
            stack.pop_back();
            ASSERT_LT(v.node, bvh.wideNodes.size());
            ASSERT_LE(v.depth + 1, uint32_t(PV_BVH_STACK_SIZE));
            const shader::WideBvhNode& w = bvh.wideNodes[v.node];
            for (int i = 0; i < 4; ++i) {
                glm::vec3 lo(w.loX[i], w.loY[i], w.loZ[i]);
                glm::vec3 hi(w.hiX[i], w.hiY[i], w.hiZ[i]);
                uint32_t ref = w.child[i];
                if (ref == kBvhNoRoot) {
                    ASSERT_TRUE(glm::all(glm::greaterThan(lo, hi)))
                        << "empty slot must be inverted";
                    continue;
                }
                ASSERT_TRUE(glm::all(glm::lessThanEqual(v.lo, lo)));
                ASSERT_TRUE(glm::all(glm::lessThanEqual(hi, v.hi)));
                if ((ref & PV_WIDE_LEAF) == 0u) {
                    stack.push_back({ref, v.depth + 1, lo, hi});
                    continue;
                }
                uint32_t first = shader::wideLeafFirst(ref);
                uint32_t count = shader::wideLeafCount(ref);
                ASSERT_LE(first + count, n);
                for (uint32_t k = first; k < first + count; ++k) {
                    seen[k]++;
                    for (int c = 0; c < 3; ++c) {
                        glm::vec3 p = g.positions[g.triangles[bvh.triangleOrder[k]][c]];
                        ASSERT_TRUE(glm::all(glm::lessThanEqual(lo, p)));
                        ASSERT_TRUE(glm::all(glm::lessThanEqual(p, hi)));
                    }
                }
            }
        }
    }
    for (size_t k = 0; k < n; ++k) ASSERT_EQ(seen[k], 1) << "BVH-order triangle " << k;
}

void checkStructure(const SceneBvh& bvh, const Geometry& g) {
    size_t n = g.triangles.size();
    ASSERT_EQ(bvh.triangleOrder.size(), n);
    std::vector<int> seen(n, 0);
    for (uint32_t t : bvh.triangleOrder) {
        ASSERT_LT(t, n);
        seen[t]++;
    }
    for (size_t i = 0; i < n; ++i) {
        ASSERT_EQ(seen[i], 1) << "triangle " << i;
    }
    ASSERT_LE(bvh.maxDepth, uint32_t(PV_BVH_STACK_SIZE));
    size_t covered = 0;
    for (uint32_t root : {bvh.realRoot, bvh.virtualRoot}) {
        if (root == kBvhNoRoot) continue;
        std::vector<std::pair<uint32_t, uint32_t>> stack{{root, 0}};
        while (!stack.empty()) {
            auto [i, depth] = stack.back();
            stack.pop_back();
            ASSERT_LT(i, bvh.nodes.size());
            ASSERT_LE(depth, bvh.maxDepth);
            const shader::BvhNode& node = bvh.nodes[i];
            if (node.count > 0) {
                ASSERT_LE(node.count, bvh.maxLeafSize);
                for (uint32_t k = node.leftOrFirst; k < node.leftOrFirst + node.count; ++k) {
                    ASSERT_LT(k, n);
                    bool real = g.triangleIsReal[bvh.triangleOrder[k]] != 0;
                    ASSERT_EQ(real, root == bvh.realRoot);
                    for (int v = 0; v < 3; ++v) {
                        glm::vec3 p = g.positions[g.triangles[bvh.triangleOrder[k]][v]];
                        ASSERT_TRUE(glm::all(glm::lessThanEqual(node.boundsMin, p)));
                        ASSERT_TRUE(glm::all(glm::lessThanEqual(p, node.boundsMax)));
                    }
                }
                covered += node.count;
            } else {
                for (uint32_t c : {node.leftOrFirst, node.leftOrFirst + 1}) {
                    ASSERT_LT(c, bvh.nodes.size());
                    ASSERT_TRUE(
                        glm::all(glm::lessThanEqual(node.boundsMin, bvh.nodes[c].boundsMin)));
                    ASSERT_TRUE(
                        glm::all(glm::lessThanEqual(bvh.nodes[c].boundsMax, node.boundsMax)));
                    stack.push_back({c, depth + 1});
                }
            }
        }
    }
    ASSERT_EQ(covered, n);
    checkWideStructure(bvh, g);
}

// Traversal must give the brute-force answer bit for bit: same t, and the same triangle unless
// two triangles give that exact t (a ray through a shared edge), where either is right.
void expectMatchesBruteForce(const CpuTracer& tracer, const std::vector<Ray>& rays) {
    int hits[2] = {0, 0};
    for (size_t i = 0; i < rays.size(); ++i) {
        for (bool realOnly : {false, true}) {
            const Ray& r = rays[i];
            std::optional<Hit> a = tracer.closestHit(r, realOnly);
            std::optional<Hit> b = bruteForce(tracer, r, realOnly);
            ASSERT_EQ(a.has_value(), b.has_value()) << "ray " << i << " realOnly " << realOnly;
            ASSERT_EQ(tracer.occluded(r, realOnly), b.has_value()) << "ray " << i;
            if (!a) continue;
            hits[realOnly]++;
            ASSERT_EQ(floatBits(a->t), floatBits(b->t)) << "ray " << i << " realOnly " << realOnly;
            if (a->triangle != b->triangle) {
                Ray exact = r;
                exact.tMax = std::nextafter(b->t, PV_FLOAT_MAX);
                exact.tMin = std::nextafter(b->t, 0.0f);
                std::optional<Hit> other = bruteForce(tracer, exact, realOnly);
                ASSERT_TRUE(other.has_value());
                ASSERT_EQ(floatBits(other->t), floatBits(a->t));
            } else {
                ASSERT_EQ(floatBits(a->b1), floatBits(b->b1));
                ASSERT_EQ(floatBits(a->b2), floatBits(b->b2));
            }
            if (realOnly) {
                ASSERT_TRUE(tracer.isReal(a->triangle));
            }
        }
    }
    // The test means something only if many rays hit, in both modes.
    EXPECT_GT(hits[0], int(rays.size()) / 10);
    EXPECT_GT(hits[1], int(rays.size()) / 20);
}

TEST(BvhTraversal, MatchesBruteForceOnRandomSoup) {
    Geometry g = randomSoup(300, 1.0f, glm::vec3(0.0f), 1);
    auto tracer = CpuTracer::create(g);
    ASSERT_TRUE(tracer) << tracer.message();
    checkStructure(tracer->bvh(), g);
    expectMatchesBruteForce(*tracer,
                            randomRays(5000 * kRayScale, glm::vec3(-1.2f), glm::vec3(1.2f), 2));
}

TEST(BvhTraversal, MatchesBruteForceAtTinyAndHugeScales) {
    for (auto [scale, center] :
         {std::pair{1e-3f, glm::vec3(0.0f)}, std::pair{1e-3f, glm::vec3(0.5f, -2.0f, 1.0f)},
          std::pair{1e3f, glm::vec3(0.0f)}, std::pair{1e3f, glm::vec3(1e4f, 0.0f, -2e4f)}}) {
        SCOPED_TRACE(::testing::Message() << "scale " << scale << " center " << center.x);
        Geometry g = randomSoup(200, scale, center, 3);
        auto tracer = CpuTracer::create(g);
        ASSERT_TRUE(tracer) << tracer.message();
        checkStructure(tracer->bvh(), g);
        expectMatchesBruteForce(
            *tracer, randomRays(1000 * kRayScale, center - 1.2f * scale, center + 1.2f * scale, 4));
    }
}

// A real mesh, split into a real half (x < centre) and a virtual half.
TEST(BvhTraversal, MatchesBruteForceOnMesh) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    auto mesh = readPly(meshPath("suzanne_blender.ply"));
    ASSERT_TRUE(mesh) << mesh.message();
    Geometry g = makeGeometry(mesh->positions, mesh->triangles);
    glm::vec3 lo(PV_FLOAT_MAX), hi(-PV_FLOAT_MAX);
    for (glm::vec3 p : g.positions) {
        lo = glm::min(lo, p);
        hi = glm::max(hi, p);
    }
    for (size_t i = 0; i < g.triangles.size(); ++i)
        g.triangleIsReal[i] = g.positions[g.triangles[i].x].x < 0.5f * (lo.x + hi.x);
    auto tracer = CpuTracer::create(g);
    ASSERT_TRUE(tracer) << tracer.message();
    checkStructure(tracer->bvh(), g);
    expectMatchesBruteForce(*tracer, randomRays(5000 * kRayScale, lo, hi, 5));
}

// ---- Watertightness ----------------------------------------------------------------------

struct Mesh {
    std::vector<glm::vec3> positions;
    std::vector<glm::uvec3> triangles;
};

// Unit icosphere with shared (welded) vertices, `levels` times subdivided.
Mesh icosphere(int levels) {
    const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
    Mesh m;
    m.positions = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                   {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
    for (auto& p : m.positions) p = glm::normalize(p);
    m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                   {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                   {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                   {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
    for (int l = 0; l < levels; ++l) {
        std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
        auto midpoint = [&](uint32_t a, uint32_t b) {
            auto key = std::minmax(a, b);
            auto it = mid.find(key);
            if (it != mid.end()) return it->second;
            m.positions.push_back(glm::normalize(m.positions[a] + m.positions[b]));
            return mid[key] = uint32_t(m.positions.size() - 1);
        };
        std::vector<glm::uvec3> next;
        for (glm::uvec3 tri : m.triangles) {
            uint32_t a = midpoint(tri.x, tri.y), b = midpoint(tri.y, tri.z),
                     c = midpoint(tri.z, tri.x);
            next.insert(next.end(), {{tri.x, a, c}, {tri.y, b, a}, {tri.z, c, b}, {a, b, c}});
        }
        m.triangles = next;
    }
    return m;
}

// Axis-aligned cube [0, n]^3 in integer steps, each face an n x n grid of quads, welded.
Mesh gridCube(int n) {
    Mesh m;
    std::map<std::tuple<int, int, int>, uint32_t> index;
    auto vertex = [&](glm::ivec3 p) {
        auto key = std::make_tuple(p.x, p.y, p.z);
        auto it = index.find(key);
        if (it != index.end()) return it->second;
        m.positions.push_back(glm::vec3(p));
        return index[key] = uint32_t(m.positions.size() - 1);
    };
    for (int axis = 0; axis < 3; ++axis) {
        for (int side = 0; side < 2; ++side) {
            int u = (axis + 1) % 3, v = (axis + 2) % 3;
            for (int i = 0; i < n; ++i) {
                for (int j = 0; j < n; ++j) {
                    glm::ivec3 p[4];
                    for (int k = 0; k < 4; ++k) {
                        p[k][axis] = side * n;
                        p[k][u] = i + (k == 1 || k == 2);
                        p[k][v] = j + (k >= 2);
                    }
                    uint32_t a = vertex(p[0]), b = vertex(p[1]), c = vertex(p[2]), d = vertex(p[3]);
                    // Alternate the diagonal so edges run both ways.
                    if ((i + j) % 2) {
                        m.triangles.push_back({a, b, c});
                        m.triangles.push_back({a, c, d});
                    } else {
                        m.triangles.push_back({a, b, d});
                        m.triangles.push_back({b, c, d});
                    }
                }
            }
        }
    }
    return m;
}

// Targets: every vertex and the midpoint of every edge, in float.
std::vector<glm::vec3> edgeAndVertexTargets(const std::vector<glm::vec3>& p,
                                            const std::vector<glm::uvec3>& tris) {
    std::vector<glm::vec3> targets = p;
    std::map<std::pair<uint32_t, uint32_t>, bool> done;
    for (glm::uvec3 t : tris) {
        for (int k = 0; k < 3; ++k) {
            auto key = std::minmax(t[k], t[(k + 1) % 3]);
            if (done[key]) continue;
            done[key] = true;
            targets.push_back(0.5f * (p[key.first] + p[key.second]));
        }
    }
    return targets;
}

// Outward normals of the faces around each vertex and each edge of a convex mesh centred at
// `center`, in the order of edgeAndVertexTargets: a ray pierces the surface there (rather than
// touching a silhouette vertex or edge) when its direction enters every one of them.
std::vector<std::vector<glm::vec3>> incidentNormals(const std::vector<glm::vec3>& p,
                                                    const std::vector<glm::uvec3>& tris,
                                                    glm::vec3 center) {
    std::vector<std::vector<glm::vec3>> vertexNormals(p.size());
    std::map<std::pair<uint32_t, uint32_t>, std::vector<glm::vec3>> edgeNormals;
    std::vector<std::pair<uint32_t, uint32_t>> edgeOrder;
    for (glm::uvec3 t : tris) {
        glm::vec3 n = glm::normalize(glm::cross(p[t.y] - p[t.x], p[t.z] - p[t.x]));
        if (glm::dot(n, p[t.x] - center) < 0.0f) n = -n;
        for (int k = 0; k < 3; ++k) {
            vertexNormals[t[k]].push_back(n);
            auto key = std::minmax(t[k], t[(k + 1) % 3]);
            if (edgeNormals.find(key) == edgeNormals.end()) edgeOrder.push_back(key);
            edgeNormals[key].push_back(n);
        }
    }
    for (const auto& key : edgeOrder) vertexNormals.push_back(edgeNormals[key]);
    return vertexNormals;
}

// Rays from outside through every edge midpoint and vertex of an icosphere must hit at or before
// the target, at several scales. Directions enter every face around the target (by a margin),
// so each ray pierces the surface there instead of grazing a silhouette vertex.
TEST(Watertight, IcosphereEdgesAndVertices) {
    Mesh m = icosphere(3);
    std::mt19937 rng(7);
    int rays = 0;
    for (auto [scale, offset] :
         {std::pair{1.0f, glm::vec3(0.0f)}, std::pair{1e-3f, glm::vec3(0.003f, -0.001f, 0.002f)},
          std::pair{1e3f, glm::vec3(1e4f, 2e3f, -5e3f)}}) {
        std::vector<glm::vec3> p;
        for (glm::vec3 v : m.positions) p.push_back(offset + scale * v);
        Geometry g = makeGeometry(p, m.triangles);
        auto tracer = CpuTracer::create(g);
        ASSERT_TRUE(tracer) << tracer.message();
        std::vector<glm::vec3> targets = edgeAndVertexTargets(p, m.triangles);
        std::vector<std::vector<glm::vec3>> normals =
            incidentNormals(m.positions, m.triangles, glm::vec3(0.0f));
        ASSERT_EQ(normals.size(), targets.size());
        int perTarget = 4 * kRayScale;
        for (size_t i = 0; i < targets.size(); ++i) {
            for (int k = 0; k < perTarget; ++k) {
                glm::vec3 u = randomDirection(rng);
                bool enters = true;
                for (glm::vec3 n : normals[i]) enters &= glm::dot(u, n) > 0.02f;
                if (!enters) u = -u;
                enters = true;
                for (glm::vec3 n : normals[i]) enters &= glm::dot(u, n) > 0.02f;
                if (!enters) continue;
                Ray r;
                r.origin = targets[i] + 3.0f * scale * u;
                r.direction = targets[i] - r.origin;  // t = 1 at the target
                r.tMin = 0.0f;
                r.tMax = PV_FLOAT_MAX;
                auto hit = tracer->closestHit(r);
                ASSERT_TRUE(hit.has_value())
                    << "scale " << scale << " target " << i << " ray " << k;
                ASSERT_LE(hit->t, 1.0f + 1e-4f);
                ASSERT_TRUE(tracer->occluded(r));
                ++rays;
            }
        }
    }
    EXPECT_GT(rays, 1000);
}

// The grid cube's edges are axis-aligned and its leaf boxes flat: rays through its vertices and
// edge midpoints, from random outside directions and exactly along the axes (zero and -0
// direction components), must hit. Tests the box test's robustness as much as the triangles'.
TEST(Watertight, GridCubeEdgesAndVerticesIncludingAxisAlignedRays) {
    const int n = 6;
    Mesh m = gridCube(n);
    std::mt19937 rng(8);
    for (auto [scale, offset] :
         {std::pair{1.0f, glm::vec3(0.0f)}, std::pair{1e-3f / n, glm::vec3(-0.01f, 0.02f, 0.0f)},
          std::pair{1e3f / n, glm::vec3(1e4f, 0.0f, 3e3f)}}) {
        std::vector<glm::vec3> p;
        for (glm::vec3 v : m.positions) p.push_back(offset + scale * v);
        Geometry g = makeGeometry(p, m.triangles);
        auto tracer = CpuTracer::create(g);
        ASSERT_TRUE(tracer) << tracer.message();
        std::vector<glm::vec3> gridTargets = edgeAndVertexTargets(m.positions, m.triangles);
        for (size_t i = 0; i < gridTargets.size(); ++i) {
            glm::vec3 q = gridTargets[i];  // in grid units: which faces it lies on
            glm::vec3 target = offset + scale * q;
            std::vector<glm::vec3> normals;
            for (int a = 0; a < 3; ++a) {
                glm::vec3 nrm(0.0f);
                if (q[a] == 0.0f) nrm[a] = -1.0f;
                if (q[a] == float(n)) nrm[a] = 1.0f;
                if (nrm[a] != 0.0f) normals.push_back(nrm);
            }
            std::vector<glm::vec3> dirs = normals;  // exactly axis-aligned
            for (int k = 0; k < 2 * kRayScale; ++k) {
                glm::vec3 u = randomDirection(rng);
                bool outside = true;
                for (glm::vec3 nrm : normals) outside &= glm::dot(u, nrm) > 0.05f;
                if (outside) dirs.push_back(u);
            }
            for (glm::vec3 u : dirs) {
                Ray r;
                r.origin = target + 2.0f * float(n) * scale * u;
                r.direction = -u;
                r.tMin = 0.0f;
                r.tMax = PV_FLOAT_MAX;
                ASSERT_TRUE(tracer->closestHit(r).has_value())
                    << "scale " << scale << " target (" << q.x << "," << q.y << "," << q.z << ")";
                ASSERT_TRUE(tracer->occluded(r));
            }
        }
    }
}

// ---- Self-intersection ---------------------------------------------------------------------

// From hit points on spheres of 1 mm and 1 km (near and far from the origin), offset rays leave
// outward without any hit (the mesh is convex), go inward to another triangle, and grazing or
// exactly tangent rays give finite origins and never hit their own triangle.
TEST(OffsetRayOrigin, NoSelfIntersectionAtAnyScale) {
    Mesh m = icosphere(3);
    std::mt19937 rng(9);
    for (auto [radius, center] :
         {std::pair{0.5e-3f, glm::vec3(0.0f)}, std::pair{0.5e-3f, glm::vec3(1.0f, -2.0f, 0.5f)},
          std::pair{500.0f, glm::vec3(0.0f)}, std::pair{500.0f, glm::vec3(1e4f, -1e4f, 1e4f)}}) {
        SCOPED_TRACE(::testing::Message() << "radius " << radius << " center " << center.x);
        std::vector<glm::vec3> p;
        for (glm::vec3 v : m.positions) p.push_back(center + radius * v);
        Geometry g = makeGeometry(p, m.triangles);
        auto tracer = CpuTracer::create(g);
        ASSERT_TRUE(tracer) << tracer.message();
        int inwardHits = 0;
        int trials = 200 * kRayScale;
        for (int i = 0; i < trials; ++i) {
            Ray r;
            r.origin = center + 3.0f * radius * randomDirection(rng);
            r.direction = center + 0.9f * radius * randomDirection(rng) - r.origin;
            r.tMin = 0.0f;
            r.tMax = PV_FLOAT_MAX;
            auto hit = tracer->closestHit(r);
            ASSERT_TRUE(hit);
            glm::uvec3 tri = tracer->triangles()[hit->triangle];
            glm::vec3 v0 = p[tri.x], v1 = p[tri.y], v2 = p[tri.z];
            glm::vec3 x = (1.0f - hit->b1 - hit->b2) * v0 + hit->b1 * v1 + hit->b2 * v2;
            glm::vec3 n = glm::normalize(glm::cross(v1 - v0, v2 - v0));
            if (glm::dot(n, x - center) < 0.0f) n = -n;
            glm::vec3 tangent = glm::normalize(glm::cross(n, randomDirection(rng)));

            // Outward, from steep to exactly tangent: nothing to hit on a convex mesh.
            for (float lift : {1.0f, 0.1f, 1e-3f, 1e-6f, 0.0f}) {
                Ray out;
                out.origin = shader::offsetRayOrigin(x, n);
                out.direction = glm::normalize(tangent + lift * n);
                out.tMin = 0.0f;
                out.tMax = PV_FLOAT_MAX;
                ASSERT_TRUE(finite(out.origin));
                auto again = tracer->closestHit(out);
                ASSERT_FALSE(again.has_value())
                    << "outward ray re-hit triangle " << again->triangle << " lift " << lift;
            }
            // Inward, from steep to grazing: hits another triangle, never its own.
            for (float dip : {PV_FLOAT_MAX, 1.0f, 0.1f, 1e-3f, 1e-6f}) {
                Ray in;
                in.origin = shader::offsetRayOrigin(x, -n);
                in.direction = dip == PV_FLOAT_MAX ? -n : glm::normalize(tangent - dip * n);
                in.tMin = 0.0f;
                in.tMax = PV_FLOAT_MAX;
                ASSERT_TRUE(finite(in.origin));
                auto inside = tracer->closestHit(in);
                if (dip >= 1.0f) {
                    ASSERT_TRUE(inside.has_value()) << "ray into the object escaped, dip " << dip;
                    // The far side: a diameter away straight in, a chord of 2r·cos45° at 45°
                    // (less the tessellation's inset).
                    EXPECT_GT(inside->t, radius * (dip == 1.0f ? 1.2f : 1.8f));
                    inwardHits += dip > 1.0f;
                }
                if (inside) {
                    ASSERT_NE(inside->triangle, hit->triangle) << "self-hit, dip " << dip;
                }
            }
        }
        EXPECT_EQ(inwardHits, trials);
    }
}

// ---- SAH quality, build time -------------------------------------------------------------

double oneLeafCost(size_t triangles) { return double(triangles); }

// A scan of the shared data as geometry (*g) and its SAH BVH (*bvh), whose structure is checked.
void buildScanBvh(const char* scan, Geometry* g, std::optional<SceneBvh>* bvh) {
    auto mesh = readPly(meshPath(scan));
    ASSERT_TRUE(mesh) << mesh.message();
    *g = makeGeometry(mesh->positions, mesh->triangles);
    auto built = buildSceneBvh(*g);
    ASSERT_TRUE(built) << built.message();
    checkStructure(*built, *g);
    *bvh = std::move(*built);
}

TEST(BvhBuild, SahBeatsMedianAndOneLeafOnBunny) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    Geometry g;
    std::optional<SceneBvh> sah;
    ASSERT_NO_FATAL_FAILURE(buildScanBvh(kBunny, &g, &sah));
    BvhBuildOptions medianOptions;
    medianOptions.split = BvhSplit::Median;
    auto median = buildSceneBvh(g, medianOptions);
    ASSERT_TRUE(median) << median.message();
    checkStructure(*median, g);
    RecordProperty("sah_cost", std::to_string(sah->sahCost));
    RecordProperty("median_cost", std::to_string(median->sahCost));
    std::printf(
        "%s (%zu triangles): SAH cost %.2f (median split %.2f, one leaf %.0f), depth %u, "
        "largest leaf %u, %zu nodes, built in %.3f s\n",
        kBunny, g.triangles.size(), sah->sahCost, median->sahCost, oneLeafCost(g.triangles.size()),
        sah->maxDepth, sah->maxLeafSize, sah->nodes.size(), sah->buildSeconds);
    EXPECT_LT(sah->sahCost, median->sahCost);
    EXPECT_LT(sah->sahCost, oneLeafCost(g.triangles.size()));
    EXPECT_LE(sah->maxDepth, uint32_t(PV_BVH_STACK_SIZE));
    EXPECT_EQ(sah->realRoot, kBvhNoRoot);
    EXPECT_NE(sah->virtualRoot, kBvhNoRoot);
}

TEST(BvhBuild, DragonBuildTime) {
    PREVIS_SKIP_WITHOUT_SHARED_DATA();
    Geometry g;
    std::optional<SceneBvh> bvh;
    ASSERT_NO_FATAL_FAILURE(buildScanBvh(kDragon, &g, &bvh));
    std::printf(
        "%s (%zu triangles): SAH cost %.2f, depth %u, largest leaf %u, "
        "built in %.3f s\n",
        kDragon, g.triangles.size(), bvh->sahCost, bvh->maxDepth, bvh->maxLeafSize,
        bvh->buildSeconds);
    RecordProperty("build_seconds", std::to_string(bvh->buildSeconds));
#ifdef NDEBUG
    EXPECT_LT(bvh->buildSeconds, 2.0);
#endif
}

// 1M triangles: run with --gtest_also_run_disabled_tests (a few seconds; kept out of the suite).
TEST(BvhBuild, DISABLED_MillionTriangles) {
    Geometry g = randomSoup(1000000, 10.0f, glm::vec3(0.0f), 11);
    auto bvh = buildSceneBvh(g);
    ASSERT_TRUE(bvh) << bvh.message();
    std::printf("1M-triangle soup: SAH cost %.2f, depth %u, built in %.3f s\n", bvh->sahCost,
                bvh->maxDepth, bvh->buildSeconds);
}

// ---- Degenerate input --------------------------------------------------------------------

Ray rayAlong(glm::vec3 origin, glm::vec3 direction) {
    Ray r;
    r.origin = origin;
    r.direction = direction;
    r.tMin = 0.0f;
    r.tMax = PV_FLOAT_MAX;
    return r;
}

TEST(BvhDegenerate, NoTriangles) {
    auto tracer = CpuTracer::create(Geometry{});
    ASSERT_TRUE(tracer) << tracer.message();
    EXPECT_EQ(tracer->bvh().realRoot, kBvhNoRoot);
    EXPECT_EQ(tracer->bvh().virtualRoot, kBvhNoRoot);
    EXPECT_TRUE(tracer->bvh().nodes.empty());
    EXPECT_EQ(tracer->bvh().sahCost, 0.0);
    EXPECT_FALSE(tracer->closestHit(rayAlong(glm::vec3(0.0f), glm::vec3(0, 0, 1))));
    EXPECT_FALSE(tracer->occluded(rayAlong(glm::vec3(0.0f), glm::vec3(0, 0, 1))));
}

TEST(BvhDegenerate, OneTriangleRealAndVirtual) {
    for (uint8_t real : {uint8_t(0), uint8_t(1)}) {
        Geometry g = makeGeometry({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}}, {real});
        auto tracer = CpuTracer::create(g);
        ASSERT_TRUE(tracer) << tracer.message();
        checkStructure(tracer->bvh(), g);
        Ray r = rayAlong(glm::vec3(0.25f, 0.25f, 1.0f), glm::vec3(0, 0, -1));
        auto hit = tracer->closestHit(r);
        ASSERT_TRUE(hit);
        EXPECT_EQ(hit->t, 1.0f);
        EXPECT_FLOAT_EQ(hit->b1, 0.25f);
        EXPECT_FLOAT_EQ(hit->b2, 0.25f);
        EXPECT_EQ(tracer->closestHit(r, true).has_value(), real != 0);
        EXPECT_EQ(tracer->occluded(r, true), real != 0);
        r.tMax = 0.5f;
        EXPECT_FALSE(tracer->closestHit(r));
        EXPECT_FALSE(tracer->occluded(r));
    }
}

TEST(BvhDegenerate, AllTrianglesAtOnePoint) {
    std::vector<glm::vec3> p(3000, glm::vec3(0.5f, -0.25f, 2.0f));
    std::vector<glm::uvec3> t;
    for (uint32_t i = 0; i < 1000; ++i) t.push_back({3 * i, 3 * i + 1, 3 * i + 2});
    Geometry g = makeGeometry(p, t);
    auto tracer = CpuTracer::create(g);
    ASSERT_TRUE(tracer) << tracer.message();
    checkStructure(tracer->bvh(), g);
    EXPECT_LE(tracer->bvh().maxLeafSize, BvhBuildOptions{}.maxLeafSize);
    EXPECT_TRUE(std::isfinite(tracer->bvh().sahCost));
    EXPECT_FALSE(tracer->closestHit(rayAlong(glm::vec3(0.5f, -0.25f, 0.0f), glm::vec3(0, 0, 1))));
}

// A leaf larger than one wide reference holds (128 triangles; the depth cap can force one) is split
// across several references with the leaf's box, and traversal still finds the nearest copy.
TEST(BvhWide, LeavesLargerThanAReferenceAreSplit) {
    std::vector<glm::vec3> p;
    std::vector<glm::uvec3> t;
    // 1000 copies of one triangle, each a little further along +z: no centroid split separates
    // them along x or y, so with a large leaf size they stay one leaf.
    for (uint32_t i = 0; i < 1000; ++i) {
        float z = 2.0f + 1e-3f * float((i * 7919u) % 1000u);
        p.push_back({-1.0f, -1.0f, z});
        p.push_back({1.0f, -1.0f, z});
        p.push_back({0.0f, 1.0f, z});
        t.push_back({3 * i, 3 * i + 1, 3 * i + 2});
    }
    Geometry g = makeGeometry(p, t);
    BvhBuildOptions options;
    options.split = BvhSplit::Median;
    options.maxLeafSize = 1000;
    auto tracer = CpuTracer::create(g, options);
    ASSERT_TRUE(tracer) << tracer.message();
    checkStructure(tracer->bvh(), g);
    EXPECT_GT(tracer->bvh().maxLeafSize, PV_WIDE_LEAF_MAX_COUNT);
    auto hit = tracer->closestHit(rayAlong(glm::vec3(0.0f, 0.0f, 0.0f), glm::vec3(0, 0, 1)));
    ASSERT_TRUE(hit);
    EXPECT_FLOAT_EQ(hit->t, 2.0f);
    EXPECT_TRUE(tracer->occluded(rayAlong(glm::vec3(0.0f, 0.0f, 0.0f), glm::vec3(0, 0, 1))));
}

// Flat (zero-thickness) boxes and needle triangles, nearly coplanar: traversal finds the
// brute-force hit up to ties within rounding.
TEST(BvhDegenerate, SliversAndFlatBoxes) {
    std::vector<glm::vec3> p;
    std::vector<glm::uvec3> t;
    std::mt19937 rng(12);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    for (uint32_t i = 0; i < 200; ++i) {
        glm::vec3 a(u(rng), u(rng), 0.0f);
        glm::vec3 b = a + glm::vec3(u(rng), u(rng), 0.0f);
        glm::vec3 c = i % 2 ? a + (b - a) * 0.5f + glm::vec3(0.0f, 0.0f, 1e-6f)  // needle
                            : glm::vec3(u(rng), a.y, 0.0f);                      // flat box
        p.insert(p.end(), {a, b, c});
        t.push_back({3 * i, 3 * i + 1, 3 * i + 2});
    }
    Geometry g = makeGeometry(p, t);
    for (size_t i = 0; i < t.size(); ++i) g.triangleIsReal[i] = i % 3 == 0;
    auto tracer = CpuTracer::create(g);
    ASSERT_TRUE(tracer) << tracer.message();
    checkStructure(tracer->bvh(), g);
    std::vector<Ray> rays =
        randomRays(2000 * kRayScale, glm::vec3(-2, -2, -0.5f), glm::vec3(2, 2, 0.5f), 13);
    int hits = 0;
    for (const Ray& r : rays) {
        for (bool realOnly : {false, true}) {
            auto a = tracer->closestHit(r, realOnly);
            auto b = bruteForce(*tracer, r, realOnly);
            ASSERT_EQ(a.has_value(), b.has_value());
            if (a) {
                // All triangles lie within 1e-6 of z = 0, so many give nearly the same t; the
                // slab test may cull a box whose triangle is closer by a few ULPs only.
                ASSERT_NEAR(a->t, b->t, 1e-5f * b->t);
                ++hits;
            }
        }
    }
    EXPECT_GT(hits, 0);
}

TEST(BvhDegenerate, BadInputIsAnErrorNotACrash) {
    Geometry nan = makeGeometry({{0, 0, 0}, {1, 0, 0}, {0, NAN, 0}}, {{0, 1, 2}});
    auto a = buildSceneBvh(nan);
    ASSERT_FALSE(a);
    EXPECT_NE(a.message().find("non-finite"), std::string::npos) << a.message();

    Geometry inf = makeGeometry({{0, 0, 0}, {INFINITY, 0, 0}, {0, 1, 0}}, {{0, 1, 2}});
    EXPECT_FALSE(buildSceneBvh(inf));

    Geometry range = makeGeometry({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 3}});
    auto b = buildSceneBvh(range);
    ASSERT_FALSE(b);
    EXPECT_NE(b.message().find("vertex 3"), std::string::npos) << b.message();

    Geometry flags = makeGeometry({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}});
    flags.triangleIsReal = {1, 0};
    EXPECT_FALSE(buildSceneBvh(flags));
}

// ---- The intersection primitives themselves ------------------------------------------------

TEST(Intersection, BoxTestHandlesZeroAndNegativeZeroDirections) {
    glm::vec3 lo(0.0f), hi(1.0f);
    for (float zero : {0.0f, -0.0f}) {
        glm::vec3 d(zero, zero, 1.0f);
        glm::vec3 inv = 1.0f / d;
        float t;
        // Inside the slab, on its boundary planes, and outside.
        EXPECT_TRUE(
            shader::intersectBox(lo, hi, glm::vec3(0.5f, 0.5f, -1.0f), inv, 0.0f, 10.0f, t));
        EXPECT_TRUE(
            shader::intersectBox(lo, hi, glm::vec3(0.0f, 1.0f, -1.0f), inv, 0.0f, 10.0f, t));
        EXPECT_TRUE(
            shader::intersectBox(lo, hi, glm::vec3(1.0f, 0.0f, -1.0f), inv, 0.0f, 10.0f, t));
        EXPECT_FALSE(
            shader::intersectBox(lo, hi, glm::vec3(1.5f, 0.5f, -1.0f), inv, 0.0f, 10.0f, t));
        EXPECT_FALSE(
            shader::intersectBox(lo, hi, glm::vec3(-0.5f, 0.5f, -1.0f), inv, 0.0f, 10.0f, t));
        // A flat box (zero thickness along the ray) is still hit.
        EXPECT_TRUE(shader::intersectBox(glm::vec3(0, 0, 2), glm::vec3(1, 1, 2),
                                         glm::vec3(0.5f, 0.5f, 0.0f), inv, 0.0f, 10.0f, t));
        EXPECT_EQ(t, 2.0f);
    }
}

TEST(Intersection, TriangleHitsOnEdgesAndVerticesAndMissesInPlane) {
    glm::vec3 v0(0, 0, 0), v1(1, 0, 0), v2(0, 1, 0);
    auto test = [&](glm::vec3 o, glm::vec3 d) {
        float t, b1, b2;
        return shader::intersectTriangle(shader::makeTriangleRay(o, d), v0, v1, v2, 0.0f,
                                         PV_FLOAT_MAX, t, b1, b2);
    };
    EXPECT_TRUE(test(glm::vec3(0.5f, 0.0f, 1.0f), glm::vec3(0, 0, -1)));   // on edge 01
    EXPECT_TRUE(test(glm::vec3(0.5f, 0.5f, 1.0f), glm::vec3(0, 0, -1)));   // on edge 12
    EXPECT_TRUE(test(glm::vec3(0.0f, 0.0f, 1.0f), glm::vec3(0, 0, -1)));   // vertex
    EXPECT_TRUE(test(glm::vec3(0.2f, 0.2f, -1.0f), glm::vec3(0, 0, 1)));   // back face
    EXPECT_FALSE(test(glm::vec3(-2.0f, 0.2f, 0.0f), glm::vec3(1, 0, 0)));  // in its plane
    EXPECT_FALSE(test(glm::vec3(0.2f, 0.2f, 1.0f), glm::vec3(0, 0, 1)));   // behind
    EXPECT_FALSE(test(glm::vec3(0.2f, 0.2f, 1.0f), glm::vec3(0.0f)));      // no direction
}

}  // namespace
}  // namespace previs::testing
