#pragma once

// What previsd will need in memory, checked against the service's own limit before anything
// big is made: a scene or render size that would cross systemd's MemoryMax= is refused with one
// line at start (exit 2), instead of the kernel's OOM killer ending previsd mid-take over and
// over. The model is fitted to previsd's measured peak resident memory on lavapipe (device
// buffers are host memory there), bench/results/benchmarks_2026-12-05.md, "previsd in the field".

#include <cstdint>
#include <optional>
#include <string>

#include "base/result.h"

namespace previs {

struct Scene;
struct ServiceConfig;

// The bytes previsd's peak resident memory is estimated at for this scene and config: a fixed
// part (code, Mesa, OpenCV, the cameras' frames), a part per output pixel (film, denoiser, held
// view, display) and the scene's own arrays (each about three times: loaded, uploaded, BVH).
uint64_t estimatedServiceBytes(const Scene& scene, const ServiceConfig& config);

// The memory limit of this process's cgroup (cgroup v2 `memory.max`, as MemoryMax= sets it);
// none when unlimited or unreadable. `root` is where the file systems are mounted ("/" on a box;
// a folder laid out the same way in tests).
std::optional<uint64_t> cgroupMemoryLimit(const std::string& root = "/");

// An error naming the scene, the render size, the estimate and the limit, when the estimate
// exceeds `limit`.
Status checkMemoryBudget(const Scene& scene, const ServiceConfig& config,
                         std::optional<uint64_t> limit);

}  // namespace previs
