#include "bench/bench_service.h"

#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <optional>
#include <thread>
#include <type_traits>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/bench_stats.h"
#include "capture/recorded_source.h"
#include "config/service_config.h"
#include "daemon/service.h"
#include "display/compose.h"
#include "display/files_output.h"
#include "gpu/context.h"
#include "scene/scene_description.h"
#include "shot/pipeline_renderer.h"
#include "shot/pipeline_stages.h"
#include "shot/shot_controller.h"

namespace previs::bench {

namespace {

namespace fs = std::filesystem;

// Median and 90th percentile (nearest rank) of a sample.
struct Stat {
    double median = NAN;
    double p90 = NAN;
    uint32_t n = 0;
};

Stat stat(std::vector<double> v) {
    Stat s;
    s.n = uint32_t(v.size());
    if (v.empty()) return s;
    std::sort(v.begin(), v.end());
    const size_t n = v.size();
    s.median = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
    s.p90 = v[size_t(std::ceil(0.9 * double(n))) - 1];
    return s;
}

double vmRssMiB() {
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("VmRSS:", 0) == 0) return std::strtod(line.c_str() + 6, nullptr) / 1024.0;
    return NAN;
}

double cpuSeconds() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
           1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

// What one child reports to the parent through a pipe (same binary, so a plain struct).
struct StageResult {
    int ok = 0;
    uint32_t width = 0, height = 0, frames = 0;
    Stat decode, track, lighting, render, display, compose1080, png;
    double firstRenderMs = 0.0;  // frame 0 (warm-up, not in the render row)
    double peakRssMiB = 0.0;
    double deviceMiB = 0.0;
};

struct LiveResult {
    int ok = 0;
    uint32_t width = 0, height = 0;
    int files = 0;
    double previewSeconds = 0.0;
    double startupSeconds = 0.0;  // start to the first frame shown (with the dial: its timing)
    double fpsStatus = 0.0;       // median of the status's fps samples
    double fpsShown = 0.0;        // frames shown / seconds over the window
    uint64_t shown = 0, dropCapture = 0, dropRender = 0, dropDisplay = 0;
    Stat latency, renderMs, trackMs, lightingMs;
    double previewCpuPct = 0.0;
    // Refinement (none output only).
    double refineSeconds = 0.0;
    double refineSppPerSecond = 0.0;
    double refinePathsPerSecond = 0.0;
    uint64_t refineSamples = 0;
    bool refineCapped = false;
    double peakRssMiB = 0.0;  // after preview (and refinement)
    double deviceMiB = 0.0;
    // Idle: refinement converged at idleTarget samples (a second service in the same child).
    uint64_t idleTarget = 0;
    double idleSeconds = 0.0;
    double idleCpuPct = 0.0;
    double lightingHz = 0.0;  // [lighting] update_hz: lighting snapshots per second
    double idleLightingMs = 0.0;
    double idlePeakRssMiB = 0.0;
    double vmRssEndMiB = 0.0;
};

template <typename T>
bool writeAll(int fd, const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    return ::write(fd, &value, sizeof(value)) == ssize_t(sizeof(value));
}

// Runs `body` in a forked child and returns what it wrote, or nullopt if it failed.
template <typename T, typename Body>
std::optional<T> inChild(Body body) {
    int fds[2];
    if (::pipe(fds) != 0) return std::nullopt;
    std::fflush(stdout);
    std::fflush(stderr);
    const pid_t pid = ::fork();
    if (pid < 0) {
        ::close(fds[0]);
        ::close(fds[1]);
        return std::nullopt;
    }
    if (pid == 0) {
        ::close(fds[0]);
        // The child blocks SIGINT/SIGTERM for the service: die with the parent instead.
        ::prctl(PR_SET_PDEATHSIG, SIGKILL);
        blockServiceSignals();
        T result = body();
        const bool written = writeAll(fds[1], result);
        std::fflush(stdout);
        std::fflush(stderr);
        ::_exit(written && result.ok ? 0 : 1);
    }
    ::close(fds[1]);
    T result{};
    size_t got = 0;
    auto* bytes = reinterpret_cast<char*>(&result);
    while (got < sizeof(T)) {
        const ssize_t n = ::read(fds[0], bytes + got, sizeof(T) - got);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) break;
        got += size_t(n);
    }
    ::close(fds[0]);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
    if (got != sizeof(T) || !WIFEXITED(status) || WEXITSTATUS(status) != 0) return std::nullopt;
    return result;
}

// One part's run at w×h in a forked child (inChild), its result appended to `results`; false,
// with the failure logged, when the child failed.
template <typename T, typename Body>
bool appendChildRun(std::vector<T>& results, const char* part, uint32_t w, uint32_t h, Body body) {
    std::optional<T> r = inChild<T>(body);
    if (!r) {
        logError("bench service: the {} run at {}x{} failed (see above)", part, w, h);
        return false;
    }
    results.push_back(*r);
    return true;
}

struct TempDir {
    std::string path;
    TempDir() {
        char name[] = "/tmp/previs-bench-service-XXXXXX";
        if (::mkdtemp(name)) path = name;
    }
    ~TempDir() {
        std::error_code ec;
        if (!path.empty()) fs::remove_all(path, ec);
    }
};

Result<ServiceConfig> demoConfig(const ServiceBenchOptions& o, uint32_t w, uint32_t h) {
    Result<ServiceConfig> config = loadServiceConfig(o.examplesDir + "/demo/previsd.toml");
    if (!config) return config;
    config->render.width = w;
    config->render.height = h;
    config->render.resolutionScale = o.resolutionScale;
    config->render.previewFps = o.previewFps;
    config->render.denoise = o.denoise;
    // The bench sets the mode itself: the take's recorded button presses would toggle it.
    config->replaySessionEvents = false;
    // The looping take pans and relights: refinement would restart on it (shot/refine_watch.h)
    // and the bench would time restarts, not a frozen shot's samples and idle.
    config->refine.poseThresholdM = std::numeric_limits<double>::infinity();
    config->refine.poseThresholdDeg = std::numeric_limits<double>::infinity();
    config->refine.lightingThreshold = std::numeric_limits<double>::infinity();
    return config;
}

Result<std::vector<std::shared_ptr<Frame>>> readAll(const std::string& dir,
                                                    std::vector<double>* decodeMs) {
    Result<std::unique_ptr<RecordedReader>> reader =
        RecordedReader::create(dir, ReplayTiming::AsFastAsPossible);
    if (!reader) return reader.error();
    if (Status s = (*reader)->start(); !s) return s.error();
    std::vector<std::shared_ptr<Frame>> frames;
    uint64_t sequence = 0;
    while (!(*reader)->finished()) {
        auto frame = std::make_shared<Frame>();
        const Clock::time_point t = Clock::now();
        Result<bool> got = (*reader)->read(1000, *frame);
        if (!got) return got.error();
        if (!*got) continue;
        if (decodeMs) decodeMs->push_back(msSince(t));
        frame->sequence = sequence++;
        frames.push_back(frame);
    }
    return frames;
}

// Part 1: every stage once per scene frame, in lock step (as take/replay.cpp), timed.
StageResult measureStages(const ServiceBenchOptions& o, uint32_t w, uint32_t h) {
    StageResult r;
    r.width = w;
    r.height = h;
    auto fail = [&](const std::string& what) {
        logError("bench service stages {}x{}: {}", w, h, what);
        return r;
    };
    Result<ServiceConfig> config = demoConfig(o, w, h);
    if (!config) return fail(config.message());
    if (!config->fisheyeCamera) return fail("the demo config has no fisheye camera");
    std::vector<double> decode;
    auto scenes = readAll(config->sceneCamera.device, &decode);
    if (!scenes) return fail(scenes.message());
    auto fisheyes = readAll(config->fisheyeCamera->device, nullptr);
    if (!fisheyes) return fail(fisheyes.message());
    Result<Scene> scene = loadScene(config->scenePath);
    if (!scene) return fail(scene.message());
    auto gpu = GpuContext::create({});
    if (!gpu) return fail(gpu.message());
    auto renderer = PipelineRenderer::create(**gpu, *scene, *config);
    if (!renderer) return fail(renderer.message());
    PipelineRenderer& pr = **renderer;
    auto tracking = TrackingStage::create(*config);
    if (!tracking) return fail(tracking.message());
    auto lighting = LightingStage::create(*config);
    if (!lighting) return fail(lighting.message());
    TempDir tmp;
    auto files = FilesOutput::create(tmp.path + "/frames");
    if (!files) return fail(files.message());
    std::vector<uint32_t> screen(1920 * 1080);

    // The service's shot rules (shot/shot_controller.h) on the live clock, in preview.
    const ModeMachine modes(Mode::Preview);
    const SteadyShotClock clock;
    ShotController shot(pr, modes, clock, config->refine);
    const size_t frames = std::min<size_t>(scenes->size(), o.quick ? 10 : scenes->size());
    std::vector<double> track, lit, render, display, compose, png;
    std::shared_ptr<const LiveLighting> current;
    size_t nextFisheye = 0;
    for (size_t i = 0; i < frames; ++i) {
        const std::shared_ptr<Frame>& frame = (*scenes)[i];
        if (i == 0 || i + 1 == frames || (i + 1) % 10 == 0)
            benchProgress("stages {}x{} frame {}/{}", w, h, i + 1, frames);
        // Every fisheye frame recorded up to this one is converted (not only those [lighting]
        // update_hz would pick): more samples of the stage's cost.
        for (; nextFisheye < fisheyes->size() &&
               (*fisheyes)[nextFisheye]->timestampNs <= frame->timestampNs;
             ++nextFisheye) {
            const Clock::time_point t = Clock::now();
            auto l = lighting->process(*(*fisheyes)[nextFisheye]);
            if (!l) return fail(l.message());
            if (!*l) continue;  // a bracket in progress
            lit.push_back(msSince(t));
            current = *l;
        }
        Clock::time_point t = Clock::now();
        auto tracked = std::make_shared<TrackedFrame>(tracking->process(frame));
        track.push_back(msSince(t));
        t = Clock::now();
        if (Result<ShotStep> step = shot.step(tracked, current); !step) return fail(step.message());
        const double renderMs = msSince(t);
        if (i == 0)
            r.firstRenderMs = renderMs;  // pipeline warm-up: not in the row
        else
            render.push_back(renderMs);
        t = Clock::now();
        Result<DisplayImage> image = pr.display();
        if (!image) return fail(image.message());
        display.push_back(msSince(t));
        DisplayFrame out;
        out.width = image->width;
        out.height = image->height;
        out.rgb = std::move(image->rgb);
        out.status = fmt::format("PREVIEW 1 spp {:.1f} fps", 1.0);
        out.index = i;
        t = Clock::now();
        composeFrame(out, 1920, 1080, screen.data(), 1920 * 4);
        compose.push_back(msSince(t));
        t = Clock::now();
        if (Status s = (*files)->show(out); !s) return fail(s.message());
        png.push_back(msSince(t));
    }
    decode.resize(std::min(decode.size(), frames));
    r.frames = uint32_t(frames);
    r.decode = stat(decode);
    r.track = stat(track);
    r.lighting = stat(lit);
    r.render = stat(render);
    r.display = stat(display);
    r.compose1080 = stat(compose);
    r.png = stat(png);
    r.peakRssMiB = peakRssMiB();
    r.deviceMiB = double(pr.deviceBytes()) / (1024.0 * 1024.0);
    r.ok = 1;
    return r;
}

// Runs `service` on a thread until stopLive() (requestStop + join).
struct Running {
    std::unique_ptr<Service> service;
    std::thread thread;
    int rc = 0;
    double startupSeconds = 0.0;  // Service::create until the first frame was shown
    void start() {
        thread = std::thread([this] { rc = service->run(); });
    }
    void stop() {
        service->requestStop();
        if (thread.joinable()) thread.join();
    }
    // Creates and runs the service, then waits for its first frame (pipeline compilation, first
    // lighting upload); an error names `what`.
    Status startAndWarmUp(const ServiceConfig& config, const char* what);
};

constexpr auto kPoll = std::chrono::milliseconds(100);
constexpr double kSceneFps = 15.0;  // the demo session's scene camera (index.csv: 66.7 ms apart)

// Waits until `done(status)` or `timeoutSeconds`; false on timeout.
template <typename Pred>
bool waitFor(const Service& s, double timeoutSeconds, Pred done) {
    const Clock::time_point start = Clock::now();
    while (secondsSince(start) < timeoutSeconds) {
        if (done(s.status())) return true;
        std::this_thread::sleep_for(kPoll);
    }
    return false;
}

Status Running::startAndWarmUp(const ServiceConfig& config, const char* what) {
    const Clock::time_point begin = Clock::now();
    auto created = Service::create(config);
    if (!created) return created.error();
    service = std::move(*created);
    start();
    if (!waitFor(*service, 120.0, [](const ServiceStatus& st) { return st.framesShown >= 1; })) {
        stop();
        return makeError("{}: no frame shown within 120 s", what);
    }
    startupSeconds = secondsSince(begin);
    return {};
}

// Part 2: the live service at recorded timing.
LiveResult measureLive(const ServiceBenchOptions& o, uint32_t w, uint32_t h, bool files) {
    LiveResult r;
    r.width = w;
    r.height = h;
    r.files = files;
    auto fail = [&](const std::string& what) {
        logError("bench service live {}x{} {}: {}", w, h, files ? "files" : "none", what);
        return r;
    };
    const double previewSeconds = o.previewSeconds > 0 ? o.previewSeconds : o.quick ? 8.0 : 20.0;
    const double refineSeconds = o.refineSeconds > 0 ? o.refineSeconds : o.quick ? 4.0 : 10.0;
    const double idleSeconds = o.idleSeconds > 0 ? o.idleSeconds : o.quick ? 4.0 : 10.0;
    TempDir tmp;
    if (tmp.path.empty()) return fail("cannot create a temporary folder in /tmp");
    Result<ServiceConfig> config = demoConfig(o, w, h);
    if (!config) return fail(config.message());
    config->control.socketPath = tmp.path + "/previsd.sock";
    config->loopSession = true;
    if (files) {
        config->output.kind = OutputKind::Files;
        config->output.folder = tmp.path + "/frames";
    } else {
        config->output.kind = OutputKind::None;
    }

    {
        Running run;
        if (Status st = run.startAndWarmUp(*config, "live run"); !st) return fail(st.message());
        const Service& s = *run.service;
        r.startupSeconds = run.startupSeconds;
        const ServiceStatus first = s.status();
        const double cpu0 = cpuSeconds();
        const Clock::time_point start = Clock::now();
        std::vector<double> fps, latency, renderMs, trackMs, lightingMs;
        uint64_t lastShown = first.framesShown;
        ServiceStatus last = first;
        while (secondsSince(start) < previewSeconds) {
            std::this_thread::sleep_for(kPoll);
            last = s.status();
            fps.push_back(last.fps);
            if (last.framesShown != lastShown) {  // one sample per frame shown
                lastShown = last.framesShown;
                latency.push_back(last.latencyMs);
                renderMs.push_back(last.renderMs);
                trackMs.push_back(last.trackMs);
                lightingMs.push_back(last.lightingMs);
            }
        }
        const double elapsed = secondsSince(start);
        r.previewCpuPct = 100.0 * (cpuSeconds() - cpu0) / elapsed;
        r.previewSeconds = elapsed;
        r.fpsStatus = stat(fps).median;
        r.shown = last.framesShown - first.framesShown;
        r.fpsShown = double(r.shown) / elapsed;
        r.dropCapture = last.droppedCapture - first.droppedCapture;
        r.dropRender = last.droppedRender - first.droppedRender;
        r.dropDisplay = last.droppedDisplay - first.droppedDisplay;
        r.latency = stat(latency);
        r.renderMs = stat(renderMs);
        r.trackMs = stat(trackMs);
        r.lightingMs = stat(lightingMs);
        r.deviceMiB = double(last.deviceBytes) / (1024.0 * 1024.0);

        if (!files) {
            run.service->modes().set(Mode::Refine, "bench");
            // The refinement has begun once a refine frame has been rendered.
            const uint64_t rendered = s.status().framesRendered;
            if (!waitFor(s, 60.0, [&](const ServiceStatus& st) {
                    return st.mode == Mode::Refine && st.framesRendered > rendered + 1;
                })) {
                run.stop();
                return fail("refinement did not start within 60 s");
            }
            const ServiceStatus r0 = s.status();
            const Clock::time_point t0 = Clock::now();
            ServiceStatus r1 = r0;
            Clock::time_point t1 = t0;
            while (secondsSince(t0) < refineSeconds) {
                std::this_thread::sleep_for(kPoll);
                ServiceStatus now = s.status();
                if (now.samples != r1.samples) {
                    r1 = now;
                    t1 = Clock::now();
                }
            }
            r.refineSeconds = std::chrono::duration<double>(t1 - t0).count();
            r.refineSamples = r1.samples - r0.samples;
            r.refineCapped = r1.samples >= config->refine.maxSamples;
            if (r.refineSeconds > 0.0) {
                r.refineSppPerSecond = double(r.refineSamples) / r.refineSeconds;
                r.refinePathsPerSecond = r.refineSppPerSecond * double(w) * double(h);
            }
        }
        r.peakRssMiB = peakRssMiB();
        r.deviceMiB = std::max(r.deviceMiB, double(s.status().deviceBytes) / (1024.0 * 1024.0));
        run.stop();
        if (run.rc != 0) return fail("the service's run() returned " + std::to_string(run.rc));
    }

    if (!files) {
        // Idle: a service whose refinement converges at a few samples, then sits there while the
        // cameras (looping session), tracking and lighting keep running.
        config->refine.maxSamples = 8;
        r.idleTarget = config->refine.maxSamples;
        r.lightingHz = config->lighting.updateHz;
        Running run;
        if (Status st = run.startAndWarmUp(*config, "idle run"); !st) return fail(st.message());
        const Service& s = *run.service;
        run.service->modes().set(Mode::Refine, "bench");
        if (!waitFor(s, 180.0, [&](const ServiceStatus& st) {
                return st.mode == Mode::Refine && st.samples >= r.idleTarget;
            })) {
            run.stop();
            return fail("idle run: refinement did not converge within 180 s");
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(500));  // last publish settles
        const double cpu0 = cpuSeconds();
        const Clock::time_point t0 = Clock::now();
        std::vector<double> lightingMs;
        while (secondsSince(t0) < idleSeconds) {
            std::this_thread::sleep_for(kPoll);
            const ServiceStatus st = s.status();
            lightingMs.push_back(st.lightingMs);
        }
        r.idleSeconds = secondsSince(t0);
        r.idleCpuPct = 100.0 * (cpuSeconds() - cpu0) / r.idleSeconds;
        r.idleLightingMs = stat(lightingMs).median;
        r.idlePeakRssMiB = peakRssMiB();
        run.stop();
        if (run.rc != 0) return fail("idle run: run() returned " + std::to_string(run.rc));
    }
    r.vmRssEndMiB = vmRssMiB();
    r.ok = 1;
    return r;
}

std::string ms(const Stat& s) {
    if (s.n == 0) return "–";
    return fmt::format("{:.1f} / {:.1f}", s.median, s.p90);
}

}  // namespace

int runServiceBench(const ServiceBenchOptions& o) {
    std::vector<std::pair<uint32_t, uint32_t>> sizes = o.sizes;
    if (sizes.empty()) sizes = {{640, 480}, {1280, 720}};
    std::printf(
        "## previsd (issue 7): the demo session (examples/demo, 640×360 scene frames at "
        "15 fps, fisheye at 3.75 fps), preview 1 spp, max depth 4, resolution scale %.3g, "
        "preview_fps %.3g (0: no dial), denoise %s%s\n\n",
        o.resolutionScale, o.previewFps, o.denoise.c_str(), o.quick ? " (quick run)" : "");

    std::vector<StageResult> stages;
    for (auto [w, h] : sizes) {
        benchProgress("stages {}x{} (forked child)", w, h);
        if (!appendChildRun(stages, "stage", w, h, [&] { return measureStages(o, w, h); }))
            return 1;
    }
    std::printf(
        "### Cost per frame of each stage, lock step (ms, median / p90)\n\n"
        "| render size | frames | JPEG decode 640×360 | tracking 640×360 | lighting "
        "(fisheye → map) | preview render 1 spp | composite + tone map (device), 8-bit readback | "
        "compose to 1920×1080 | PNG write | peak RSS | device memory |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const StageResult& s : stages)
        std::printf("| %u×%u | %u | %s | %s | %s | %s | %s | %s | %s | %.0f MiB | %.0f MiB |\n",
                    s.width, s.height, s.frames, ms(s.decode).c_str(), ms(s.track).c_str(),
                    ms(s.lighting).c_str(), ms(s.render).c_str(), ms(s.display).c_str(),
                    ms(s.compose1080).c_str(), ms(s.png).c_str(), s.peakRssMiB, s.deviceMiB);
    std::printf("\nFirst preview frame (warm-up, not in the render column): %s.\n\n",
                [&] {
                    std::string t;
                    for (const StageResult& s : stages)
                        t += fmt::format("{}{}×{} {:.0f} ms", t.empty() ? "" : ", ", s.width,
                                         s.height, s.firstRenderMs);
                    return t;
                }()
                    .c_str());
    std::fflush(stdout);

    std::vector<LiveResult> live;
    for (auto [w, h] : sizes)
        for (bool files : {false, true}) {
            benchProgress("live service {}x{} output {} (forked child)", w, h,
                          files ? "files" : "none");
            if (!appendChildRun(live, "live", w, h, [&] { return measureLive(o, w, h, files); }))
                return 1;
        }
    std::printf(
        "### The live service (recorded timing, looping; ms as median / p90)\n\n"
        "| render size | output | start to first frame | seconds | fps (status) | fps (shown/s) "
        "| latency ms | render ms | drops capture / render / display | CPU (preview) | peak RSS | "
        "device memory |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const LiveResult& l : live)
        std::printf(
            "| %u×%u | %s | %.1f s | %.0f | %.2f | %.2f | %s | %s | %llu / %llu / %llu | %.0f %% | "
            "%.0f MiB | %.0f MiB |\n",
            l.width, l.height, l.files ? "files" : "none", l.startupSeconds, l.previewSeconds,
            l.fpsStatus, l.fpsShown, ms(l.latency).c_str(), ms(l.renderMs).c_str(),
            (unsigned long long)l.dropCapture, (unsigned long long)l.dropRender,
            (unsigned long long)l.dropDisplay, l.previewCpuPct, l.peakRssMiB, l.deviceMiB);
    // What the stages that keep running while refinement idles should cost, from the lock-step
    // medians: every scene frame decoded and tracked, lighting at its update rate.
    auto idleEstimatePct = [&](const LiveResult& l) {
        for (const StageResult& s : stages)
            if (s.width == l.width && s.height == l.height)
                return (s.decode.median + s.track.median) * kSceneFps / 10.0 +
                       s.lighting.median * l.lightingHz / 10.0;
        return double(NAN);
    };
    std::printf(
        "\n| render size | refinement spp/s | paths/s | idle at %llu spp: CPU of one core "
        "| expected from decode + tracking at %.0f fps + lighting (lock-step medians) | "
        "peak RSS incl. idle run | VmRSS at end |\n|---|---|---|---|---|---|---|\n",
        (unsigned long long)(live.empty() ? 8 : live.front().idleTarget), kSceneFps);
    for (const LiveResult& l : live) {
        if (l.files) continue;
        std::printf("| %u×%u | %.2f%s | %.2f M | %.0f %% | %.0f %% | %.0f MiB | %.0f MiB |\n",
                    l.width, l.height, l.refineSppPerSecond, l.refineCapped ? " (capped)" : "",
                    l.refinePathsPerSecond * 1e-6, l.idleCpuPct, idleEstimatePct(l),
                    l.idlePeakRssMiB, l.vmRssEndMiB);
    }
    std::printf("\n");
    std::fflush(stdout);

    if (!o.csvPath.empty()) {
        std::ofstream csv(o.csvPath, std::ios::trunc);
        csv << "part,width,height,output,metric,median,p90,n\n";
        auto row = [&](const char* part, uint32_t w, uint32_t h, const char* out,
                       const char* metric, double median, double p90, uint32_t n) {
            csv << part << "," << w << "," << h << "," << out << "," << metric << ","
                << fmt::format("{:.4g}", median) << ","
                << (std::isnan(p90) ? std::string() : fmt::format("{:.4g}", p90)) << "," << n
                << "\n";
        };
        for (const StageResult& s : stages) {
            std::pair<const char*, const Stat*> list[] = {{"decode_ms", &s.decode},
                                                          {"track_ms", &s.track},
                                                          {"lighting_ms", &s.lighting},
                                                          {"render_ms", &s.render},
                                                          {"display_ms", &s.display},
                                                          {"compose1080_ms", &s.compose1080},
                                                          {"png_ms", &s.png}};
            for (auto [name, st] : list)
                row("stages", s.width, s.height, "", name, st->median, st->p90, st->n);
            row("stages", s.width, s.height, "", "first_render_ms", s.firstRenderMs, NAN, 1);
            row("stages", s.width, s.height, "", "peak_rss_mib", s.peakRssMiB, NAN, 1);
            row("stages", s.width, s.height, "", "device_mib", s.deviceMiB, NAN, 1);
        }
        for (const LiveResult& l : live) {
            const char* out = l.files ? "files" : "none";
            row("live", l.width, l.height, out, "seconds", l.previewSeconds, NAN, 1);
            row("live", l.width, l.height, out, "startup_seconds", l.startupSeconds, NAN, 1);
            row("live", l.width, l.height, out, "fps_status", l.fpsStatus, NAN, 1);
            row("live", l.width, l.height, out, "fps_shown", l.fpsShown, NAN, uint32_t(l.shown));
            row("live", l.width, l.height, out, "latency_ms", l.latency.median, l.latency.p90,
                l.latency.n);
            row("live", l.width, l.height, out, "render_ms", l.renderMs.median, l.renderMs.p90,
                l.renderMs.n);
            row("live", l.width, l.height, out, "track_ms", l.trackMs.median, l.trackMs.p90,
                l.trackMs.n);
            row("live", l.width, l.height, out, "dropped_capture", double(l.dropCapture), NAN, 1);
            row("live", l.width, l.height, out, "dropped_render", double(l.dropRender), NAN, 1);
            row("live", l.width, l.height, out, "dropped_display", double(l.dropDisplay), NAN, 1);
            row("live", l.width, l.height, out, "preview_cpu_pct", l.previewCpuPct, NAN, 1);
            row("live", l.width, l.height, out, "peak_rss_mib", l.peakRssMiB, NAN, 1);
            row("live", l.width, l.height, out, "device_mib", l.deviceMiB, NAN, 1);
            if (l.files) continue;
            row("live", l.width, l.height, out, "refine_spp_per_s", l.refineSppPerSecond, NAN, 1);
            row("live", l.width, l.height, out, "refine_paths_per_s", l.refinePathsPerSecond, NAN,
                1);
            row("live", l.width, l.height, out, "idle_cpu_pct", l.idleCpuPct, NAN, 1);
            row("live", l.width, l.height, out, "idle_cpu_expected_pct", idleEstimatePct(l), NAN,
                1);
            row("live", l.width, l.height, out, "idle_peak_rss_mib", l.idlePeakRssMiB, NAN, 1);
            row("live", l.width, l.height, out, "vmrss_end_mib", l.vmRssEndMiB, NAN, 1);
        }
        if (!csv) {
            logError("--csv {}: cannot write the file", o.csvPath);
            return 1;
        }
        benchProgress("wrote {}", o.csvPath);
    }
    return 0;
}

}  // namespace previs::bench
