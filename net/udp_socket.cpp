#include "net/udp_socket.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <memory>

namespace previs {

namespace {

struct AddrInfoDeleter {
    void operator()(addrinfo* ai) const { freeaddrinfo(ai); }
};
using AddrInfoPtr = std::unique_ptr<addrinfo, AddrInfoDeleter>;

Result<AddrInfoPtr> resolve(const std::string& hostPort, bool passive) {
    auto split = splitHostPort(hostPort);
    if (!split) return split.error();
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    hints.ai_protocol = IPPROTO_UDP;
    hints.ai_flags = passive ? AI_PASSIVE : 0;
    addrinfo* list = nullptr;
    const char* host = split->first.empty() ? nullptr : split->first.c_str();
    int rc = getaddrinfo(host, split->second.c_str(), &hints, &list);
    if (rc != 0) {
        return makeError("'{}': cannot resolve: {} (give a reachable HOST:PORT)", hostPort,
                         gai_strerror(rc));
    }
    return AddrInfoPtr(list);
}

Result<UniqueFD> openSocket(int family) {
    UniqueFD fd(::socket(family, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, IPPROTO_UDP));
    if (!fd.isValid()) return makeError("cannot open a UDP socket: {}", std::strerror(errno));
    return fd;
}

// A socket handed over to send to a `family` address: a datagram socket of that family, made
// non-blocking as ours are.
Status checkHandedOver(int fd, int family) {
    int domain = 0, type = 0;
    socklen_t size = sizeof domain;
    if (::getsockopt(fd, SOL_SOCKET, SO_DOMAIN, &domain, &size) != 0 ||
        ::getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &(size = sizeof type)) != 0 ||
        type != SOCK_DGRAM)
        return makeError("the socket handed over is not a datagram socket");
    if (domain != family)
        return makeError("the socket handed over is {}, the destination {}",
                         domain == AF_INET6 ? "IPv6" : "IPv4",
                         family == AF_INET6 ? "IPv6" : "IPv4");
    const int flags = ::fcntl(fd, F_GETFL);
    if (flags < 0 || ::fcntl(fd, F_SETFL, flags | O_NONBLOCK) != 0)
        return makeError("cannot make the socket handed over non-blocking: {}",
                         std::strerror(errno));
    return {};
}

// The socket to send to a `family` address from: the handed-over one (taken only when it fits),
// else a new one.
Result<UniqueFD> socketFor(int family, UniqueFD& handedOver) {
    if (!handedOver.isValid()) return openSocket(family);
    if (Status st = checkHandedOver(handedOver.get(), family); !st) return st.error();
    return std::move(handedOver);
}

}  // namespace

Result<std::pair<std::string, std::string>> splitHostPort(const std::string& hostPort) {
    std::string host, port;
    if (!hostPort.empty() && hostPort[0] == '[') {
        size_t close = hostPort.find(']');
        if (close == std::string::npos || close + 1 >= hostPort.size() ||
            hostPort[close + 1] != ':') {
            return makeError("'{}': an IPv6 address is written [ADDRESS]:PORT", hostPort);
        }
        host = hostPort.substr(1, close - 1);
        port = hostPort.substr(close + 2);
    } else {
        size_t colon = hostPort.rfind(':');
        if (colon == std::string::npos || hostPort.find(':') != colon) {
            return makeError("'{}': expected HOST:PORT (IPv6 as [ADDRESS]:PORT)", hostPort);
        }
        host = hostPort.substr(0, colon);
        port = hostPort.substr(colon + 1);
    }
    char* end = nullptr;
    long number = port.empty() ? -1 : std::strtol(port.c_str(), &end, 10);
    if (number < 0 || number > 65535 || *end != '\0') {
        return makeError("'{}': the port must be a number from 0 to 65535", hostPort);
    }
    return std::pair(host, port);
}

UdpSocket::UdpSocket(UdpSocket&& other) noexcept
    : fd_(std::move(other.fd_)),
      sent_(other.sent_.load()),
      dropped_(other.dropped_.load()),
      failed_(other.failed_.load()) {}

UdpSocket& UdpSocket::operator=(UdpSocket&& other) noexcept {
    fd_ = std::move(other.fd_);
    sent_ = other.sent_.load();
    dropped_ = other.dropped_.load();
    failed_ = other.failed_.load();
    return *this;
}

Result<UdpSocket> UdpSocket::sender(const std::string& hostPort, UniqueFD handedOver) {
    auto list = resolve(hostPort, false);
    if (!list) return list.error();
    std::string lastError = "no address";
    for (addrinfo* ai = list->get(); ai; ai = ai->ai_next) {
        auto fd = socketFor(ai->ai_family, handedOver);
        if (!fd) {  // e.g. no IPv6 on this host: the next address may be IPv4
            lastError = fd.message();
            continue;
        }
        // connect(): the destination is fixed, send() needs no address and the kernel reports
        // an unreachable port back to us (ECONNREFUSED on a later send).
        if (::connect(fd->get(), ai->ai_addr, ai->ai_addrlen) == 0) {
            return UdpSocket(std::move(*fd));
        }
        lastError = std::strerror(errno);
    }
    return makeError("'{}': cannot reach: {}", hostPort, lastError);
}

Result<UdpSocket> UdpSocket::multicastSender(const std::string& group, uint16_t port, int ttl,
                                             const std::string& interfaceAddress,
                                             UniqueFD handedOver) {
    in_addr groupAddr{};
    if (inet_pton(AF_INET, group.c_str(), &groupAddr) != 1 ||
        !IN_MULTICAST(ntohl(groupAddr.s_addr))) {
        return makeError("'{}': not an IPv4 multicast group (224.0.0.0/4)", group);
    }
    auto fd = socketFor(AF_INET, handedOver);
    if (!fd) return fd.error();
    unsigned char hops = static_cast<unsigned char>(std::clamp(ttl, 0, 255));
    if (setsockopt(fd->get(), IPPROTO_IP, IP_MULTICAST_TTL, &hops, sizeof hops) != 0) {
        return makeError("multicast TTL {}: {}", ttl, std::strerror(errno));
    }
    if (!interfaceAddress.empty()) {
        in_addr local{};
        if (inet_pton(AF_INET, interfaceAddress.c_str(), &local) != 1) {
            return makeError("'{}': the multicast interface must be a local IPv4 address",
                             interfaceAddress);
        }
        if (setsockopt(fd->get(), IPPROTO_IP, IP_MULTICAST_IF, &local, sizeof local) != 0) {
            return makeError("multicast interface {}: {}", interfaceAddress, std::strerror(errno));
        }
    }
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(port);
    to.sin_addr = groupAddr;
    if (::connect(fd->get(), reinterpret_cast<sockaddr*>(&to), sizeof to) != 0) {
        return makeError("{}:{}: cannot send there: {}", group, port, std::strerror(errno));
    }
    return UdpSocket(std::move(*fd));
}

Result<UdpSocket> UdpSocket::receiver(const std::string& hostPort,
                                      const std::string& multicastGroup) {
    auto list = resolve(hostPort, true);
    if (!list) return list.error();
    addrinfo* ai = list->get();
    auto fd = openSocket(ai->ai_family);
    if (!fd) return fd.error();
    int one = 1;
    // Several listeners (a monitor beside the daemon) may share a FreeD or multicast port.
    setsockopt(fd->get(), SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    if (::bind(fd->get(), ai->ai_addr, ai->ai_addrlen) != 0) {
        return makeError("'{}': cannot listen there: {}", hostPort, std::strerror(errno));
    }
    if (!multicastGroup.empty()) {
        ip_mreq join{};
        if (inet_pton(AF_INET, multicastGroup.c_str(), &join.imr_multiaddr) != 1 ||
            setsockopt(fd->get(), IPPROTO_IP, IP_ADD_MEMBERSHIP, &join, sizeof join) != 0) {
            return makeError("'{}': cannot join the multicast group: {}", multicastGroup,
                             std::strerror(errno));
        }
    }
    return UdpSocket(std::move(*fd));
}

UdpSocket::SendStatus UdpSocket::send(std::span<const uint8_t> datagram) {
    ssize_t n = ::send(fd_.get(), datagram.data(), datagram.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
    if (n >= 0) {
        sent_.fetch_add(1, std::memory_order_relaxed);
        return SendStatus::Sent;
    }
    if (errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS) {
        dropped_.fetch_add(1, std::memory_order_relaxed);
        return SendStatus::Dropped;
    }
    failed_.fetch_add(1, std::memory_order_relaxed);
    return SendStatus::Failed;
}

int UdpSocket::receive(std::span<uint8_t> buffer, int timeoutMs) {
    if (timeoutMs > 0) {
        pollfd p{fd_.get(), POLLIN, 0};
        int rc = ::poll(&p, 1, timeoutMs);
        if (rc < 0) return -errno;
        if (rc == 0) return -EAGAIN;
    }
    ssize_t n = ::recv(fd_.get(), buffer.data(), buffer.size(), MSG_DONTWAIT | MSG_TRUNC);
    return n < 0 ? -errno : static_cast<int>(n);
}

uint16_t UdpSocket::localPort() const {
    sockaddr_storage addr{};
    socklen_t len = sizeof addr;
    if (getsockname(fd_.get(), reinterpret_cast<sockaddr*>(&addr), &len) != 0) return 0;
    if (addr.ss_family == AF_INET6) return ntohs(reinterpret_cast<sockaddr_in6*>(&addr)->sin6_port);
    return ntohs(reinterpret_cast<sockaddr_in*>(&addr)->sin_port);
}

}  // namespace previs
