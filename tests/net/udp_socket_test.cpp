// UDP sockets on the loopback interface: address parsing, a datagram each way, timeouts, and a
// sender that never blocks. No timing asserts: only outcomes.

#include "net/udp_socket.h"

#include <gtest/gtest.h>
#include <sys/socket.h>

#include <cerrno>
#include <vector>

namespace previs {
namespace {

TEST(UdpSocket, SplitsHostAndPort) {
    auto v4 = splitHostPort("192.168.1.20:40000");
    ASSERT_TRUE(v4.ok());
    EXPECT_EQ(v4->first, "192.168.1.20");
    EXPECT_EQ(v4->second, "40000");
    auto v6 = splitHostPort("[fe80::1%eth0]:6301");
    ASSERT_TRUE(v6.ok());
    EXPECT_EQ(v6->first, "fe80::1%eth0");
    auto name = splitHostPort("unreal-box.local:40000");
    ASSERT_TRUE(name.ok());
    EXPECT_EQ(name->first, "unreal-box.local");
    auto any = splitHostPort(":40000");
    ASSERT_TRUE(any.ok());
    EXPECT_EQ(any->first, "");
    for (const char* bad : {"host", "host:", "host:70000", "host:12a", "::1:5000", "[::1]5000"}) {
        auto r = splitHostPort(bad);
        EXPECT_FALSE(r.ok()) << bad;
        if (!r.ok()) {
            EXPECT_NE(r.message().find(bad), std::string::npos) << r.message();
        }
    }
}

TEST(UdpSocket, SendsAndReceivesOnIpv4Loopback) {
    auto rx = UdpSocket::receiver("127.0.0.1:0");
    ASSERT_TRUE(rx.ok()) << rx.message();
    auto tx = UdpSocket::sender(fmt::format("127.0.0.1:{}", rx->localPort()));
    ASSERT_TRUE(tx.ok()) << tx.message();
    std::vector<uint8_t> datagram = {0xD1, 1, 2, 3};
    EXPECT_EQ(tx->send(datagram), UdpSocket::SendStatus::Sent);
    EXPECT_EQ(tx->sentCount(), 1u);
    std::vector<uint8_t> buffer(64);
    int n = rx->receive(buffer, 5000);  // a generous bound; returns as soon as it arrives
    ASSERT_EQ(n, 4);
    EXPECT_EQ(std::vector<uint8_t>(buffer.begin(), buffer.begin() + n), datagram);
}

TEST(UdpSocket, SendsAndReceivesOnIpv6Loopback) {
    auto rx = UdpSocket::receiver("[::1]:0");
    if (!rx.ok()) GTEST_SKIP() << "no IPv6 loopback here: " << rx.message();
    auto tx = UdpSocket::sender(fmt::format("[::1]:{}", rx->localPort()));
    ASSERT_TRUE(tx.ok()) << tx.message();
    std::vector<uint8_t> datagram(29, 0x55);
    EXPECT_EQ(tx->send(datagram), UdpSocket::SendStatus::Sent);
    std::vector<uint8_t> buffer(64);
    EXPECT_EQ(rx->receive(buffer, 5000), 29);
}

TEST(UdpSocket, ResolvesNames) {
    auto rx = UdpSocket::receiver("localhost:0");
    ASSERT_TRUE(rx.ok()) << rx.message();
    EXPECT_NE(rx->localPort(), 0);
}

TEST(UdpSocket, ReportsAnOversizedDatagramWithItsFullSize) {
    auto rx = UdpSocket::receiver("127.0.0.1:0");
    ASSERT_TRUE(rx.ok());
    auto tx = UdpSocket::sender(fmt::format("127.0.0.1:{}", rx->localPort()));
    ASSERT_TRUE(tx.ok());
    std::vector<uint8_t> big(100, 1);
    tx->send(big);
    std::vector<uint8_t> buffer(29);
    EXPECT_EQ(rx->receive(buffer, 5000), 100);  // the caller sees 100 ≠ 29 and rejects it
}

TEST(UdpSocket, ReceiveWithoutDataReturnsEagain) {
    auto rx = UdpSocket::receiver("127.0.0.1:0");
    ASSERT_TRUE(rx.ok());
    std::vector<uint8_t> buffer(64);
    EXPECT_EQ(rx->receive(buffer, 0), -EAGAIN);
    EXPECT_EQ(rx->receive(buffer, 1), -EAGAIN);
}

TEST(UdpSocket, SendNeverBlocksWhenNobodyReads) {
    // A receiver that never reads, with the smallest buffers: the kernel drops what does not
    // fit. Every send must return (this test would hang otherwise) and be counted.
    auto rx = UdpSocket::receiver("127.0.0.1:0");
    ASSERT_TRUE(rx.ok());
    auto tx = UdpSocket::sender(fmt::format("127.0.0.1:{}", rx->localPort()));
    ASSERT_TRUE(tx.ok());
    int small = 1;
    setsockopt(tx->fd(), SOL_SOCKET, SO_SNDBUF, &small, sizeof small);
    setsockopt(rx->fd(), SOL_SOCKET, SO_RCVBUF, &small, sizeof small);
    std::vector<uint8_t> datagram(1400, 0xAB);
    constexpr int kSends = 5000;
    for (int i = 0; i < kSends; ++i) tx->send(datagram);
    EXPECT_EQ(tx->sentCount() + tx->droppedCount() + tx->failedCount(), uint64_t(kSends));
}

TEST(UdpSocket, SendToAClosedPortIsCountedNotFatal) {
    uint16_t port;
    {
        auto probe = UdpSocket::receiver("127.0.0.1:0");
        ASSERT_TRUE(probe.ok());
        port = probe->localPort();
    }  // closed: nobody listens there now
    auto tx = UdpSocket::sender(fmt::format("127.0.0.1:{}", port));
    ASSERT_TRUE(tx.ok());
    std::vector<uint8_t> datagram(29, 0);
    for (int i = 0; i < 10; ++i) tx->send(datagram);
    EXPECT_EQ(tx->sentCount() + tx->failedCount() + tx->droppedCount(), 10u);
}

TEST(UdpSocket, MulticastSender) {
    auto tx = UdpSocket::multicastSender("239.135.1.1", 55555, 1);
    ASSERT_TRUE(tx.ok()) << tx.message();
    auto notMulticast = UdpSocket::multicastSender("192.168.1.1", 55555);
    ASSERT_FALSE(notMulticast.ok());
    EXPECT_NE(notMulticast.message().find("192.168.1.1"), std::string::npos);
    EXPECT_FALSE(UdpSocket::multicastSender("239.135.1.1", 55555, 1, "not-an-address").ok());
}

TEST(UdpSocket, MulticastReachesAMemberOnThisHost) {
    // The kernel loops multicast back to members on the sending host (IP_MULTICAST_LOOP is on by
    // default). A host without a multicast route cannot run this: it skips, saying so.
    auto rx = UdpSocket::receiver("0.0.0.0:0", "239.135.1.200");
    if (!rx.ok()) GTEST_SKIP() << "cannot join a multicast group here: " << rx.message();
    auto tx = UdpSocket::multicastSender("239.135.1.200", rx->localPort(), 0);
    ASSERT_TRUE(tx.ok()) << tx.message();
    std::vector<uint8_t> datagram = {'O', 'T', 'r', 'k'};
    if (tx->send(datagram) != UdpSocket::SendStatus::Sent) {
        GTEST_SKIP() << "no multicast route on this host";
    }
    std::vector<uint8_t> buffer(16);
    int n = rx->receive(buffer, 2000);
    if (n == -EAGAIN) GTEST_SKIP() << "multicast is not looped back on this host";
    EXPECT_EQ(n, 4);
}

TEST(UdpSocket, ErrorsNameTheAddress) {
    auto bad = UdpSocket::sender("no-such-host.invalid:40000");
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.message().find("no-such-host.invalid"), std::string::npos) << bad.message();
    auto used = UdpSocket::receiver("127.0.0.1:0");
    ASSERT_TRUE(used.ok());
    // TEST-NET-3 (RFC 5737): documentation-only, so no machine has it as its own address.
    auto badBind = UdpSocket::receiver("203.0.113.77:0");
    ASSERT_FALSE(badBind.ok());
    EXPECT_NE(badBind.message().find("203.0.113.77"), std::string::npos);
}

}  // namespace
}  // namespace previs
