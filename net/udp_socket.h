#pragma once

// A UDP socket that owns its fd (UniqueFD): a sender connected to one destination (unicast or a
// multicast group) or a receiver bound to a local address.
//
// Sending runs on the tracking thread, so it never blocks: the socket is non-blocking and a full
// send buffer drops the datagram (counted in droppedCount()) instead of stalling the frame loop.
//     auto out = UdpSocket::sender("192.168.1.20:40000");      // or "[fe80::1%eth0]:40000"
//     if (!out) logError("[freed] out: {}", out.message());
//     out->send(packet.bytes);                                 // per frame, never blocks
//     auto group = UdpSocket::multicastSender("239.135.1.1", 55555);
//     auto in = UdpSocket::receiver("0.0.0.0:40000");
//     int n = in->receive(buffer, 10);                         // bytes, or −EAGAIN after 10 ms

#include <atomic>
#include <cstdint>
#include <span>
#include <string>
#include <utility>

#include "base/result.h"
#include "base/unique_fd.h"

namespace previs {

// "HOST:PORT" split: HOST a name, an IPv4 address or a bracketed IPv6 address ("[::1]:9000").
Result<std::pair<std::string, std::string>> splitHostPort(const std::string& hostPort);

class UdpSocket {
public:
    enum class SendStatus { Sent, Dropped, Failed };

    // A sender to HOST:PORT (IPv4 or IPv6, a name resolved once with getaddrinfo).
    // `handedOver`: a UDP socket made by someone else to send from (systemd's socket
    // activation, so the service itself needs no network: docs/systemd.md), connected here
    // to the first address of its family; none: a new socket.
    static Result<UdpSocket> sender(const std::string& hostPort, UniqueFD handedOver = {});
    // A sender to an IPv4 multicast group. `ttl` is the hop limit (1: this subnet);
    // `interfaceAddress` ("" for the kernel's choice) is the local IPv4 address to send from.
    static Result<UdpSocket> multicastSender(const std::string& group, uint16_t port, int ttl = 1,
                                             const std::string& interfaceAddress = "",
                                             UniqueFD handedOver = {});
    // A receiver bound to HOST:PORT ("0.0.0.0:40000"; port 0 picks a free one, see localPort()).
    // `multicastGroup`, when given, is joined (IPv4) on the kernel's default interface.
    static Result<UdpSocket> receiver(const std::string& hostPort,
                                      const std::string& multicastGroup = "");
    // A receiver on a bound socket made by someone else (systemd's socket activation).
    static UdpSocket adoptReceiver(UniqueFD fd) { return UdpSocket(std::move(fd)); }

    UdpSocket(UdpSocket&& other) noexcept;
    UdpSocket& operator=(UdpSocket&& other) noexcept;

    // Sends one datagram without blocking. Dropped: the send buffer was full (EAGAIN/ENOBUFS);
    // Failed: another error (e.g. ECONNREFUSED after an ICMP port unreachable: nobody listens
    // yet), counted in failedCount(). Neither is fatal: the next frame tries again.
    SendStatus send(std::span<const uint8_t> datagram);

    // Receives one datagram into `buffer`: its size (a larger datagram is truncated to the
    // buffer and reported with its full size, so the caller can reject it), or −errno; −EAGAIN
    // when nothing came within `timeoutMs` (0: do not wait).
    int receive(std::span<uint8_t> buffer, int timeoutMs);

    uint16_t localPort() const;
    int fd() const { return fd_.get(); }
    uint64_t sentCount() const { return sent_.load(std::memory_order_relaxed); }
    uint64_t droppedCount() const { return dropped_.load(std::memory_order_relaxed); }
    uint64_t failedCount() const { return failed_.load(std::memory_order_relaxed); }

private:
    explicit UdpSocket(UniqueFD fd) : fd_(std::move(fd)) {}

    UniqueFD fd_;
    // Atomic: status readers run on other threads than the sender.
    std::atomic<uint64_t> sent_{0}, dropped_{0}, failed_{0};
};

}  // namespace previs
