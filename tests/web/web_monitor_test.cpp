#include "web/web_monitor.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdio>
#include <optional>
#include <thread>

#include "tests/web/monitor_fixture.h"
#include "tests/web/synthetic_frames.h"
#include "tests/web/web_test_support.h"

namespace previs {
namespace {

using namespace std::chrono_literals;
using test::StreamViewer;

// The display thread's stand-in: submits frames at `fps` and records the longest submitFrame.
class FrameProducer {
public:
    FrameProducer(WebMonitor& monitor, double fps, uint32_t width, uint32_t height, bool noisy)
        : thread_([this, &monitor, fps, width, height, noisy] {
              // A few distinct frames made once: making them is not what is measured.
              std::vector<WebFrame> frames;
              for (uint64_t i = 0; i < 4; ++i)
                  frames.push_back(test::syntheticFrame(width, height, i, noisy));
              const auto period = std::chrono::duration<double>(1.0 / fps);
              auto next = std::chrono::steady_clock::now();
              for (uint64_t i = 0; !stop_; ++i) {
                  WebFrame f = frames[i % frames.size()];
                  f.index = i;
                  const auto start = std::chrono::steady_clock::now();
                  monitor.submitFrame(std::move(f));
                  const auto took = std::chrono::steady_clock::now() - start;
                  longest_ = std::max<int64_t>(
                      longest_,
                      std::chrono::duration_cast<std::chrono::microseconds>(took).count());
                  ++submitted_;
                  next += std::chrono::duration_cast<std::chrono::steady_clock::duration>(period);
                  std::this_thread::sleep_until(next);
              }
          }) {}
    ~FrameProducer() { stop(); }
    void stop() {
        stop_ = true;
        if (thread_.joinable()) thread_.join();
    }
    int64_t longestSubmitUs() const { return longest_; }
    uint64_t submitted() const { return submitted_; }

private:
    std::atomic<bool> stop_{false};
    std::atomic<int64_t> longest_{0};
    std::atomic<uint64_t> submitted_{0};
    std::thread thread_;
};

// Noisy frames (each a JPEG of a few hundred KiB) streamed to a raw client that asked for the
// stream and reads only when the test makes it, and to a viewer that reads all it gets.
struct LaggardAndViewer {
    LaggardAndViewer(WebMonitor& monitor, uint32_t width, uint32_t height, size_t laggardBuffer)
        : producer(monitor, 30.0, width, height, true),
          laggard(monitor.port(), laggardBuffer),
          port(monitor.port()) {}
    // The laggard's request sent, then the viewer has had its first two frames.
    bool started() {
        if (!laggard.send("GET /stream.mjpeg HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")) return false;
        viewer.emplace(port);
        return viewer->waitFrames(2, 10s);
    }

    FrameProducer producer;
    test::RawConnection laggard;
    std::optional<StreamViewer> viewer;
    int port;
};

class WebMonitorTest : public test::MonitorTest {};

TEST(WebListen, ParsesHostAndPort) {
    Result<ListenAddress> a = parseListenAddress("0.0.0.0:8080");
    ASSERT_TRUE(a.ok()) << a.message();
    EXPECT_EQ(a->host, "0.0.0.0");
    EXPECT_EQ(a->port, 8080);
    Result<ListenAddress> v6 = parseListenAddress("[::1]:0");
    ASSERT_TRUE(v6.ok()) << v6.message();
    EXPECT_EQ(v6->host, "::1");
    EXPECT_EQ(v6->port, 0);
    for (const char* bad :
         {"", "8080", ":8080", "host:", "host:http", "host:70000", "::1:80", "[::1:80"}) {
        Result<ListenAddress> r = parseListenAddress(bad);
        EXPECT_FALSE(r.ok()) << bad;
        if (!r.ok()) {
            EXPECT_NE(r.message().find("[web] listen"), std::string::npos);
        }
    }
}

TEST(WebToken, MatchesOnlyTheBearerToken) {
    EXPECT_TRUE(bearerTokenMatches("Bearer abc", "abc"));
    EXPECT_TRUE(bearerTokenMatches("bearer   abc ", "abc"));
    EXPECT_FALSE(bearerTokenMatches("Bearer abd", "abc"));
    EXPECT_FALSE(bearerTokenMatches("Bearer ab", "abc"));
    EXPECT_FALSE(bearerTokenMatches("Bearer abcabc", "abc"));
    EXPECT_FALSE(bearerTokenMatches("Basic abc", "abc"));
    EXPECT_FALSE(bearerTokenMatches("abc", "abc"));
    EXPECT_FALSE(bearerTokenMatches("", "abc"));
    EXPECT_FALSE(bearerTokenMatches("Bearer ", ""));
}

TEST_F(WebMonitorTest, RefusesAPortInUse) {
    ASSERT_TRUE(start());
    WebMonitorSettings s = test::testSettings();
    s.listen = "127.0.0.1:" + std::to_string(monitor->port());
    Result<std::unique_ptr<WebMonitor>> second = WebMonitor::create(s, {});
    ASSERT_FALSE(second.ok());
    EXPECT_NE(second.message().find(s.listen), std::string::npos) << second.message();
}

TEST_F(WebMonitorTest, ServesThePageAndTheStatus) {
    ASSERT_TRUE(start());
    const test::HttpReply page = test::get(monitor->port(), "/");
    EXPECT_EQ(page.status, 200);
    EXPECT_NE(page.head.find("text/html"), std::string::npos);
    EXPECT_NE(page.body.find("<img id=\"stream\""), std::string::npos);
    EXPECT_NE(page.body.find("name=\"viewport\""), std::string::npos);
    // Offline box: nothing fetched from elsewhere.
    EXPECT_EQ(page.body.find("http://"), std::string::npos);
    EXPECT_EQ(page.body.find("https://"), std::string::npos);

    const test::HttpReply status = test::get(monitor->port(), "/status.json");
    EXPECT_EQ(status.status, 200);
    EXPECT_NE(status.head.find("application/json"), std::string::npos);
    const nlohmann::json j = nlohmann::json::parse(status.body);
    EXPECT_EQ(j["mode"], "preview");
    EXPECT_EQ(j["fps"], 29.97);
    ASSERT_TRUE(j.contains("web"));
    EXPECT_EQ(j["web"]["viewers"], 0);
}

TEST_F(WebMonitorTest, StreamsJpegFramesThatChange) {
    ASSERT_TRUE(start());
    FrameProducer producer(*monitor, 30.0, 1280, 720, false);
    test::RawConnection c(monitor->port());
    ASSERT_TRUE(c.send("GET /stream.mjpeg HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"));
    ASSERT_TRUE(test::eventually([&] {
        c.receiveFor(20ms);
        return test::completeParts(c.buffer()) >= 3;
    }));
    const test::HttpReply reply = test::parseReply(c.buffer());
    EXPECT_EQ(reply.status, 200);
    EXPECT_NE(reply.head.find("multipart/x-mixed-replace; boundary=previsframe"),
              std::string::npos);
    // Parts are JPEGs (SOI marker) of the configured size, and they differ.
    std::vector<std::string> jpegs;
    size_t pos = 0;
    while ((pos = c.buffer().find("Content-Length: ", pos)) != std::string::npos &&
           jpegs.size() < 2) {
        const size_t body = c.buffer().find("\r\n\r\n", pos) + 4;
        const size_t length = std::stoul(c.buffer().substr(pos + 16));
        jpegs.push_back(c.buffer().substr(body, length));
        pos = body + length;
    }
    ASSERT_EQ(jpegs.size(), 2u);
    EXPECT_EQ(jpegs[0].substr(0, 2), "\xff\xd8");
    EXPECT_NE(jpegs[0], jpegs[1]);
    EXPECT_EQ(monitor->stats().viewers, 1);
}

// Five viewers cost what one does: one encode per stream frame, every viewer gets each one.
TEST_F(WebMonitorTest, FiveViewersShareOneEncodePerFrame) {
    WebMonitorSettings s = test::testSettings();
    s.streamFps = 10.0;
    s.maxStreams = 5;
    ASSERT_TRUE(start(s));
    FrameProducer producer(*monitor, 30.0, 640, 360, false);
    std::vector<std::unique_ptr<StreamViewer>> viewers;
    for (int i = 0; i < 5; ++i) viewers.push_back(std::make_unique<StreamViewer>(monitor->port()));
    ASSERT_TRUE(test::eventually([&] { return monitor->stats().viewers == 5; }));
    const WebStats before = monitor->stats();
    const auto start = std::chrono::steady_clock::now();
    std::this_thread::sleep_for(2s);
    const WebStats after = monitor->stats();
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const uint64_t encoded = after.framesEncoded - before.framesEncoded;
    const uint64_t submitted = after.framesSubmitted - before.framesSubmitted;
    // The rate is the stream's (10 fps), not the input's (30 fps) times the viewers.
    EXPECT_LE(double(encoded), seconds * 10.0 + 2.0);
    EXPECT_GE(double(encoded), seconds * 10.0 * 0.4);
    EXPECT_LT(encoded, submitted);
    // Each encoded frame went to (nearly) every viewer.
    const uint64_t sent = after.framesSent - before.framesSent;
    EXPECT_GE(double(sent), 5.0 * double(encoded) * 0.8);
    EXPECT_LE(sent, 5 * encoded + 5);
    for (auto& v : viewers) EXPECT_GE(v->frames(), 3);
    viewers.clear();
    EXPECT_TRUE(test::eventually([&] { return monitor->stats().viewers == 0; }));
}

// A viewer that stops reading: the render's submitFrame and the other viewer go on as before,
// the stalled one is dropped after the write timeout and its missed frames counted.
TEST_F(WebMonitorTest, AStalledViewerSlowsNeitherTheRenderNorOtherViewers) {
    WebMonitorSettings s = test::testSettings();
    s.streamFps = 10.0;
    s.streamWidth = 1280;
    s.jpegQuality = 95;
    s.writeTimeoutMs = 1000;
    ASSERT_TRUE(start(s));
    // At 1280×720 the stalled socket (the laggard, which never reads) fills at once.
    LaggardAndViewer stream(*monitor, 1280, 720, 4096);
    ASSERT_TRUE(stream.started());
    const int framesBefore = stream.viewer->frames();
    std::this_thread::sleep_for(3s);
    const int received = stream.viewer->frames() - framesBefore;
    // 3 s at 10 fps; a loaded 2-core machine gets a wide margin.
    EXPECT_GE(received, 10);
    EXPECT_TRUE(test::eventually([&] { return monitor->stats().viewersStalled >= 1; }))
        << "viewersStalled " << monitor->stats().viewersStalled;
    const WebStats st = monitor->stats();
    EXPECT_GE(st.viewerFramesDropped, 1u);
    EXPECT_EQ(st.viewers, 1);
    stream.producer.stop();
    // A pointer swap (tens of microseconds): had it waited for the stalled viewer it would have
    // taken the write timeout (1 s). The margin is for a busy 2-core machine descheduling the
    // producer thread (12 ms seen), not for any wait of ours.
    EXPECT_LT(stream.producer.longestSubmitUs(), 200000);
}

// A viewer on a slow link (it takes 64 KiB every 100 ms, a fraction of the stream): it stays
// connected, skips to the newest frame each time it is done with one, and the skipped frames are
// counted; the fast viewer gets every frame.
TEST_F(WebMonitorTest, ASlowViewerSkipsToTheNewestFrame) {
    WebMonitorSettings s = test::testSettings();
    s.streamFps = 10.0;
    s.jpegQuality = 95;
    ASSERT_TRUE(start(s));
    // At 640×360 a JPEG takes the slow viewer (the laggard) several 100 ms reads.
    LaggardAndViewer stream(*monitor, 640, 360, 65536);
    ASSERT_TRUE(stream.started());
    test::RawConnection& slow = stream.laggard;
    const auto start = std::chrono::steady_clock::now();
    while (std::chrono::steady_clock::now() - start < 3s) {
        slow.receiveSome(65536);
        std::this_thread::sleep_for(100ms);
    }
    const WebStats st = monitor->stats();
    EXPECT_EQ(st.viewers, 2);
    EXPECT_EQ(st.viewersStalled, 0u);
    EXPECT_GE(st.viewerFramesDropped, 3u);
    EXPECT_GE(stream.viewer->frames(), 15);
    EXPECT_GE(test::completeParts(slow.buffer()), 1)
        << slow.buffer().size() << " bytes read, JPEGs of " << st.jpegBytes;
    std::printf("slow viewer: %d frames in 3 s, fast viewer %d, %llu skipped, JPEG %zu bytes\n",
                test::completeParts(slow.buffer()), stream.viewer->frames(),
                static_cast<unsigned long long>(st.viewerFramesDropped), st.jpegBytes);
}

TEST_F(WebMonitorTest, ABusyStreamLimitAnswers503) {
    WebMonitorSettings s = test::testSettings();
    s.maxStreams = 2;
    ASSERT_TRUE(start(s));
    FrameProducer producer(*monitor, 30.0, 320, 180, false);
    auto a = std::make_unique<StreamViewer>(monitor->port());
    StreamViewer b(monitor->port());
    ASSERT_TRUE(a->waitFrames(1, 10s));
    ASSERT_TRUE(b.waitFrames(1, 10s));
    const test::HttpReply third = test::get(monitor->port(), "/stream.mjpeg");
    EXPECT_EQ(third.status, 503);
    EXPECT_NE(third.head.find("Retry-After"), std::string::npos);
    EXPECT_EQ(monitor->stats().busy, 1u);
    // Viewing the status still works while the streams are full.
    EXPECT_EQ(test::get(monitor->port(), "/status.json").status, 200);
    a.reset();
    ASSERT_TRUE(test::eventually([&] { return monitor->stats().viewers == 1; }));
    StreamViewer c(monitor->port());
    EXPECT_TRUE(c.waitFrames(1, 10s));
}

TEST_F(WebMonitorTest, ControlNeedsTheToken) {
    ASSERT_TRUE(start());
    const int port = monitor->port();
    EXPECT_EQ(test::post(port, "/mode", "toggle").status, 401);
    EXPECT_EQ(test::post(port, "/mode", "toggle", "Authorization: Bearer wrong\r\n").status, 401);
    EXPECT_EQ(test::post(port, "/record", "start", "Authorization: s3cret-token\r\n").status, 401);
    EXPECT_EQ(service.commandCount(), 0u);
    EXPECT_EQ(service.currentMode(), "preview");
    EXPECT_EQ(monitor->stats().unauthorized, 3u);

    const std::string auth = "Authorization: Bearer s3cret-token\r\n";
    const test::HttpReply toggled = test::post(port, "/mode", "toggle", auth);
    EXPECT_EQ(toggled.status, 200);
    EXPECT_EQ(nlohmann::json::parse(toggled.body)["mode"], "refine");
    EXPECT_EQ(service.currentMode(), "refine");
    EXPECT_EQ(test::post(port, "/mode", "preview\n", auth).status, 200);
    EXPECT_EQ(test::post(port, "/record", "start", auth).status, 200);
    EXPECT_EQ(test::post(port, "/record", "stop", auth).status, 200);
    EXPECT_EQ(test::post(port, "/mode", "fast", auth).status, 400);
    EXPECT_EQ(test::post(port, "/record", "toggle", auth).status, 400);
    EXPECT_EQ(service.commands,
              (std::vector<std::string>{"toggle", "mode preview", "record start", "record stop"}));
    EXPECT_EQ(monitor->stats().commands, 4u);
    service.refuse = true;
    EXPECT_EQ(test::post(port, "/record", "start", auth).status, 409);
}

// The page's sign-in (GET /control) checks a token without doing anything, and the status says
// whether control is on at all (the page then says so instead of offering a sign-in).
TEST_F(WebMonitorTest, SignInChecksTheTokenAndDoesNothing) {
    ASSERT_TRUE(start());
    const int port = monitor->port();
    EXPECT_EQ(test::get(port, "/control").status, 401);
    EXPECT_EQ(test::get(port, "/control", "Authorization: Bearer wrong\r\n").status, 401);
    EXPECT_EQ(test::get(port, "/control", "Authorization: Bearer s3cret-token\r\n").status, 200);
    EXPECT_EQ(test::post(port, "/control", "x").status, 405);
    EXPECT_EQ(service.commandCount(), 0u);
    EXPECT_EQ(monitor->stats().unauthorized, 2u);
    EXPECT_EQ(nlohmann::json::parse(test::get(port, "/status.json").body)["web"]["control"], true);

    WebMonitorSettings s = test::testSettings();
    s.token.clear();
    auto off = test::startMonitor(service, s);
    ASSERT_TRUE(off);
    EXPECT_EQ(test::get(off->port(), "/control", "Authorization: Bearer \r\n").status, 403);
    EXPECT_EQ(nlohmann::json::parse(test::get(off->port(), "/status.json").body)["web"]["control"],
              false);
}

// previsd's statusJson writes "web": null when it has no monitor's counters (a test server, a
// status taken before the monitor opened): the monitor's own are served, with web.control.
TEST(WebMonitor, AStatusWithANullWebGetsTheMonitorsCounters) {
    Result<std::unique_ptr<WebMonitor>> m = WebMonitor::create(
        test::testSettings(),
        {.statusJson = [] { return std::string(R"({"web":null})"); }, .command = {}});
    ASSERT_TRUE(m.ok()) << m.message();
    const nlohmann::json j =
        nlohmann::json::parse(test::get((*m)->port(), "/status.json").body, nullptr, false);
    ASSERT_TRUE(j.is_object());
    EXPECT_EQ(j["web"]["viewers"], 0);
    EXPECT_EQ(j["web"]["control"], true);
}

TEST_F(WebMonitorTest, WithoutATokenControlIsOffAndViewingWorks) {
    WebMonitorSettings s = test::testSettings();
    s.token.clear();
    ASSERT_TRUE(start(s));
    EXPECT_EQ(test::post(monitor->port(), "/mode", "toggle", "Authorization: Bearer \r\n").status,
              403);
    EXPECT_EQ(test::post(monitor->port(), "/mode", "toggle").status, 403);
    EXPECT_EQ(service.commandCount(), 0u);
    EXPECT_EQ(monitor->stats().forbidden, 2u);
    EXPECT_EQ(test::get(monitor->port(), "/").status, 200);
    EXPECT_EQ(test::get(monitor->port(), "/status.json").status, 200);
}

TEST(WebMonitor, AHookThatThrowsIsAnswered500) {
    WebMonitorSettings s = test::testSettings();
    Result<std::unique_ptr<WebMonitor>> m = WebMonitor::create(
        s, {.statusJson = []() -> std::string { throw std::runtime_error("status broke"); },
            .command = {}});
    ASSERT_TRUE(m.ok()) << m.message();
    const test::HttpReply r = test::get((*m)->port(), "/status.json");
    EXPECT_EQ(r.status, 500);
    EXPECT_NE(r.body.find("status broke"), std::string::npos);
    EXPECT_EQ((*m)->stats().internalError, 1u);
    EXPECT_EQ(test::get((*m)->port(), "/").status, 200);
}

}  // namespace
}  // namespace previs
