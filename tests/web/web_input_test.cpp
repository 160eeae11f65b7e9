// Bad input (issue 39): malformed, oversized, slow or unrouted requests are answered (or
// dropped), counted by kind, and never crash the monitor or stall the frames going in.

#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "tests/web/monitor_fixture.h"
#include "tests/web/synthetic_frames.h"
#include "tests/web/web_test_support.h"
#include "web/web_monitor.h"

namespace previs {
namespace {

using namespace std::chrono_literals;

// After each bad request the monitor still answers, and submitFrame still returns at once.
void expectStillServing(WebMonitor& monitor) {
    const auto start = std::chrono::steady_clock::now();
    monitor.submitFrame(test::syntheticFrame(64, 36, 1));
    EXPECT_LT(std::chrono::steady_clock::now() - start, 50ms);
    EXPECT_EQ(test::get(monitor.port(), "/status.json").status, 200);
}

// The start of a TLS ClientHello, then a blank line: a browser told https:// for this port.
constexpr char kTlsHello[] = "\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\r\n\r\n";

class WebInput : public test::MonitorTest {};

TEST_F(WebInput, MalformedRequestsAreAnswered400) {
    ASSERT_TRUE(start());
    const std::vector<std::string> malformed = {
        "HELLO\r\n\r\n",
        "GET\r\n\r\n",
        "GET / HTTP/9.9 extra words\r\n\r\n",
        "BREW /pot HTTP/1.1\r\nConnection: close\r\n\r\n",
        std::string(kTlsHello, sizeof(kTlsHello) - 1),  // a TLS ClientHello on the HTTP port
    };
    for (const std::string& request : malformed) {
        const test::HttpReply r = test::roundTrip(monitor->port(), request, 5s);
        EXPECT_EQ(r.status, 400) << request.substr(0, 40);
    }
    EXPECT_EQ(monitor->stats().badRequest, malformed.size());
    EXPECT_EQ(service.commandCount(), 0u);
    expectStillServing(*monitor);
}

TEST_F(WebInput, UnknownPathIs404AndWrongMethod405) {
    ASSERT_TRUE(start());
    const int port = monitor->port();
    EXPECT_EQ(test::get(port, "/nope").status, 404);
    EXPECT_EQ(test::get(port, "/../../etc/passwd").status, 404);
    const test::HttpReply getMode = test::get(port, "/mode");
    EXPECT_EQ(getMode.status, 405);
    EXPECT_NE(getMode.head.find("Allow: POST"), std::string::npos);
    EXPECT_EQ(test::post(port, "/status.json", "x").status, 405);
    EXPECT_EQ(test::roundTrip(port, "DELETE / HTTP/1.1\r\nConnection: close\r\n\r\n").status, 405);
    EXPECT_EQ(test::roundTrip(port,
                              "PUT /x HTTP/1.1\r\nConnection: close\r\nContent-Length: 2"
                              "\r\n\r\nhi")
                  .status,
              404);
    const WebStats s = monitor->stats();
    EXPECT_EQ(s.notFound, 3u);
    EXPECT_EQ(s.methodNotAllowed, 3u);
    expectStillServing(*monitor);
}

TEST_F(WebInput, OversizedBodiesAre413AndHeaders431) {
    ASSERT_TRUE(start());
    const int port = monitor->port();
    const std::string auth = "Authorization: Bearer s3cret-token\r\n";
    // Declared too long (refused before reading it); chunked bodies are refused whatever their
    // size (a body is read whole before a worker takes the request, so its length must be known).
    EXPECT_EQ(test::post(port, "/mode", std::string(100000, 'a'), auth).status, 413);
    std::string chunked = "POST /mode HTTP/1.1\r\nConnection: close\r\n" + auth +
                          "Transfer-Encoding: chunked\r\n\r\n";
    for (int i = 0; i < 4; ++i) chunked += "200\r\n" + std::string(512, 'b') + "\r\n";
    chunked += "0\r\n\r\n";
    EXPECT_EQ(test::roundTrip(port, chunked).status, 411);
    // No length at all: refused rather than read until the client closes.
    EXPECT_EQ(
        test::roundTrip(port, "POST /mode HTTP/1.1\r\nConnection: close\r\n" + auth + "\r\n", 5s)
            .status,
        411);
    // Many header lines, each within the library's line limit, together above ours.
    std::string many = "GET /status.json HTTP/1.1\r\nConnection: close\r\n";
    for (int i = 0; i < 40; ++i)
        many += "X-Pad-" + std::to_string(i) + ": " + std::string(500, 'p') + "\r\n";
    EXPECT_EQ(test::roundTrip(port, many + "\r\n").status, 431);
    // One header line above the whole headers' limit.
    EXPECT_EQ(
        test::roundTrip(port, "GET / HTTP/1.1\r\n" + std::string(9000, 'x') + ": y\r\n\r\n").status,
        431);
    // A request line above cpp-httplib's 8 KiB.
    EXPECT_EQ(test::get(port, "/" + std::string(9000, 'u')).status, 414);
    const WebStats s = monitor->stats();
    EXPECT_EQ(s.payloadTooLarge, 1u);
    EXPECT_EQ(s.lengthRequired, 2u);
    EXPECT_EQ(s.headersTooLarge, 2u);
    EXPECT_EQ(s.uriTooLong, 1u);
    EXPECT_EQ(service.commandCount(), 0u);
    expectStillServing(*monitor);
}

// A client that half-closes after its request (nc -N, some scripts) still gets its answer.
TEST_F(WebInput, AHalfClosedClientIsAnswered) {
    ASSERT_TRUE(start());
    test::RawConnection c(monitor->port());
    ASSERT_TRUE(c.send("GET /status.json HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"));
    c.shutdownWrite();
    EXPECT_TRUE(c.receiveToClose(10s));
    EXPECT_EQ(test::parseReply(c.buffer()).status, 200);
    EXPECT_EQ(monitor->stats().silentConnections, 0u);
}

// Clients that connect and then send nothing, or stop mid-request: the silent one is dropped
// after the idle timeout, the others are answered 408 after the read timeout, each counted; and
// meanwhile the page, the status and the stream keep being served even though the slow clients
// outnumber the request workers.
TEST_F(WebInput, SlowClientsAreDroppedWithoutStarvingViewers) {
    WebMonitorSettings s = test::testSettings();
    s.readTimeoutMs = 700;
    s.keepAliveTimeoutS = 1;
    s.requestThreads = 2;
    s.maxStreams = 2;
    ASSERT_TRUE(start(s));
    const int port = monitor->port();
    std::vector<std::unique_ptr<test::RawConnection>> slow;
    for (int i = 0; i < 3; ++i) {
        slow.push_back(std::make_unique<test::RawConnection>(port));
        ASSERT_TRUE(slow.back()->connected());
    }
    ASSERT_TRUE(slow[1]->send("GET /status.json HT"));
    ASSERT_TRUE(slow[2]->send("GET /status.json HTTP/1.1\r\nHost: te"));

    // Served within a read timeout or two even with every worker taken by a slow client.
    const auto start = std::chrono::steady_clock::now();
    EXPECT_EQ(test::get(port, "/status.json").status, 200);
    EXPECT_LT(std::chrono::steady_clock::now() - start, 5s);

    for (auto& c : slow) EXPECT_TRUE(c->receiveToClose(10s)) << "a slow client stayed connected";
    // The two that stopped mid-request got a 408; the silent one was dropped without a word.
    EXPECT_EQ(test::parseReply(slow[1]->buffer()).status, 408);
    EXPECT_EQ(test::parseReply(slow[2]->buffer()).status, 408);
    EXPECT_TRUE(slow[0]->buffer().empty());
    EXPECT_TRUE(test::eventually([&] { return monitor->stats().silentConnections >= 1; }))
        << monitor->stats().silentConnections;
    EXPECT_EQ(monitor->stats().requestTimeout, 2u);

    // A kept-alive client that goes quiet is also let go, after the keep-alive timeout.
    monitor->submitFrame(test::syntheticFrame(64, 36, 2));
    test::StreamViewer viewer(port);
    EXPECT_TRUE(viewer.waitFrames(1, 10s));
    expectStillServing(*monitor);
}

}  // namespace
}  // namespace previs
