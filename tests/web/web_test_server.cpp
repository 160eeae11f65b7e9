// The server the browser test (browser_test.py) drives: a WebMonitor fed a synthetic picture that
// changes every frame, with a small mode/record state machine behind its hooks, as previsd's
// Service has. Prints "LISTENING PORT" on stdout once it serves; runs until stdin closes or
// SIGTERM.
//
//   web_test_server [--listen HOST:PORT] [--token TOKEN] [--fps N] [--command-delay-ms N]
//
// --command-delay-ms makes each control command take that long (a record start that opens a
// take), so a second tap can arrive while the first request is in flight.

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

#include "tests/web/synthetic_frames.h"
#include "web/web_monitor.h"

namespace {

std::atomic<bool> gStop{false};

void onSignal(int) { gStop = true; }

// What previsd's Service answers, reduced to the states the page shows.
class FakeService {
public:
    explicit FakeService(int commandDelayMs) : commandDelayMs_(commandDelayMs) {}
    std::string statusJson() {
        std::lock_guard lock(mutex_);
        nlohmann::json j = {{"mode", mode_},
                            {"framesShown", framesShown_},
                            {"fps", 30.0},
                            {"samples", mode_ == "refine" ? 4 + framesShown_ % 100 : 1},
                            {"recording", recording_},
                            {"record", recording_ ? nlohmann::json{{"frames", framesShown_}}
                                                  : nlohmann::json(nullptr)},
                            {"pose", {{"tags", 4}, {"lost", false}}},
                            {"timecode", "01:00:00:00"}};
        return j.dump();
    }
    std::string command(const std::string& c) {
        std::this_thread::sleep_for(std::chrono::milliseconds(commandDelayMs_));
        std::lock_guard lock(mutex_);
        if (c == "toggle")
            mode_ = mode_ == "preview" ? "refine" : "preview";
        else if (c == "mode preview" || c == "mode refine")
            mode_ = c.substr(5);
        else if (c == "record start")
            recording_ = true;
        else if (c == "record stop")
            recording_ = false;
        else
            return R"({"ok":false,"error":"unknown command"})";
        std::fprintf(stderr, "web_test_server: command '%s' -> mode %s\n", c.c_str(),
                     mode_.c_str());
        return nlohmann::json{{"ok", true}, {"mode", mode_}}.dump();
    }
    void frameShown() {
        std::lock_guard lock(mutex_);
        ++framesShown_;
    }

private:
    const int commandDelayMs_;
    std::mutex mutex_;
    std::string mode_ = "preview";
    bool recording_ = false;
    uint64_t framesShown_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
    previs::WebMonitorSettings settings;
    settings.listen = "127.0.0.1:0";
    settings.token = "test-token";
    double renderFps = 30.0;
    int commandDelayMs = 0;
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
        else {
            std::fprintf(stderr, "web_test_server: unknown option %s\n", key.c_str());
            return 2;
        }
    }
    std::signal(SIGTERM, onSignal);
    std::signal(SIGINT, onSignal);
    FakeService service(commandDelayMs);
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
    auto next = std::chrono::steady_clock::now();
    for (uint64_t i = 0; !gStop; ++i) {
        (*monitor)->submitFrame(previs::test::syntheticFrame(960, 540, i));
        service.frameShown();
        next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
        std::this_thread::sleep_until(next);
        // The test closes our stdin when it is done (also if it dies).
        pollfd p{STDIN_FILENO, POLLIN, 0};
        if (::poll(&p, 1, 0) > 0) {
            char c;
            if (::read(STDIN_FILENO, &c, 1) <= 0) break;
        }
    }
    return 0;
}
