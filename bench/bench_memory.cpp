#include "bench/bench_memory.h"

#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <fstream>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/bench_scenes.h"
#include "bench/bench_stats.h"
#include "gpu/context.h"
#include "render/renderer.h"

namespace previs::bench {

namespace {

double mib(double bytes) { return bytes / (1024.0 * 1024.0); }

// Resident set now (not the peak), from /proc/self/statm's second field (pages).
double currentRssMiB() {
    std::ifstream statm("/proc/self/statm");
    size_t sizePages = 0, residentPages = 0;
    statm >> sizePages >> residentPages;
    return mib(double(residentPages) * double(sysconf(_SC_PAGESIZE)));
}

// A few preview frames as the shipped configs run them: half resolution, accumulated through
// the denoiser's temporal stage, the held view on, each finished on the device.
Status previewAsShipped(Renderer& r, uint32_t width, uint32_t height) {
    ImageF plate;
    plate.width = width;
    plate.height = height;
    plate.channels = 3;
    plate.pixels.assign(size_t(plate.width) * plate.height * 3, 0.18f);
    if (Status s = r.film().setPlate(std::move(plate), "bench plate"); !s) return s;
    if (Status s = r.setResolutionScale(0.5f); !s) return s;
    r.film().setTemporalDenoise(true);
    for (uint64_t frame = 1; frame <= 3; ++frame) {
        if (Status s = r.holdView(true); !s) return s;
        if (Status s = r.renderPreviewFrame(1, frame); !s) return s;
        if (Result<DisplayImage> shown = r.display(true, {}); !shown) return shown.error();
    }
    return {};
}

// One resolution, in the forked child: prints its table row, returns the exit code.
int measureOne(const MemoryBenchOptions& o, uint32_t width, uint32_t height) {
    const double baseline = currentRssMiB();
    auto ctx = GpuContext::create({});
    if (!ctx) {
        logError("{}", ctx.message());
        return 1;
    }
    const std::string env = o.dataDir + "/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr";
    const double beforeScene = currentRssMiB();
    Scene scene;
    {
        auto dragon = readPly(o.dataDir + "/meshes/dragon_vrip_res2.ply");
        if (!dragon) {
            logError("{}", dragon.message());
            return 1;
        }
        scene = meshOnPlaneScene(subdivide(*dragon), env, 0.3f);
    }
    const double sceneMiB = currentRssMiB() - beforeScene;
    RenderSettings rs;
    rs.width = width;
    rs.height = height;
    rs.maxDepth = 8;
    // The preview as shipped keeps the denoiser (its temporal history), the held view and the
    // display pass: created here so their memory is in the figures.
    rs.denoise = true;
    auto renderer = Renderer::create(**ctx, scene, rs);
    if (!renderer) {
        logError("{}", renderer.message());
        return 1;
    }
    if (Status s = (*renderer)->render(o.spp); !s) {
        logError("{}", s.message());
        return 1;
    }
    auto image = (*renderer)->image();  // a readback's staging buffer counts too
    if (!image) {
        logError("{}", image.message());
        return 1;
    }
    const uint64_t refineBytes = (*renderer)->deviceBytes();
    if (Status s = previewAsShipped(**renderer, width, height); !s) {
        logError("{}", s.message());
        return 1;
    }
    std::printf("| %u×%u | %zu | %.0f MiB | %.0f MiB | %.0f MiB | %.0f MiB | %.0f MiB |\n", width,
                height, scene.geometry.triangles.size(), mib(double(refineBytes)),
                mib(double((*renderer)->deviceBytes())), sceneMiB, peakRssMiB(), baseline);
    std::fflush(stdout);
    return 0;
}

}  // namespace

int runMemoryBench(const MemoryBenchOptions& o) {
    std::printf(
        "## Memory: the 810K-triangle scene (dragon ×4), environment map, max depth 8, "
        "%u spp, then 3 preview frames as shipped (half resolution, temporal accumulation, "
        "the held view, the display pass)\n\n"
        "| resolution | triangles | device buffers (refinement) | device buffers (preview) | "
        "host scene | peak RSS | RSS at start |\n"
        "|---|---|---|---|---|---|---|\n",
        o.spp);
    for (auto [w, h] : {std::pair{640u, 480u}, {1920u, 1080u}}) {
        benchProgress("memory {}x{} (forked child)", w, h);
        std::fflush(stdout);
        std::fflush(stderr);
        const pid_t pid = ::fork();
        if (pid < 0) {
            logError("bench memory: fork failed");
            return 1;
        }
        if (pid == 0) {
            ::prctl(PR_SET_PDEATHSIG, SIGKILL);
            ::_exit(measureOne(o, w, h));
        }
        int status = 0;
        if (::waitpid(pid, &status, 0) < 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) {
            logError("bench memory: the run at {}x{} failed (see above)", w, h);
            return 1;
        }
    }
    std::printf(
        "\nDevice buffers: Renderer::deviceBytes(), every buffer the renderer keeps "
        "(scene, BVH, accumulation, lighting, the held view, the denoiser with its history, "
        "the display pass), not the transient staging copies. Host "
        "scene: the resident growth while the CPU scene (vertices, triangles, the map) was "
        "built. Peak RSS: the whole child process's maximum, which on a CPU Vulkan device "
        "(lavapipe) includes the device buffers, the staging copies and the JIT-compiled "
        "pipeline; on a GPU the device buffers would live in video memory instead.\n\n");
    return 0;
}

}  // namespace previs::bench
