#include "web/http_connections.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <linux/sockios.h>
#include <netinet/in.h>
#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/ioctl.h>
#include <sys/socket.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <exception>
#include <string_view>

#include "base/guarded_thread.h"
#include "base/log.h"

namespace previs {

namespace {

using Clock = Connection::Clock;

// How long an answered connection may go on sending before it is closed: long enough for a
// client that sent its whole request to read the answer, short enough to free the slot.
constexpr std::chrono::milliseconds kLinger{2000};
// How often the poll thread looks at the timeouts when nothing arrives.
constexpr int kTickMs = 100;
constexpr size_t kReceiveChunk = 16384;
// A connection's next request waits until the answers before it have mostly left the kernel's
// send queue: then the next answer (the page, 8 KiB, is the largest that is not a stream) fits
// without its worker waiting, however slowly the client reads.
constexpr int kUnsentBeforeNextRequest = 64 * 1024;

bool whole(const Connection& c) {
    return !c.lingering && c.requestEnd > 0 && c.pending() >= c.requestEnd;
}

// Whether the answers already sent on `c` still wait in the kernel for a client that reads
// slowly (or not at all).
bool answersPending(const Connection& c) {
    int unsent = 0;
    return ::ioctl(c.fd.get(), SIOCOUTQ, &unsent) == 0 && unsent > kUnsentBeforeNextRequest;
}

const char* reasonOf(int status) {
    switch (status) {
        case 400:
            return "Bad Request";
        case 408:
            return "Request Timeout";
        case 411:
            return "Length Required";
        case 413:
            return "Payload Too Large";
        case 414:
            return "URI Too Long";
        case 431:
            return "Request Header Fields Too Large";
        case 503:
            return "Service Unavailable";
        default:
            return "Error";
    }
}

// A short answer written without waiting: what does not fit the socket's buffer is lost, and
// the connection closes anyway.
void sendAnswer(int fd, int status, const std::string& message) {
    const std::string body = message + "\n";
    const std::string reply = fmt::format(
        "HTTP/1.1 {} {}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\n"
        "Connection: close\r\n{}\r\n{}",
        status, reasonOf(status), body.size(), status == 503 ? "Retry-After: 2\r\n" : "", body);
    (void)::send(fd, reply.data(), reply.size(), MSG_DONTWAIT | MSG_NOSIGNAL);
}

}  // namespace

bool socketAddress(int fd, SocketEnd end, std::string& address, int& port) {
    sockaddr_storage a{};
    socklen_t size = sizeof a;
    sockaddr* at = reinterpret_cast<sockaddr*>(&a);
    if ((end == SocketEnd::Peer ? ::getpeername(fd, at, &size) : ::getsockname(fd, at, &size)) != 0)
        return false;
    char text[INET6_ADDRSTRLEN] = {};
    if (a.ss_family == AF_INET) {
        const auto& v4 = reinterpret_cast<const sockaddr_in&>(a);
        ::inet_ntop(AF_INET, &v4.sin_addr, text, sizeof text);
        port = ntohs(v4.sin_port);
    } else if (a.ss_family == AF_INET6) {
        const auto& v6 = reinterpret_cast<const sockaddr_in6&>(a);
        if (IN6_IS_ADDR_V4MAPPED(&v6.sin6_addr))
            ::inet_ntop(AF_INET, &v6.sin6_addr.s6_addr[12], text, sizeof text);
        else
            ::inet_ntop(AF_INET6, &v6.sin6_addr, text, sizeof text);
        port = ntohs(v6.sin6_port);
    } else {
        return false;
    }
    address = text;
    return true;
}

namespace {

bool namedLike(std::string_view line, std::string_view lowerName) {
    if (line.size() <= lowerName.size() || line[lowerName.size()] != ':') return false;
    for (size_t i = 0; i < lowerName.size(); ++i)
        if (std::tolower(static_cast<unsigned char>(line[i])) != lowerName[i]) return false;
    return true;
}

std::string_view valueOf(std::string_view line) {
    line.remove_prefix(line.find(':') + 1);
    while (!line.empty() && (line.front() == ' ' || line.front() == '\t')) line.remove_prefix(1);
    while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back())))
        line.remove_suffix(1);
    return line;
}

// What the head says about the body, and the head without its Range lines.
struct HeadFacts {
    std::string head;  // request line, kept header lines, blank line
    bool chunked = false;
    bool badLength = false;
    size_t contentLength = 0;
};

// The monitor serves no partial content: Range and If-Range are dropped, so a request with
// thousands of ranges is answered once, in full, like any other.
HeadFacts readHead(std::string_view head, size_t requestLineEnd) {
    HeadFacts facts;
    facts.head.reserve(head.size());
    facts.head.append(head.substr(0, requestLineEnd + 1));
    bool lengthSeen = false;
    size_t pos = requestLineEnd + 1;
    while (pos < head.size()) {
        const size_t end = head.find('\n', pos);
        const std::string_view line = head.substr(pos, end + 1 - pos);
        pos = end + 1;
        if (namedLike(line, "range") || namedLike(line, "if-range")) continue;
        facts.head.append(line);
        if (namedLike(line, "transfer-encoding")) facts.chunked = true;
        if (namedLike(line, "content-length")) {
            const std::string_view v = valueOf(line);
            size_t value = 0;
            bool digits = !v.empty() && v.size() <= 18;
            for (char ch : v) {
                digits = digits && std::isdigit(static_cast<unsigned char>(ch));
                value = value * 10 + size_t(ch - '0');
            }
            if (!digits || (lengthSeen && value != facts.contentLength)) facts.badLength = true;
            facts.contentLength = value;
            lengthSeen = true;
        }
    }
    return facts;
}

}  // namespace

Connection::~Connection() {
    if (owner) owner->releaseSlot(address);
}

Result<std::unique_ptr<ConnectionHub>> ConnectionHub::create(const ConnectionLimits& limits,
                                                             Serve serve, Answered answered) {
    if (limits.maxConnections < 1 || limits.maxPerAddress < 1 || limits.workers < 1)
        return makeError("web connections: the bounds and the workers must be at least 1");
    std::unique_ptr<ConnectionHub> hub(
        new ConnectionHub(limits, std::move(serve), std::move(answered)));
    hub->epoll_ = UniqueFD(::epoll_create1(EPOLL_CLOEXEC));
    hub->wake_ = UniqueFD(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
    if (!hub->epoll_.isValid() || !hub->wake_.isValid())
        return makeError("web connections: cannot make the poll set: {}", std::strerror(errno));
    epoll_event e{};
    e.events = EPOLLIN;
    e.data.fd = hub->wake_.get();
    if (::epoll_ctl(hub->epoll_.get(), EPOLL_CTL_ADD, hub->wake_.get(), &e) != 0)
        return makeError("web connections: cannot watch the wake-up: {}", std::strerror(errno));
    ConnectionHub* raw = hub.get();
    hub->poller_ = std::thread([raw] { runGuarded("web poll", [raw] { raw->poll(); }); });
    for (int i = 0; i < limits.workers; ++i)
        hub->workers_.emplace_back([raw] { runGuarded("web worker", [raw] { raw->work(); }); });
    return hub;
}

ConnectionHub::ConnectionHub(const ConnectionLimits& limits, Serve serve, Answered answered)
    : limits_(limits), serve_(std::move(serve)), answered_(std::move(answered)) {}

ConnectionHub::~ConnectionHub() { stop(); }

bool ConnectionHub::reserveSlot(const std::string& address) {
    std::lock_guard lock(slotsMutex_);
    int& mine = perAddress_[address];
    if (open_ >= limits_.maxConnections || mine >= limits_.maxPerAddress) {
        if (mine == 0) perAddress_.erase(address);
        return false;
    }
    ++mine;
    ++open_;
    return true;
}

void ConnectionHub::releaseSlot(const std::string& address) {
    std::lock_guard lock(slotsMutex_);
    auto it = perAddress_.find(address);
    if (it != perAddress_.end() && --it->second <= 0) perAddress_.erase(it);
    --open_;
}

void ConnectionHub::admit(UniqueFD fd) {
    std::string address;
    int port = 0;
    if (!socketAddress(fd.get(), SocketEnd::Peer, address, port)) return;  // gone already
    if (!reserveSlot(address)) {
        ++refused_;
        sendAnswer(fd.get(), 503,
                   fmt::format("too many connections: at most {} from one address and {} in all; "
                               "close other pages of this monitor or try again later",
                               limits_.maxPerAddress, limits_.maxConnections));
        return;  // closed here: a refused client holds no descriptor of ours
    }
    auto c = std::make_unique<Connection>();
    c->owner = this;
    c->address = std::move(address);
    c->port = port;
    c->fd = std::move(fd);
    const int flags = ::fcntl(c->fd.get(), F_GETFL);
    ::fcntl(c->fd.get(), F_SETFL, flags | O_NONBLOCK);
    c->lastActivity = Clock::now();
    watch(std::move(c));
}

void ConnectionHub::watch(std::unique_ptr<Connection> c) {
    {
        std::lock_guard lock(handMutex_);
        handed_.push_back(std::move(c));
    }
    wakePoller();
}

void ConnectionHub::wakePoller() {
    const uint64_t one = 1;
    (void)!::write(wake_.get(), &one, sizeof one);
}

void ConnectionHub::poll() {
    std::array<epoll_event, 64> events;
    for (;;) {
        {
            std::lock_guard lock(readyMutex_);
            if (stopping_) break;
        }
        const int n = ::epoll_wait(epoll_.get(), events.data(), int(events.size()), kTickMs);
        std::vector<std::unique_ptr<Connection>> handed;
        {
            std::lock_guard lock(handMutex_);
            handed.swap(handed_);
        }
        for (std::unique_ptr<Connection>& c : handed) {
            // A connection back from a worker may hold the next request already.
            if (c->pending() > 0) scan(*c);
            if (whole(*c) && !answersPending(*c)) {
                lend(std::move(c));
                continue;
            }
            // A whole request waiting for its answers to drain is not polled for more bytes
            // (expire() looks at it each tick); any other connection is.
            const int fd = c->fd.get();
            epoll_event e{};
            e.events = EPOLLIN | EPOLLRDHUP;
            e.data.fd = fd;
            if (whole(*c) || ::epoll_ctl(epoll_.get(), EPOLL_CTL_ADD, fd, &e) == 0)
                watched_[fd] = std::move(c);
        }
        for (int i = 0; i < n; ++i) {
            const int fd = events[size_t(i)].data.fd;
            if (fd == wake_.get()) {
                uint64_t count;
                (void)!::read(fd, &count, sizeof count);
                continue;
            }
            auto it = watched_.find(fd);
            if (it != watched_.end()) receive(it->second);
        }
        expire(Clock::now());
    }
    watched_.clear();
}

// Reads what arrived. A connection that is whole is lent to a worker, one that ended or broke
// a bound is dropped (its entry cleared), others stay.
void ConnectionHub::receive(std::unique_ptr<Connection>& slot) {
    Connection& c = *slot;
    const int fd = c.fd.get();
    std::array<char, kReceiveChunk> chunk;
    // Room for the largest request within the bounds, plus a byte to see one beyond them.
    const size_t capacity =
        limits_.maxRequestLineBytes + limits_.maxHeaderBytes + limits_.maxBodyBytes + 8;
    bool ended = false;  // the client sent all it will (or the socket broke)
    for (;;) {
        const size_t room =
            c.lingering ? chunk.size() : capacity + 1 - std::min(capacity + 1, c.pending());
        if (room == 0) break;
        const ssize_t got = ::recv(fd, chunk.data(), std::min(room, chunk.size()), 0);
        if (got < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) break;
        if (got < 0 && errno == EINTR) continue;
        if (got <= 0) {
            ended = true;
            break;
        }
        if (c.lingering) continue;
        const Clock::time_point now = Clock::now();
        if (c.pending() == 0) c.requestStart = now;
        c.lastActivity = now;
        c.buffer.append(chunk.data(), size_t(got));
    }
    const Scan s = c.lingering ? Scan::Closed : scan(c);
    if (s == Scan::Whole) {
        // Served even when the client has half-closed after it (the answer can still go out);
        // not polled while it waits for a worker or for its earlier answers to drain.
        ::epoll_ctl(epoll_.get(), EPOLL_CTL_DEL, fd, nullptr);
        if (answersPending(c)) return;
        std::unique_ptr<Connection> request = std::move(slot);
        watched_.erase(fd);
        lend(std::move(request));
    } else if (ended) {
        // Hung up before a whole request (a browser's spare connection, a scanner).
        if (!c.lingering && c.requests == 0) ++silent_;
        watched_.erase(fd);
    } else if (s == Scan::Partial && c.pending() > capacity) {
        answerAndLinger(c, 431, "request above the monitor's bounds");
    }
}

// Follows the request at readPos as bytes arrive: whole, still partial, or answered because it
// broke a bound.
ConnectionHub::Scan ConnectionHub::scan(Connection& c) {
    if (c.requestEnd == 0) {
        const size_t headEnd = scanHead(c);
        if (c.lingering) return Scan::Closed;
        if (headEnd == 0) return Scan::Partial;
        if (!takeHead(c, headEnd)) return Scan::Closed;
    }
    return c.pending() >= c.requestEnd ? Scan::Whole : Scan::Partial;
}

// Looks at each new byte of the head once; returns where the head ends (after its blank line),
// 0 while it is incomplete or once it is answered for breaking a bound.
size_t ConnectionHub::scanHead(Connection& c) {
    const std::string_view data(c.buffer.data() + c.readPos, c.pending());
    size_t headEnd = 0;
    for (; c.scanned < data.size() && headEnd == 0; ++c.scanned) {
        if (data[c.scanned] != '\n') continue;
        if (c.requestLineEnd == std::string::npos) {
            c.requestLineEnd = c.scanned;
        } else if (c.scanned >= 3 && data.substr(c.scanned - 3, 4) == "\r\n\r\n") {
            headEnd = c.scanned + 1;
        } else if (++c.headerLines > limits_.maxHeaderLines) {
            answerAndLinger(c, 431,
                            fmt::format("more than {} header lines", limits_.maxHeaderLines));
            return 0;
        }
    }
    if (c.requestLineEnd == std::string::npos) {
        if (data.size() > limits_.maxRequestLineBytes + 2)
            answerAndLinger(
                c, 414, fmt::format("request line above {} bytes", limits_.maxRequestLineBytes));
        return 0;
    }
    // The header lines with their line ends, the blank line that ends them excluded.
    const size_t headerBytes = (headEnd ? headEnd - 2 : data.size()) - (c.requestLineEnd + 1);
    if (headerBytes > limits_.maxHeaderBytes) {
        answerAndLinger(c, 431,
                        fmt::format("request headers above {} bytes", limits_.maxHeaderBytes));
        return 0;
    }
    return headEnd;
}

// A whole head: its body must have a length within the bound; Range lines are dropped. False
// when it was answered instead.
bool ConnectionHub::takeHead(Connection& c, size_t headEnd) {
    const HeadFacts facts =
        readHead(std::string_view(c.buffer).substr(c.readPos, headEnd), c.requestLineEnd);
    if (facts.chunked) {
        answerAndLinger(c, 411, "send the body with a Content-Length, not chunked");
        return false;
    }
    if (facts.badLength) {
        answerAndLinger(c, 400, "Content-Length is not one number");
        return false;
    }
    if (facts.contentLength > limits_.maxBodyBytes) {
        answerAndLinger(c, 413, fmt::format("body above {} bytes", limits_.maxBodyBytes));
        return false;
    }
    c.buffer.replace(c.readPos, headEnd, facts.head);
    c.requestEnd = facts.head.size() + facts.contentLength;
    return true;
}

void ConnectionHub::answerAndLinger(Connection& c, int status, const std::string& message) {
    sendAnswer(c.fd.get(), status, message);
    if (answered_) answered_(status);
    ::shutdown(c.fd.get(), SHUT_WR);
    std::string().swap(c.buffer);
    c.readPos = 0;
    c.lingering = true;
    c.lingerUntil = Clock::now() + kLinger;
}

void ConnectionHub::expire(Clock::time_point now) {
    std::vector<std::unique_ptr<Connection>> drained;
    for (auto it = watched_.begin(); it != watched_.end();) {
        Connection& c = *it->second;
        bool drop = false;
        if (c.lingering) {
            drop = now >= c.lingerUntil;
        } else if (whole(c)) {
            // Its earlier answers were waiting in the kernel: lent once they left, dropped if
            // the client takes none of them for the read timeout.
            if (!answersPending(c)) {
                drained.push_back(std::move(it->second));
                drop = true;
            } else {
                drop = now - c.lastActivity >= limits_.readTimeout;
            }
        } else if (c.pending() == 0) {
            drop = now - c.lastActivity >= limits_.idleTimeout;
            if (drop && c.requests == 0) ++silent_;
        } else if (now - c.lastActivity >= limits_.readTimeout ||
                   now - c.requestStart >= limits_.requestDeadline) {
            answerAndLinger(
                c, 408,
                fmt::format("the request was not complete within {} ms of its first "
                            "byte or {} ms of silence",
                            limits_.requestDeadline.count(), limits_.readTimeout.count()));
        }
        it = drop ? watched_.erase(it) : std::next(it);
    }
    for (std::unique_ptr<Connection>& c : drained) lend(std::move(c));
}

void ConnectionHub::lend(std::unique_ptr<Connection> c) {
    ++c->requests;
    std::lock_guard lock(readyMutex_);
    if (stopping_) return;
    ready_.push_back(std::move(c));
    readyWake_.notify_one();
}

void ConnectionHub::work() {
    for (;;) {
        std::unique_ptr<Connection> c;
        {
            std::unique_lock lock(readyMutex_);
            readyWake_.wait(lock, [&] { return stopping_ || !ready_.empty(); });
            if (stopping_) return;
            c = std::move(ready_.front());
            ready_.pop_front();
            lent_.push_back(c->fd.get());
        }
        const size_t requestEnd = c->readPos + c->requestEnd;
        bool keep = false;
        try {
            keep = serve_(*c);
        } catch (const std::exception& e) {
            logError("web: a connection from {} ended on an error: {}", c->address, e.what());
        }
        {
            std::lock_guard lock(readyMutex_);
            lent_.erase(std::find(lent_.begin(), lent_.end(), c->fd.get()));
            if (stopping_) keep = false;
        }
        if (keep) giveBack(std::move(c), requestEnd);
    }
}

// A connection whose answer is sent goes back to the poll thread to wait for its next request,
// holding no worker meanwhile.
void ConnectionHub::giveBack(std::unique_ptr<Connection> c, size_t requestEnd) {
    // Whatever of the request the worker left unread (a body no handler asked for) is skipped.
    c->readPos = std::min(std::max(c->readPos, requestEnd), c->buffer.size());
    c->buffer.erase(0, c->readPos);
    c->readPos = 0;
    c->scanned = 0;
    c->requestLineEnd = std::string::npos;
    c->headerLines = 0;
    c->requestEnd = 0;
    c->lastActivity = Clock::now();
    c->requestStart = c->lastActivity;
    watch(std::move(c));
}

void ConnectionHub::stop() {
    {
        std::lock_guard lock(readyMutex_);
        if (stopping_ && !poller_.joinable()) return;
        stopping_ = true;
        ready_.clear();
        // Cuts off the requests being served: their workers' next write fails at once.
        for (int fd : lent_) ::shutdown(fd, SHUT_RDWR);
    }
    readyWake_.notify_all();
    wakePoller();
    if (poller_.joinable()) poller_.join();
    for (std::thread& t : workers_)
        if (t.joinable()) t.join();
    std::lock_guard lock(handMutex_);
    handed_.clear();
}

ConnectionStats ConnectionHub::stats() const {
    ConnectionStats s;
    {
        std::lock_guard lock(slotsMutex_);
        s.open = open_;
    }
    s.refused = refused_;
    s.silent = silent_;
    return s;
}

}  // namespace previs
