// The server the browser test (browser_test.py) drives: a WebMonitor fed a synthetic picture that
// changes every frame, with a small mode/record state machine behind its hooks, as previsd's
// Service has; its status is previsd's own statusJson of a ServiceStatus, so the page reads the
// fields exactly as previsd writes them. Prints "LISTENING PORT" on stdout once it serves; runs
// until stdin closes or SIGTERM.
//
//   web_test_server [--listen HOST:PORT] [--token TOKEN] [--fps N] [--command-delay-ms N]
//                   [--starting WHAT]
//
// --token "" turns control off (403). --command-delay-ms makes each control command take that
// long (a record start that opens a take), so a second tap can arrive while the first request is
// in flight. --starting says the box is starting (status "state": "starting", "starting": WHAT)
// until stdin gives the line "ready". Other lines on stdin change what the status says: "lost"
// and "found" (tracking), "lighting off" (the plate-consistency meter out of range: the render
// too dark).

#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "daemon/service.h"
#include "tests/web/synthetic_frames.h"
#include "web/web_monitor.h"

namespace {

using Clock = std::chrono::steady_clock;

std::atomic<bool> gStop{false};

void onSignal(int) { gStop = true; }

// A take's folder as previsd names one: the page must show its name, never the box's path.
constexpr const char* kTakePath = "/var/lib/previs/takes/2026-12-06_101200";

// What previsd's Service answers, reduced to the states the page shows.
class FakeService {
public:
    FakeService(int commandDelayMs, std::string starting)
        : commandDelayMs_(commandDelayMs), starting_(std::move(starting)) {}

    std::string statusJson() {
        std::lock_guard lock(mutex_);
        if (!starting_.empty()) {
            // As previsd while it starts: the fields at their values before any frame.
            nlohmann::json j = nlohmann::json::parse(previs::statusJson(previs::ServiceStatus{}));
            j["state"] = "starting";
            j["starting"] = starting_;
            return j.dump();
        }
        previs::ServiceStatus s;
        s.mode = refine_ ? previs::Mode::Refine : previs::Mode::Preview;
        s.framesShown = framesShown_;
        s.fps = 30.0;
        s.samples = refine_ ? 4 + framesShown_ % 100 : 1;
        if (refine_) {
            s.noiseEstimate = 0.018;
            s.etaSeconds = 12.0;
        }
        s.worldFromCamera = cv::Matx44d::eye();
        s.tags = trackingLost_ ? 0 : 4;
        s.trackingLost = trackingLost_;
        s.record.recording = recording_;
        if (recording_) {
            s.record.path = kTakePath;
            s.record.frames = framesShown_ - recordFrom_;
            s.record.seconds = std::chrono::duration<double>(Clock::now() - recordSince_).count();
        }
        s.timecode = previs::Timecode::fromFrameCount(108000, previs::TimecodeRate::fps30());
        previs::PlateConsistency plate;
        plate.ratio = lightingOff_ ? std::array{0.41, 0.43, 0.42} : std::array{1.0, 1.01, 0.99};
        plate.ok = !lightingOff_;
        s.plateConsistency = previs::PlateConsistencyReading{plate, framesShown_, 0};
        return previs::statusJson(s);
    }

    std::string command(const std::string& c) {
        std::this_thread::sleep_for(std::chrono::milliseconds(commandDelayMs_));
        std::lock_guard lock(mutex_);
        nlohmann::json reply = {{"ok", true}};
        if (c == "toggle" || c == "mode preview" || c == "mode refine") {
            refine_ = c == "toggle" ? !refine_ : c == "mode refine";
            reply["mode"] = refine_ ? "refine" : "preview";
        } else if (c == "record start" && !recording_) {
            recording_ = true;
            recordFrom_ = framesShown_;
            recordSince_ = Clock::now();
            reply["path"] = kTakePath;
        } else if (c == "record stop" && recording_) {
            recording_ = false;
            reply["path"] = kTakePath;
        } else {
            reply = {{"ok", false}, {"error", "cannot " + c + " now"}};
        }
        std::fprintf(stderr, "web_test_server: command '%s' -> %s\n", c.c_str(),
                     reply.dump().c_str());
        return reply.dump();
    }

    // A line from the test: what the status should say from now on.
    void tell(const std::string& line) {
        std::lock_guard lock(mutex_);
        if (line == "ready") starting_.clear();
        if (line == "lost" || line == "found") trackingLost_ = line == "lost";
        if (line == "lighting off") lightingOff_ = true;
    }

    void frameShown() {
        std::lock_guard lock(mutex_);
        ++framesShown_;
    }

private:
    const int commandDelayMs_;
    std::mutex mutex_;
    std::string starting_;
    bool refine_ = false;
    bool recording_ = false;
    bool trackingLost_ = false;
    bool lightingOff_ = false;
    uint64_t recordFrom_ = 0;
    Clock::time_point recordSince_{};
    uint64_t framesShown_ = 0;
};

// Reads what stdin holds now without waiting; false once it is closed (the test is done).
bool readStdin(FakeService& service, std::string& pending) {
    for (pollfd p{STDIN_FILENO, POLLIN, 0}; ::poll(&p, 1, 0) > 0;) {
        char buffer[256];
        const ssize_t n = ::read(STDIN_FILENO, buffer, sizeof buffer);
        if (n <= 0) return false;
        pending.append(buffer, size_t(n));
        for (size_t end; (end = pending.find('\n')) != std::string::npos;) {
            service.tell(pending.substr(0, end));
            pending.erase(0, end + 1);
        }
    }
    return true;
}

}  // namespace

int main(int argc, char** argv) {
    previs::WebMonitorSettings settings;
    settings.listen = "127.0.0.1:0";
    settings.token = "test-token";
    double renderFps = 30.0;
    int commandDelayMs = 0;
    std::string starting;
    for (int i = 1; i + 1 < argc; i += 2) {
        const std::string key = argv[i];
        if (key == "--listen")
            settings.listen = argv[i + 1];
        else if (key == "--token")
            settings.token = argv[i + 1];
        else if (key == "--fps")
            settings.streamFps = std::stod(argv[i + 1]);
        else if (key == "--command-delay-ms")
            commandDelayMs = std::stoi(argv[i + 1]);
        else if (key == "--starting")
            starting = argv[i + 1];
        else {
            std::fprintf(stderr, "web_test_server: unknown option %s\n", key.c_str());
            return 2;
        }
    }
    std::signal(SIGTERM, onSignal);
    std::signal(SIGINT, onSignal);
    FakeService service(commandDelayMs, starting);
    auto monitor = previs::WebMonitor::create(
        settings, {.statusJson = [&] { return service.statusJson(); },
                   .command = [&](const std::string& c) { return service.command(c); }});
    if (!monitor) {
        std::fprintf(stderr, "web_test_server: %s\n", monitor.message().c_str());
        return 1;
    }
    std::printf("LISTENING %d\n", (*monitor)->port());
    std::fflush(stdout);

    // The render stand-in: a new picture every frame period until told to stop.
    const auto period = std::chrono::duration<double>(1.0 / renderFps);
    auto next = Clock::now();
    std::string pending;
    for (uint64_t i = 0; !gStop; ++i) {
        (*monitor)->submitFrame(previs::test::syntheticFrame(960, 540, i));
        service.frameShown();
        next += std::chrono::duration_cast<Clock::duration>(period);
        std::this_thread::sleep_until(next);
        // The test closes our stdin when it is done (also if it dies).
        if (!readStdin(service, pending)) break;
    }
    return 0;
}
