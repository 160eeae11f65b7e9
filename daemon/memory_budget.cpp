#include "daemon/memory_budget.h"

#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

#include "config/service_config.h"
#include "scene/scene.h"

namespace previs {

namespace {

// Fitted to previsd on the demo scene (bench/results/benchmarks_2026-12-05.md, "previsd in the
// field"): peak resident memory 480–520 MiB at 640×360 and 1.94–2.0 GiB at 1920×1080 on lavapipe,
// i.e. about 800 bytes a pixel over a fixed 340 MiB. Rounded up: the check refuses only what cannot
// fit.
constexpr uint64_t kFixedBytes = uint64_t(360) << 20;
constexpr uint64_t kBytesPerPixel = 850;
// Each array of the scene is held about three times at the peak: as loaded, as uploaded, and in
// the BVH's build.
constexpr uint64_t kSceneCopies = 3;

template <typename T>
uint64_t bytesOf(const std::vector<T>& v) {
    return uint64_t(v.size()) * sizeof(T);
}

uint64_t sceneBytes(const Scene& scene) {
    const Geometry& g = scene.geometry;
    uint64_t bytes = bytesOf(g.positions) + bytesOf(g.normals) + bytesOf(g.uvs) +
                     bytesOf(g.triangles) + bytesOf(g.triangleMaterials) +
                     bytesOf(g.triangleIsReal) +
                     // the BVH: about two nodes of 64 bytes a triangle
                     uint64_t(g.triangles.size()) * 128;
    for (const Texture& t : scene.textures) bytes += bytesOf(t.rgba8);
    if (scene.environment) bytes += bytesOf(scene.environment->radiance) * 2;  // + its sampler
    return bytes * kSceneCopies;
}

std::string mib(uint64_t bytes) { return std::to_string((bytes + (1 << 19)) >> 20) + " MiB"; }

// The output's size: [render]'s, else the scene camera's (the plate's).
std::pair<uint32_t, uint32_t> outputSize(const ServiceConfig& config) {
    if (config.render.width && config.render.height)
        return {config.render.width, config.render.height};
    return {config.sceneCamera.width, config.sceneCamera.height};
}

}  // namespace

uint64_t estimatedServiceBytes(const Scene& scene, const ServiceConfig& config) {
    const auto [width, height] = outputSize(config);
    const uint64_t pixels = uint64_t(width) * height;
    return kFixedBytes + pixels * kBytesPerPixel + sceneBytes(scene);
}

std::optional<uint64_t> cgroupMemoryLimit(const std::string& root) {
    // cgroup v2: /proc/self/cgroup is one line "0::/system.slice/previsd.service".
    std::ifstream self(root + "/proc/self/cgroup");
    std::string line, path;
    while (std::getline(self, line))
        if (line.rfind("0::", 0) == 0) path = line.substr(3);
    if (path.empty()) return std::nullopt;
    std::ifstream max(root + "/sys/fs/cgroup" + (path == "/" ? "" : path) + "/memory.max");
    std::string value;
    if (!(max >> value) || value == "max") return std::nullopt;
    std::istringstream in(value);
    uint64_t bytes = 0;
    if (!(in >> bytes) || bytes == 0) return std::nullopt;
    return bytes;
}

Status checkMemoryBudget(const Scene& scene, const ServiceConfig& config,
                         std::optional<uint64_t> limit) {
    if (!limit) return {};
    const uint64_t need = estimatedServiceBytes(scene, config);
    if (need <= *limit) return {};
    const auto [width, height] = outputSize(config);
    return makeError(
        "{}: scene {} at {}x{} needs about {} of memory, over this service's limit of {} "
        "(MemoryMax=): lower [render] width and height, simplify the scene, or raise MemoryMax= "
        "in a drop-in (docs/systemd.md)",
        config.path, scene.path, width, height, mib(need), mib(*limit));
}

}  // namespace previs
