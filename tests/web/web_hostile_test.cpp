// Hostile clients on the set's network (issue 52), each against the real server on loopback:
// a crowd of connections, a flood of header lines, slow and idle clients, thousands of ranges,
// a rebinding Host, and a status whose names are not UTF-8.

#include <dirent.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "tests/web/monitor_fixture.h"
#include "tests/web/web_test_support.h"
#include "web/web_monitor.h"

namespace previs {
namespace {

using namespace std::chrono_literals;
using test::RawConnection;

class WebHostile : public test::MonitorTest {};

int openDescriptors() {
    int n = 0;
    DIR* d = ::opendir("/proc/self/fd");
    if (!d) return -1;
    while (::readdir(d)) ++n;
    ::closedir(d);
    return n;
}

// A field of /proc/self/status in KiB (VmRSS, VmHWM).
long statusKiB(const std::string& field) {
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind(field + ":", 0) == 0) return std::stol(line.substr(field.size() + 1));
    return -1;
}

// Starts a new peak (VmHWM) at the present resident size; false where the kernel refuses.
bool resetPeakMemory() {
    std::ofstream out("/proc/self/clear_refs");
    out << "5";
    out.flush();
    return bool(out);
}

// Sends `request` and reads until the reply is whole or the server closes.
test::HttpReply answerOn(RawConnection& c, const std::string& request) {
    if (!c.send(request)) return {};
    const auto end = std::chrono::steady_clock::now() + 10s;
    while (!test::replyComplete(c.buffer()) && std::chrono::steady_clock::now() < end)
        if (!c.receiveFor(20ms)) break;
    return test::parseReply(c.buffer());
}

// Two request workers and one stream: a few clients that held a worker each would take them
// all, which the cases of slow and idle clients check they do not.
WebMonitorSettings twoWorkers() {
    WebMonitorSettings s = test::testSettings();
    s.maxStreams = 1;
    s.requestThreads = 2;
    return s;
}

// `count` connections to the monitor, opened and left silent.
std::vector<std::unique_ptr<RawConnection>> openConnections(int port, int count) {
    std::vector<std::unique_ptr<RawConnection>> connections;
    for (int i = 0; i < count; ++i) connections.push_back(std::make_unique<RawConnection>(port));
    return connections;
}

// Beyond its bound per address, or the bound of all, a connection is answered 503 and closed at
// once: it keeps no descriptor of the service and takes no worker.
TEST_F(WebHostile, ConnectionsBeyondTheBoundsAreRefusedAndClosed) {
    WebMonitorSettings s = test::testSettings();
    s.maxConnectionsPerAddress = 3;
    s.maxConnections = 5;
    ASSERT_TRUE(start(s));
    const int port = monitor->port();
    std::vector<std::unique_ptr<RawConnection>> held = openConnections(port, 3);
    ASSERT_TRUE(test::eventually([&] { return monitor->stats().connections == 3; }));
    RawConnection fourth(port);
    EXPECT_TRUE(fourth.receiveToClose(10s)) << "the 4th connection of one address stayed open";
    EXPECT_EQ(test::parseReply(fourth.buffer()).status, 503);
    // Another address still gets in, up to the bound of all.
    for (int i = 0; i < 2; ++i)
        held.push_back(std::make_unique<RawConnection>(port, 0, "127.0.0.2"));
    ASSERT_TRUE(test::eventually([&] { return monitor->stats().connections == 5; }));
    RawConnection sixth(port, 0, "127.0.0.3");
    EXPECT_TRUE(sixth.receiveToClose(10s)) << "a connection beyond the bound of all stayed open";
    EXPECT_EQ(test::parseReply(sixth.buffer()).status, 503);
    EXPECT_EQ(monitor->stats().connectionsRefused, 2u);
    // A held connection still works, and a freed slot is taken again.
    EXPECT_EQ(answerOn(*held[0],
                       "GET /status.json HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                       "Connection: close\r\n\r\n")
                  .status,
              200);
    held.erase(held.begin());
    ASSERT_TRUE(test::eventually([&] { return monitor->stats().connections == 4; }));
    EXPECT_EQ(test::get(port, "/status.json").status, 200);
}

// The review's 1100 idle connections, scaled down: the service holds at most its bound of them,
// whatever the crowd (each client socket here is one descriptor of this process; the service's
// own are what is left).
TEST_F(WebHostile, AnIdleCrowdHoldsFewDescriptors) {
    ASSERT_TRUE(start());
    const WebMonitorSettings defaults;
    const int before = openDescriptors();
    constexpr int kCrowd = 300;
    std::vector<std::unique_ptr<RawConnection>> crowd;
    for (int i = 0; i < kCrowd; ++i) {
        crowd.push_back(std::make_unique<RawConnection>(monitor->port()));
        ASSERT_TRUE(crowd.back()->connected());
    }
    // Every connection accepted: held or refused.
    ASSERT_TRUE(test::eventually([&] {
        const WebStats st = monitor->stats();
        return uint64_t(st.connections) + st.connectionsRefused == kCrowd;
    })) << monitor->stats().connections
        << " held, " << monitor->stats().connectionsRefused << " refused";
    // A refused connection is counted before its descriptor is closed (after its 503 is sent):
    // the bound holds once the refusals are done, not at the instant of the count (the CI's
    // sanitized run once saw 17 for the bound of 16).
    auto serviceHeld = [&] { return openDescriptors() - before - kCrowd; };
    EXPECT_TRUE(test::eventually([&] {
        return serviceHeld() <= defaults.maxConnectionsPerAddress;
    })) << serviceHeld()
        << " descriptors held";
    std::printf("%d idle connections: the service holds %d descriptors for them\n", kCrowd,
                serviceHeld());
    EXPECT_EQ(monitor->stats().connections, defaults.maxConnectionsPerAddress);
}

// A flood of header lines, each within the library's line limit: the request is answered 431
// once its headers pass the bound, and the service's memory does not follow the flood (the
// review saw 3 bytes of memory per byte sent, never given back).
TEST_F(WebHostile, AHeaderFloodIsCutOffWithoutMemoryGrowth) {
    ASSERT_TRUE(start());
    std::string chunk;
    for (int i = 0; chunk.size() < 65536; ++i)
        chunk += "X-Flood-" + std::to_string(i) + ": " + std::string(1000, 'f') + "\r\n";
    constexpr size_t kFloodBytes = size_t(32) << 20;
    const bool peakReset = resetPeakMemory();
    const long rssBefore = statusKiB("VmRSS");
    RawConnection c(monitor->port());
    ASSERT_TRUE(c.send("GET /status.json HTTP/1.1\r\nHost: 127.0.0.1\r\n"));
    size_t sent = 0;
    while (sent < kFloodBytes && c.send(chunk)) sent += chunk.size();
    EXPECT_TRUE(c.receiveToClose(10s)) << "the flooding connection stayed open";
    const long grownKiB = (peakReset ? statusKiB("VmHWM") : statusKiB("VmRSS")) - rssBefore;
    std::printf("%zu MiB of headers sent (of %zu): memory grew %ld KiB (%s)\n", sent >> 20,
                kFloodBytes >> 20, grownKiB, peakReset ? "peak" : "after");
    EXPECT_LT(grownKiB, 16 * 1024);
    EXPECT_EQ(test::parseReply(c.buffer()).status, 431);
    EXPECT_EQ(monitor->stats().headersTooLarge, 1u);
    EXPECT_EQ(test::get(monitor->port(), "/status.json").status, 200);
}

// Many short header lines, together within the byte bound, beyond the bound of lines: 431.
TEST_F(WebHostile, TooManyHeaderLinesAre431) {
    ASSERT_TRUE(start());
    std::string request = "GET /status.json HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n";
    for (int i = 0; i < 200; ++i) request += "X-" + std::to_string(i) + ": a\r\n";
    EXPECT_EQ(test::roundTrip(monitor->port(), request + "\r\n").status, 431);
    EXPECT_EQ(monitor->stats().headersTooLarge, 1u);
}

// The review's slowloris: more connections than workers, each dribbling its request a byte at a
// time within the read timeout. The status is served meanwhile, and each dribbler is answered
// 408 at its request's deadline.
TEST_F(WebHostile, SlowlorisClientsHoldNoWorkerPastTheDeadline) {
    WebMonitorSettings s = twoWorkers();
    s.readTimeoutMs = 2000;
    s.requestDeadlineMs = 3000;
    ASSERT_TRUE(start(s));
    const int port = monitor->port();
    std::vector<std::unique_ptr<RawConnection>> slow = openConnections(port, 14);
    // And one that sends its head whole, then withholds the body it declared.
    auto withheld = std::make_unique<RawConnection>(port);
    ASSERT_TRUE(
        withheld->send("POST /record HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 5\r\n\r\nst"));
    std::atomic<bool> stop{false};
    std::thread dribble([&] {
        const std::string request =
            "GET /status.json HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: " + std::string(200, 's');
        for (size_t i = 0; i < request.size() && !stop; ++i) {
            for (auto& c : slow) c->send(request.substr(i, 1));
            std::this_thread::sleep_for(200ms);
        }
    });
    std::this_thread::sleep_for(500ms);  // every dribbler has begun its request
    const auto start = std::chrono::steady_clock::now();
    const test::HttpReply status = test::get(port, "/status.json");
    const auto took = std::chrono::steady_clock::now() - start;
    EXPECT_EQ(status.status, 200) << "the status waited behind the slow clients";
    for (auto& c : slow) {
        EXPECT_TRUE(c->receiveToClose(10s)) << "a dribbler was not cut off at the deadline";
        EXPECT_EQ(test::parseReply(c->buffer()).status, 408);
    }
    stop = true;
    dribble.join();
    EXPECT_TRUE(withheld->receiveToClose(10s)) << "a withheld body kept its connection";
    EXPECT_EQ(test::parseReply(withheld->buffer()).status, 408);
    EXPECT_EQ(monitor->stats().requestTimeout, 15u);
    EXPECT_EQ(service.commandCount(), 0u);
    std::printf("status served in %lld ms beside 14 dribbling clients\n",
                static_cast<long long>(
                    std::chrono::duration_cast<std::chrono::milliseconds>(took).count()));
}

// Idle connections, new and kept alive, many more than the workers: they take none, so a new
// request is answered at once, not after their timeouts.
TEST_F(WebHostile, IdleConnectionsTakeNoWorker) {
    WebMonitorSettings s = twoWorkers();
    s.readTimeoutMs = 30000;
    s.keepAliveTimeoutS = 30;
    s.maxConnectionsPerAddress = 32;
    ASSERT_TRUE(start(s));
    const int port = monitor->port();
    std::vector<std::unique_ptr<RawConnection>> idle = openConnections(port, 10);
    for (int i = 0; i < 10; ++i) {
        idle.push_back(std::make_unique<RawConnection>(port));
        EXPECT_EQ(
            answerOn(*idle.back(), "GET /status.json HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n").status,
            200);
    }
    const test::HttpReply status = test::roundTrip(
        port, "GET /status.json HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n", 10s);
    EXPECT_EQ(status.status, 200) << "a request waited behind idle connections";
    EXPECT_EQ(monitor->stats().connections, 20);
}

// Clients that pipeline requests and never read the answers (a slow-read attack), more of them
// than the workers: their answers wait in the kernel, not in a worker blocked on writing, so a
// new request is answered at once.
TEST_F(WebHostile, ClientsThatReadNoAnswersHoldNoWorker) {
    WebMonitorSettings s = twoWorkers();
    s.writeTimeoutMs = 30000;
    s.keepAliveTimeoutS = 30;
    ASSERT_TRUE(start(s));
    const int port = monitor->port();
    std::string pipelined;
    // 2000 pages (about 16 MiB) each: more than Linux would queue for a socket (4 MiB at most).
    for (int i = 0; i < 2000; ++i) pipelined += "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n";
    std::vector<std::unique_ptr<RawConnection>> readers;
    for (int i = 0; i < 4; ++i) {
        readers.push_back(std::make_unique<RawConnection>(port, 4096));
        ASSERT_TRUE(readers.back()->send(pipelined));
    }
    ASSERT_TRUE(test::eventually([&] { return monitor->stats().requests >= 4 * 5; }));
    const test::HttpReply status = test::get(port, "/status.json");
    EXPECT_EQ(status.status, 200) << "a request waited behind clients that read nothing";
    EXPECT_LT(monitor->stats().requests, 4u * 2000u);
}

// Thousands of ranges over the page: one whole answer, not a copy of the page per range (the
// review turned 7.9 KB of request into 19.9 MB of answer).
TEST_F(WebHostile, ManyRangesAreAnsweredOnceInFull) {
    ASSERT_TRUE(start());
    const test::HttpReply plain = test::get(monitor->port(), "/");
    ASSERT_EQ(plain.status, 200);
    std::string ranges = "bytes=0-";
    for (int i = 0; i < 2000; ++i) ranges += ",0-";
    const test::HttpReply ranged =
        test::roundTrip(monitor->port(), "GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nRange: " + ranges +
                                             "\r\nConnection: close\r\n\r\n");
    EXPECT_EQ(ranged.status, 200);
    EXPECT_EQ(ranged.body.size(), plain.body.size());
}

TEST_F(WebHostile, HostIsThisMonitorAcceptsAddressesLocalhostAndTheNamesGiven) {
    const std::vector<std::string> names = {"previs-box.local"};
    for (const char* good :
         {"", "127.0.0.1", "127.0.0.1:8080", "10.1.2.3:80", "[::1]:8080", "[fe80::1]", "localhost",
          "LOCALHOST:8080", "cam.localhost", "previs-box.local", "Previs-Box.Local.:8080"})
        EXPECT_TRUE(hostIsThisMonitor(good, names)) << good;
    for (const char* bad :
         {"evil.example", "evil.example:8080", "previs-box.local.evil.example", "127.0.0.1.nip.io",
          "localhost.evil.example", "[::1", "::1", "[not-an-ip]:80"})
        EXPECT_FALSE(hostIsThisMonitor(bad, names)) << bad;
}

// DNS rebinding: a page from another name that resolves to the box sends that name as Host; it
// is refused (421) on every path, while the box's own addresses and names are served.
TEST_F(WebHostile, AForeignHostIsMisdirected) {
    WebMonitorSettings s = test::testSettings();
    s.hostNames = {"previs-box.local"};
    ASSERT_TRUE(start(s));
    const int port = monitor->port();
    auto getWithHost = [&](const std::string& path, const std::string& host) {
        return test::roundTrip(
            port, "GET " + path + " HTTP/1.1\r\nHost: " + host + "\r\nConnection: close\r\n\r\n");
    };
    for (const char* path : {"/status.json", "/stream.mjpeg", "/"}) {
        const test::HttpReply r = getWithHost(path, "rebind.evil.example:" + std::to_string(port));
        EXPECT_EQ(r.status, 421) << path;
        EXPECT_EQ(r.body.find("\"mode\""), std::string::npos);
    }
    EXPECT_EQ(test::roundTrip(port,
                              "POST /record HTTP/1.1\r\nHost: rebind.evil.example\r\n"
                              "Authorization: Bearer s3cret-token\r\nConnection: close\r\n"
                              "Content-Length: 5\r\n\r\nstart")
                  .status,
              421);
    EXPECT_EQ(service.commandCount(), 0u);
    EXPECT_EQ(monitor->stats().misdirected, 4u);
    const std::string p = std::to_string(port);
    for (const std::string& host : std::vector<std::string>{
             "127.0.0.1:" + p, "localhost:" + p, "previs-box.local:" + p, "PREVIS-BOX.LOCAL"})
        EXPECT_EQ(getWithHost("/status.json", host).status, 200) << host;
    EXPECT_EQ(test::roundTrip(port, "GET /status.json HTTP/1.0\r\n\r\n").status, 200);
}

TEST_F(WebHostile, ValidUtf8ReplacesOnlyWhatIsIllFormed) {
    EXPECT_EQ(validUtf8("plain"), "plain");
    EXPECT_EQ(validUtf8("caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x8e\xa5"),
              "caf\xc3\xa9 \xe2\x82\xac \xf0\x9f\x8e\xa5");
    EXPECT_EQ(validUtf8("a\xff"
                        "b"),
              "a\xef\xbf\xbd"
              "b");
    EXPECT_EQ(validUtf8("\xc0\xaf"), "\xef\xbf\xbd\xef\xbf\xbd");                  // overlong '/'
    EXPECT_EQ(validUtf8("\xed\xa0\x80"), "\xef\xbf\xbd\xef\xbf\xbd\xef\xbf\xbd");  // surrogate
    EXPECT_EQ(validUtf8("\xe2\x82"), "\xef\xbf\xbd");                              // cut short
    EXPECT_EQ(validUtf8("\xf4\x90\x80\x80"),                                       // above U+10FFFF
              "\xef\xbf\xbd\xef\xbf\xbd\xef\xbf\xbd\xef\xbf\xbd");
}

// A camera named with bytes that are not UTF-8 (a V4L2 card name, a USB string): /status.json
// is still valid JSON, the names readable with U+FFFD where the bytes were.
TEST_F(WebHostile, StatusIsValidJsonWhateverTheNamesHold) {
    WebMonitorSettings s = test::testSettings();
    Result<std::unique_ptr<WebMonitor>> m = WebMonitor::create(
        s, {.statusJson =
                [] {
                    return std::string(
                        "{\"mode\":\"preview\",\"cameras\":{\"scene\":\"cam\xff\xfe\","
                        "\"fisheye\":\"\xc3\"}}");
                },
            .command = {}});
    ASSERT_TRUE(m.ok()) << m.message();
    const test::HttpReply r = test::get((*m)->port(), "/status.json");
    ASSERT_EQ(r.status, 200);
    const nlohmann::json j = nlohmann::json::parse(r.body, nullptr, false);
    ASSERT_FALSE(j.is_discarded()) << r.body;
    EXPECT_EQ(j["cameras"]["scene"], "cam\xef\xbf\xbd\xef\xbf\xbd");
    EXPECT_EQ(j["cameras"]["fisheye"], "\xef\xbf\xbd");
    EXPECT_TRUE(j.contains("web"));
}

}  // namespace
}  // namespace previs
