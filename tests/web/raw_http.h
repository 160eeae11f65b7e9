#pragma once

// Raw TCP for the web tests: requests exactly as written (malformed ones included), replies read
// as bytes, every wait bounded so a broken server fails a test instead of hanging it.

#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <optional>
#include <string>

#include "base/unique_fd.h"

namespace previs::test {

class RawConnection {
public:
    // Connects to 127.0.0.1:port; receiveBuffer > 0 shrinks the socket's receive buffer first
    // (a viewer that cannot take much before it stalls); `source` is the client's own address
    // (any of 127.0.0.0/8: clients on different addresses without configuring any).
    explicit RawConnection(int port, int receiveBuffer = 0, const char* source = nullptr) {
        fd_ = UniqueFD(::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0));
        if (receiveBuffer > 0)
            setsockopt(fd_.get(), SOL_SOCKET, SO_RCVBUF, &receiveBuffer, sizeof(receiveBuffer));
        if (source) {
            sockaddr_in s{};
            s.sin_family = AF_INET;
            ::inet_pton(AF_INET, source, &s.sin_addr);
            if (::bind(fd_.get(), reinterpret_cast<sockaddr*>(&s), sizeof(s)) != 0) return;
        }
        sockaddr_in a{};
        a.sin_family = AF_INET;
        a.sin_port = htons(uint16_t(port));
        a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        connected_ = ::connect(fd_.get(), reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
    }
    bool connected() const { return connected_; }

    bool send(const std::string& bytes) {
        size_t done = 0;
        while (done < bytes.size()) {
            const ssize_t n =
                ::send(fd_.get(), bytes.data() + done, bytes.size() - done, MSG_NOSIGNAL);
            if (n <= 0) return false;
            done += size_t(n);
        }
        return true;
    }

    // Reads what arrives within `timeout` (appending to buffer()); false once the peer closed.
    bool receiveFor(std::chrono::milliseconds timeout) {
        const auto end = std::chrono::steady_clock::now() + timeout;
        for (;;) {
            const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
                end - std::chrono::steady_clock::now());
            if (left.count() <= 0) return true;
            pollfd p{fd_.get(), POLLIN, 0};
            if (::poll(&p, 1, int(left.count())) <= 0) return true;
            char chunk[65536];
            const ssize_t n = ::recv(fd_.get(), chunk, sizeof(chunk), 0);
            if (n <= 0) return false;
            buffer_.append(chunk, size_t(n));
        }
    }

    // One read of at most `maxBytes` of what has arrived (none waited for); false once the
    // peer closed.
    bool receiveSome(size_t maxBytes) {
        std::string chunk(maxBytes, '\0');
        const ssize_t n = ::recv(fd_.get(), chunk.data(), maxBytes, MSG_DONTWAIT);
        if (n == 0) return false;
        if (n > 0) buffer_.append(chunk.data(), size_t(n));
        return true;
    }

    // Reads until `needle` is in the buffer, the peer closes or `timeout` passes.
    bool receiveUntil(const std::string& needle, std::chrono::milliseconds timeout) {
        const auto end = std::chrono::steady_clock::now() + timeout;
        while (buffer_.find(needle) == std::string::npos) {
            if (std::chrono::steady_clock::now() >= end) return false;
            if (!receiveFor(std::chrono::milliseconds(20)) &&
                buffer_.find(needle) == std::string::npos)
                return false;
        }
        return true;
    }

    // Reads until the peer closes (or `timeout`); true if it closed.
    bool receiveToClose(std::chrono::milliseconds timeout) {
        const auto end = std::chrono::steady_clock::now() + timeout;
        while (std::chrono::steady_clock::now() < end)
            if (!receiveFor(std::chrono::milliseconds(20))) return true;
        return false;
    }

    // Says the request is all sent (a half-close); the reply can still be read.
    void shutdownWrite() { ::shutdown(fd_.get(), SHUT_WR); }

    std::string& buffer() { return buffer_; }

private:
    UniqueFD fd_;
    bool connected_ = false;
    std::string buffer_;
};

struct HttpReply {
    int status = 0;  // 0: no status line arrived
    std::string head;
    std::string body;
};

inline HttpReply parseReply(const std::string& bytes) {
    HttpReply r;
    if (bytes.rfind("HTTP/1.1 ", 0) == 0 && bytes.size() >= 12)
        r.status = std::stoi(bytes.substr(9, 3));
    const size_t end = bytes.find("\r\n\r\n");
    r.head = bytes.substr(0, end);
    if (end != std::string::npos) r.body = bytes.substr(end + 4);
    return r;
}

// Whether `bytes` hold a whole reply: its header and as much body as its Content-Length says.
inline bool replyComplete(const std::string& bytes) {
    const size_t end = bytes.find("\r\n\r\n");
    if (end == std::string::npos) return false;
    const size_t key = bytes.find("Content-Length: ");
    if (key == std::string::npos || key > end) return false;
    return bytes.size() >= end + 4 + std::stoul(bytes.substr(key + 16));
}

// Sends `request` on a fresh connection and reads the reply until it is complete, the server
// closes the connection or `timeout` passes.
inline HttpReply roundTrip(int port, const std::string& request,
                           std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
    RawConnection c(port);
    if (!c.connected() || !c.send(request)) return {};
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (!replyComplete(c.buffer()) && std::chrono::steady_clock::now() < end)
        if (!c.receiveFor(std::chrono::milliseconds(20))) break;
    return parseReply(c.buffer());
}

inline HttpReply get(int port, const std::string& path, const std::string& extraHeaders = "") {
    return roundTrip(port, "GET " + path + " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n" +
                               extraHeaders + "\r\n");
}

inline HttpReply post(int port, const std::string& path, const std::string& body,
                      const std::string& extraHeaders = "") {
    return roundTrip(port, "POST " + path +
                               " HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n" +
                               extraHeaders + "Content-Length: " + std::to_string(body.size()) +
                               "\r\n\r\n" + body);
}

}  // namespace previs::test
