#pragma once

// The monitor's connections (issue 52): admitted within bounds per client address and in all,
// kept by one poll thread while they are idle or still sending their request, and lent to a
// worker only once the whole request (line, headers and its short body) is in memory. So an
// idle or slow client costs a descriptor and a bounded buffer, never a worker; a request is
// bounded before anything parses it; and one that is not whole within a deadline from its first
// byte is answered 408. The HTTP itself is cpp-httplib's, run by the worker on the bytes read
// here (web/web_monitor.cpp).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "base/result.h"
#include "base/unique_fd.h"

namespace previs {

struct ConnectionLimits {
    int maxConnections = 64;            // open at once, every client together
    int maxPerAddress = 16;             // open at once from one client address
    size_t maxRequestLineBytes = 8192;  // above: 414 (cpp-httplib's own limit)
    size_t maxHeaderBytes = 8192;       // the header lines together, line ends included; 431
    size_t maxHeaderLines = 100;        // 431 above
    size_t maxBodyBytes = 1024;         // a larger declared body: 413; chunked bodies: 411
    std::chrono::milliseconds idleTimeout{5000};       // no byte since connect or the last answer
    std::chrono::milliseconds readTimeout{5000};       // silence in the middle of a request: 408
    std::chrono::milliseconds requestDeadline{10000};  // first byte to the whole request: 408
    int workers = 12;
};

class ConnectionHub;

// A socket's peer or local address as text (an IPv4 address of an IPv6 socket as plain IPv4) and
// its port. False (nothing written) where the socket has none or is not IP.
enum class SocketEnd { Peer, Local };
bool socketAddress(int fd, SocketEnd end, std::string& address, int& port);

// One client connection. The hub fills `buffer`; a worker consumes the request at readPos.
struct Connection {
    using Clock = std::chrono::steady_clock;

    ~Connection();

    ConnectionHub* owner = nullptr;  // holds this address's slot until the connection closes
    UniqueFD fd;
    std::string address;  // the client's IP address, the key of its per-address bound
    int port = 0;
    std::string buffer;  // received bytes; those before readPos are consumed
    size_t readPos = 0;
    Clock::time_point requestStart;  // first byte of the request being received
    Clock::time_point lastActivity;  // last byte received, or the connect, or the last answer
    int requests = 0;                // requests lent to a worker so far

    // The scan of the request that starts at readPos (positions relative to readPos).
    size_t scanned = 0;
    size_t requestLineEnd = std::string::npos;  // its '\n'
    size_t headerLines = 0;
    size_t requestEnd = 0;   // head and body; 0 while the head is incomplete
    bool lingering = false;  // answered and closing: what still arrives is read and dropped
    Clock::time_point lingerUntil;

    size_t pending() const { return buffer.size() - readPos; }
};

// What the hub counts; read with stats().
struct ConnectionStats {
    int open = 0;          // connections open now
    uint64_t refused = 0;  // closed at accept: a bound was reached (answered 503)
    uint64_t silent = 0;   // closed with no whole request: idle, or the client hung up
};

class ConnectionHub {
public:
    // Runs on a worker with a whole request at conn.buffer[readPos...]; returns whether the
    // connection stays open for the next one (keep-alive).
    using Serve = std::function<bool(Connection&)>;
    // Told of each answer the hub gives itself (408, 411, 413, 414, 431), for the counters.
    using Answered = std::function<void(int status)>;

    static Result<std::unique_ptr<ConnectionHub>> create(const ConnectionLimits& limits,
                                                         Serve serve, Answered answered);
    ~ConnectionHub();
    ConnectionHub(const ConnectionHub&) = delete;
    ConnectionHub& operator=(const ConnectionHub&) = delete;

    // A connection just accepted (the listen thread): kept, or answered 503 and closed at once
    // when its address or the monitor is at its bound. Never blocks.
    void admit(UniqueFD fd);
    // Closes every connection and ends the threads; a request being served is cut off.
    void stop();
    ConnectionStats stats() const;

private:
    friend struct Connection;  // gives back its address's slot when it closes
    enum class Scan { Partial, Whole, Closed };

    ConnectionHub(const ConnectionLimits& limits, Serve serve, Answered answered);
    bool reserveSlot(const std::string& address);
    void releaseSlot(const std::string& address);
    void poll();
    void work();
    void receive(std::unique_ptr<Connection>& c);
    Scan scan(Connection& c);
    size_t scanHead(Connection& c);
    bool takeHead(Connection& c, size_t headEnd);
    void answerAndLinger(Connection& c, int status, const std::string& message);
    void expire(Connection::Clock::time_point now);
    void watch(std::unique_ptr<Connection> c);
    void lend(std::unique_ptr<Connection> c);
    void giveBack(std::unique_ptr<Connection> c, size_t requestEnd);
    void wakePoller();

    const ConnectionLimits limits_;
    const Serve serve_;
    const Answered answered_;
    UniqueFD epoll_;
    UniqueFD wake_;  // eventfd: connections handed to the poll thread, or stop

    mutable std::mutex slotsMutex_;
    std::unordered_map<std::string, int> perAddress_;
    int open_ = 0;
    std::atomic<uint64_t> refused_{0}, silent_{0};

    std::mutex handMutex_;  // connections for the poll thread to watch
    std::vector<std::unique_ptr<Connection>> handed_;

    std::mutex readyMutex_;  // whole requests waiting for a worker, and the ones lent out
    std::condition_variable readyWake_;
    std::deque<std::unique_ptr<Connection>> ready_;
    std::vector<int> lent_;
    bool stopping_ = false;

    // Owned by the poll thread: the connections it watches, by descriptor.
    std::unordered_map<int, std::unique_ptr<Connection>> watched_;
    std::thread poller_;
    std::vector<std::thread> workers_;
};

}  // namespace previs
