// The web stream's cost (docs/web-monitor.md "Performance"): JPEG encode time per frame at the
// stream size, and the stream's rate and the process's CPU time with 1 and 5 viewers reading
// over loopback while a 30 fps "render" submits 1920×1080 frames.
//
//   web_stream_bench [SECONDS]   (default 4 per case)

#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "tests/web/synthetic_frames.h"
#include "tests/web/web_test_support.h"
#include "web/stream_encoder.h"
#include "web/web_monitor.h"

namespace {

using Clock = std::chrono::steady_clock;

double cpuSeconds() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
           double(u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

void encodeCost(uint32_t width, uint32_t height) {
    const previs::WebFrame frame = previs::test::syntheticFrame(width, height, 5);
    constexpr int kRuns = 50;
    size_t bytes = 0;
    const auto start = Clock::now();
    for (int i = 0; i < kRuns; ++i) bytes = previs::encodeJpeg(frame, 640, 80)->size();
    const double ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
    std::printf("encode %ux%u -> 640 wide, q80: %.2f ms/frame, %zu bytes\n", width, height,
                ms / kRuns, bytes);
}

void viewers(int count, double seconds) {
    previs::test::FakeService service;
    previs::WebMonitorSettings s = previs::test::testSettings();
    s.maxStreams = 8;
    auto monitor = previs::test::startMonitor(service, s);
    std::vector<previs::WebFrame> frames;
    for (uint64_t i = 0; i < 8; ++i) frames.push_back(previs::test::syntheticFrame(1920, 1080, i));
    std::vector<std::unique_ptr<previs::test::StreamViewer>> list;
    for (int i = 0; i < count; ++i)
        list.push_back(std::make_unique<previs::test::StreamViewer>(monitor->port()));
    previs::test::eventually([&] { return monitor->stats().viewers == count; });
    const previs::WebStats before = monitor->stats();
    const double cpuBefore = cpuSeconds();
    const auto start = Clock::now();
    auto next = start;
    double longestSubmitUs = 0.0;
    for (uint64_t i = 0; Clock::now() - start < std::chrono::duration<double>(seconds); ++i) {
        const auto t = Clock::now();
        monitor->submitFrame(frames[i % frames.size()]);
        longestSubmitUs = std::max(
            longestSubmitUs, std::chrono::duration<double, std::micro>(Clock::now() - t).count());
        next += std::chrono::milliseconds(33);
        std::this_thread::sleep_until(next);
    }
    const double wall = std::chrono::duration<double>(Clock::now() - start).count();
    const double cpu = cpuSeconds() - cpuBefore;
    const previs::WebStats after = monitor->stats();
    const double encoded = double(after.framesEncoded - before.framesEncoded);
    std::printf(
        "%d viewer(s): stream %.2f fps, %.0f encodes for %llu frames submitted, %.2f frames sent "
        "per encode, encode %.2f ms, %zu bytes/frame, process CPU %.1f %% of one core "
        "(includes the viewers' reading), longest submitFrame %.0f us\n",
        count, encoded / wall, encoded,
        static_cast<unsigned long long>(after.framesSubmitted - before.framesSubmitted),
        double(after.framesSent - before.framesSent) / std::max(1.0, encoded), after.encodeMs,
        after.jpegBytes, 100.0 * cpu / wall, longestSubmitUs);
}

}  // namespace

int main(int argc, char** argv) {
    const double seconds = argc > 1 ? std::stod(argv[1]) : 4.0;
    encodeCost(640, 360);
    encodeCost(1920, 1080);
    viewers(0, seconds);
    viewers(1, seconds);
    viewers(5, seconds);
    return 0;
}
