#include "web/web_monitor.h"

#include <arpa/inet.h>
#include <httplib.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <exception>
#include <mutex>
#include <string_view>
#include <thread>
#include <vector>

#include "base/guarded_thread.h"
#include "base/log.h"
#include "net/udp_socket.h"
#include "web/http_connections.h"
#include "web/monitor_page.h"
#include "web/stream_encoder.h"

namespace previs {

namespace {

using Clock = std::chrono::steady_clock;

constexpr const char* kBoundary = "previsframe";
// How long a viewer waits for a new frame before it sends the newest one again: a render that
// paused still shows, and a viewer that went away is noticed by the failing write.
constexpr std::chrono::milliseconds kViewerWait{250};
constexpr int kResendAfterWaits = 4;

constexpr int kListenBacklog = 128;
// Requests answered on one connection before it is closed (cpp-httplib's keep-alive count).
constexpr int kKeepAliveMaxCount = 100;

// cpp-httplib's task queue, run on its accept thread: each accepted socket goes straight to
// the connection hub (MonitorServer::admit, ConnectionHub::admit), which bounds and holds it; no
// job waits here.
class AcceptQueue : public httplib::TaskQueue {
public:
    void enqueue(std::function<void()> fn) override { fn(); }
    void shutdown() override {}
};

// A whole request the hub has read into memory, and the socket to answer on: cpp-httplib parses
// the bytes and writes its answer here. Nothing waits for the client to send: a read beyond the
// request fails at once (the hub already decided where the request ends).
class ConnectionStream final : public httplib::Stream {
public:
    ConnectionStream(Connection& connection, int writeTimeoutMs)
        : c_(connection), writeTimeoutMs_(writeTimeoutMs) {}

    bool is_readable() const override { return c_.pending() > 0; }
    bool is_writable() const override {
        pollfd p{c_.fd.get(), POLLOUT, 0};
        return ::poll(&p, 1, writeTimeoutMs_) > 0 && (p.revents & (POLLERR | POLLHUP)) == 0;
    }
    ssize_t read(char* ptr, size_t size) override {
        const size_t n = std::min(size, c_.pending());
        if (n == 0) return -1;
        std::memcpy(ptr, c_.buffer.data() + c_.readPos, n);
        c_.readPos += n;
        return ssize_t(n);
    }
    ssize_t write(const char* ptr, size_t size) override {
        for (;;) {
            const ssize_t n = ::send(c_.fd.get(), ptr, size, MSG_NOSIGNAL);
            if (n >= 0) return n;
            if (errno == EINTR) continue;
            // The socket is non-blocking (the hub's): wait for room, up to the write timeout.
            if ((errno != EAGAIN && errno != EWOULDBLOCK) || !is_writable()) return -1;
        }
    }
    void get_remote_ip_and_port(std::string& ip, int& port) const override {
        ip = c_.address;
        port = c_.port;
    }
    void get_local_ip_and_port(std::string& ip, int& port) const override {
        port = -1;
        ip.clear();
        socketAddress(c_.fd.get(), SocketEnd::Local, ip, port);
    }
    socket_t socket() const override { return c_.fd.get(); }

private:
    Connection& c_;
    const int writeTimeoutMs_;
};

enum class Path { Page, Stream, Status, Mode, Record, Control, Other };

Path pathOf(const std::string& path) {
    if (path == "/" || path == "/index.html") return Path::Page;
    if (path == "/stream.mjpeg") return Path::Stream;
    if (path == "/status.json") return Path::Status;
    if (path == "/mode") return Path::Mode;
    if (path == "/record") return Path::Record;
    if (path == "/control") return Path::Control;
    return Path::Other;
}

std::string trimmed(const std::string& s) {
    const size_t b = s.find_first_not_of(" \t\r\n");
    if (b == std::string::npos) return {};
    const size_t e = s.find_last_not_of(" \t\r\n");
    return s.substr(b, e - b + 1);
}

void answer(httplib::Response& res, int status, const std::string& message) {
    res.status = status;
    res.set_content(message + "\n", "text/plain; charset=utf-8");
}

// The library's own error answers carry no body: a word for the ones it gives.
std::string reasonPhrase(int status) {
    switch (status) {
        case 400:
            return "bad request";
        case 404:
            return "not found";
        case 413:
            return "payload too large";
        case 414:
            return "request line too long";
        case 416:
            return "range not satisfiable";
        default:
            return fmt::format("error {}", status);
    }
}

// cpp-httplib listens with SO_REUSEPORT, which would let a second previsd share the port
// silently; SO_REUSEADDR alone still lets a restart bind while old connections linger.
void listenSocketOptions(int sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof(yes));
}

// The kernel's send queue of a connection: Linux grows it up to 4 MiB, many seconds of stream
// for a slow viewer, who would see the picture that late instead of skipping to the newest
// frame. 128 KiB (the kernel doubles it) holds a few frames at the default size and still fills
// a Wi-Fi link's round trip.
constexpr int kSendBufferBytes = 128 * 1024;

void boundSendBuffer(int fd) {
    setsockopt(fd, SOL_SOCKET, SO_SNDBUF, &kSendBufferBytes, sizeof(kSendBufferBytes));
}

// One /stream.mjpeg response's progress, kept by its content provider.
struct ViewerState {
    uint64_t lastSequence = 0;  // of the last frame sent; 0 before the first
    int idleWaits = 0;          // waits since then that brought no new frame
    bool started = false;       // the opening boundary is sent
};

// Each rejected answer's status code, its WebStats counter and its name in the status JSON.
struct RejectedCount {
    int status;
    uint64_t WebStats::*count;
    const char* name;
};
constexpr RejectedCount kRejectedCounts[] = {
    {400, &WebStats::badRequest, "badRequest"},
    {401, &WebStats::unauthorized, "unauthorized"},
    {403, &WebStats::forbidden, "forbidden"},
    {404, &WebStats::notFound, "notFound"},
    {405, &WebStats::methodNotAllowed, "methodNotAllowed"},
    {408, &WebStats::requestTimeout, "requestTimeout"},
    {421, &WebStats::misdirected, "misdirected"},
    {411, &WebStats::lengthRequired, "lengthRequired"},
    {413, &WebStats::payloadTooLarge, "payloadTooLarge"},
    {414, &WebStats::uriTooLong, "uriTooLong"},
    {431, &WebStats::headersTooLarge, "headersTooLarge"},
    {503, &WebStats::busy, "busy"},
    {500, &WebStats::internalError, "internalError"},
};

}  // namespace

nlohmann::json toJson(const WebStats& s) {
    nlohmann::json rejected;
    for (const RejectedCount& r : kRejectedCounts) rejected[r.name] = s.*r.count;
    rejected["connectionsRefused"] = s.connectionsRefused;
    rejected["silentConnections"] = s.silentConnections;
    return {{"viewers", s.viewers},
            {"streamsServed", s.streamsServed},
            {"framesSubmitted", s.framesSubmitted},
            {"framesEncoded", s.framesEncoded},
            {"framesSent", s.framesSent},
            {"viewerFramesDropped", s.viewerFramesDropped},
            {"viewersStalled", s.viewersStalled},
            {"encodeMs", std::round(s.encodeMs * 100.0) / 100.0},
            {"jpegBytes", s.jpegBytes},
            {"requests", s.requests},
            {"commands", s.commands},
            {"connections", s.connections},
            {"rejected", rejected}};
}

Result<ListenAddress> parseListenAddress(const std::string& listen) {
    // The one HOST:PORT syntax of every network key (net/udp_socket.h).
    Result<std::pair<std::string, std::string>> split = splitHostPort(listen);
    if (!split)
        return makeError(
            "[web] listen = \"{}\": {}; expected \"HOST:PORT\" such as "
            "\"0.0.0.0:8080\" or \"[::]:8080\"",
            listen, split.message());
    if (split->first.empty())
        return makeError("[web] listen = \"{}\": no host (\"0.0.0.0:PORT\" for every address)",
                         listen);
    return ListenAddress{split->first, std::stoi(split->second)};
}

bool bearerTokenMatches(const std::string& authorization, const std::string& token) {
    if (token.empty()) return false;
    constexpr std::string_view scheme = "bearer ";
    if (authorization.size() < scheme.size()) return false;
    for (size_t i = 0; i < scheme.size(); ++i)
        if (std::tolower(static_cast<unsigned char>(authorization[i])) != scheme[i]) return false;
    const std::string presented = trimmed(authorization.substr(scheme.size()));
    // Time depends on the presented length only: every byte is compared, the first difference
    // does not end the loop, and the configured length is not probed (index modulo its size).
    unsigned diff = presented.size() != token.size() ? 1u : 0u;
    for (size_t i = 0; i < presented.size(); ++i)
        diff |= static_cast<unsigned char>(presented[i]) ^
                static_cast<unsigned char>(token[i % token.size()]);
    return diff == 0;
}

bool hostIsThisMonitor(const std::string& host, const std::vector<std::string>& names) {
    if (host.empty()) return true;
    std::string name;
    if (host.front() == '[') {
        const size_t close = host.find(']');
        if (close == std::string::npos) return false;
        in6_addr v6{};
        return ::inet_pton(AF_INET6, host.substr(1, close - 1).c_str(), &v6) == 1;
    }
    name = host.substr(0, host.find(':'));
    if (host.find(':') != host.rfind(':')) return false;  // a bare IPv6 is no Host value
    in_addr v4{};
    if (::inet_pton(AF_INET, name.c_str(), &v4) == 1) return true;
    auto canonical = [](std::string n) {
        std::transform(n.begin(), n.end(), n.begin(),
                       [](unsigned char ch) { return char(std::tolower(ch)); });
        if (!n.empty() && n.back() == '.') n.pop_back();
        return n;
    };
    name = canonical(name);
    if (name == "localhost" || name.ends_with(".localhost")) return true;
    return std::any_of(names.begin(), names.end(),
                       [&](const std::string& n) { return !n.empty() && canonical(n) == name; });
}

std::string validUtf8(const std::string& text) {
    std::string out;
    out.reserve(text.size());
    const auto byte = [&](size_t i) { return static_cast<unsigned char>(text[i]); };
    for (size_t i = 0; i < text.size();) {
        const unsigned char lead = byte(i);
        // The sequence's length and the range its second byte must fall in (Unicode 15, table
        // 3-7: no overlong forms, no surrogates, nothing above U+10FFFF).
        size_t length = 0;
        unsigned char low = 0x80, high = 0xBF;
        if (lead < 0x80)
            length = 1;
        else if (lead >= 0xC2 && lead <= 0xDF)
            length = 2;
        else if (lead >= 0xE0 && lead <= 0xEF) {
            length = 3;
            if (lead == 0xE0) low = 0xA0;
            if (lead == 0xED) high = 0x9F;
        } else if (lead >= 0xF0 && lead <= 0xF4) {
            length = 4;
            if (lead == 0xF0) low = 0x90;
            if (lead == 0xF4) high = 0x8F;
        }
        size_t good = length > 0 ? 1 : 0;
        while (good > 0 && good < length && i + good < text.size()) {
            const unsigned char next = byte(i + good);
            const bool inRange =
                good == 1 ? next >= low && next <= high : next >= 0x80 && next <= 0xBF;
            if (!inRange) break;
            ++good;
        }
        if (length > 0 && good == length) {
            out.append(text, i, length);
            i += length;
        } else {
            out += "\xEF\xBF\xBD";  // U+FFFD for the maximal ill-formed part
            i += std::max<size_t>(good, 1);
        }
    }
    return out;
}

// cpp-httplib binds its own socket; one handed over by systemd is adopted through the server's
// protected listening socket, which listen_after_bind() then serves (and stop() closes). Each
// accepted socket goes to `admit` instead of the library's own per-connection loop, and a
// worker runs the library on one whole request at a time (serveOne).
class MonitorServer : public httplib::Server {
public:
    void adopt(int fd) { svr_sock_ = fd; }
    // cpp-httplib listens with a backlog of 5: a burst of connections (a page and its status
    // polls from a few phones) would wait a second each for SYN retries. Waiting connections are
    // the kernel's, not descriptors of ours.
    void raiseBacklog() { ::listen(svr_sock_, kListenBacklog); }
    std::function<void(UniqueFD)> admit;
    bool serveOne(httplib::Stream& stream, bool lastOnConnection, bool& connectionClosed) {
        return process_request(stream, lastOnConnection, connectionClosed, nullptr);
    }

private:
    bool process_and_close_socket(socket_t sock) override {
        admit(UniqueFD(sock));
        return true;
    }
};

struct WebMonitor::Impl {
    WebMonitorSettings settings;
    WebMonitorHooks hooks;
    std::unique_ptr<StreamEncoder> encoder;
    MonitorServer server;
    std::unique_ptr<ConnectionHub> hub;
    std::thread listenThread;
    std::atomic<bool> listenDone{false};
    int port = 0;

    std::atomic<int> viewers{0};
    std::atomic<uint64_t> streamsServed{0}, framesSent{0}, viewerFramesDropped{0},
        viewersStalled{0}, requests{0}, commands{0};
    // Answers by status code (index = code − 400), counted in the logger.
    std::array<std::atomic<uint64_t>, 200> rejected{};

    void configure();
    void route();
    void count(int status);
    bool serve(Connection& connection);
    bool readBody(const httplib::Request& req, httplib::Response& res,
                  const httplib::ContentReader& reader, std::string& body) const;
    void servePage(const httplib::Request& req, httplib::Response& res) const;
    void serveStatus(const httplib::Request& req, httplib::Response& res) const;
    void serveStream(const httplib::Request& req, httplib::Response& res);
    bool sendFrame(ViewerState& viewer, httplib::DataSink& sink);
    bool mayControl(const httplib::Request& req, httplib::Response& res) const;
    void serveSignIn(const httplib::Request& req, httplib::Response& res) const;
    void serveControl(const httplib::Request& req, httplib::Response& res,
                      const httplib::ContentReader& reader, Path path);
    void serveOther(const httplib::Request& req, httplib::Response& res,
                    const httplib::ContentReader* reader) const;
    WebStats stats() const;
};

void WebMonitor::Impl::configure() {
    server.new_task_queue = [] { return new AcceptQueue; };
    server.admit = [this](UniqueFD fd) {
        boundSendBuffer(fd.get());
        hub->admit(std::move(fd));
    };
    server.set_socket_options(listenSocketOptions);
    server.set_read_timeout(std::chrono::milliseconds(settings.readTimeoutMs));
    server.set_write_timeout(std::chrono::milliseconds(settings.writeTimeoutMs));
    server.set_keep_alive_timeout(settings.keepAliveTimeoutS);
    server.set_keep_alive_max_count(kKeepAliveMaxCount);
    server.set_payload_max_length(settings.maxBodyBytes);
    server.set_logger(
        [this](const httplib::Request&, const httplib::Response& res) { count(res.status); });
    // DNS rebinding: a page from another name must not read the status or the stream.
    std::vector<std::string> names = settings.hostNames;
    Result<ListenAddress> listen = parseListenAddress(settings.listen);
    if (listen) names.push_back(listen->host);
    server.set_pre_routing_handler([names](const httplib::Request& req, httplib::Response& res) {
        const std::string host = req.get_header_value("Host");
        if (hostIsThisMonitor(host, names)) return httplib::Server::HandlerResponse::Unhandled;
        // The name is not echoed: the client chose it.
        answer(res, 421,
               "the Host this request names is not this monitor's: open the page by the box's "
               "IP address, or add the name to [web] host_names");
        return httplib::Server::HandlerResponse::Handled;
    });
    // The library's own answers (400, 404, 413, 414) get a body saying what happened.
    server.set_error_handler([](const httplib::Request&, httplib::Response& res) {
        if (res.body.empty()) answer(res, res.status, reasonPhrase(res.status));
    });
    server.set_exception_handler(
        [](const httplib::Request& req, httplib::Response& res, std::exception_ptr e) {
            std::string what = "unknown exception";
            try {
                std::rethrow_exception(e);
            } catch (const std::exception& ex) {
                what = ex.what();
            } catch (...) {
            }
            logError("web: {} {}: {}", req.method, req.path, what);
            answer(res, 500, "internal error: " + what);
        });
}

void WebMonitor::Impl::count(int status) {
    ++requests;
    if (status >= 400 && status < 600) ++rejected[size_t(status - 400)];
}

// A worker, for one whole request the hub read: cpp-httplib parses it, routes it and writes
// the answer. True keeps the connection for the next request.
bool WebMonitor::Impl::serve(Connection& connection) {
    ConnectionStream stream(connection, settings.writeTimeoutMs);
    const bool last = connection.requests >= kKeepAliveMaxCount;
    bool closed = false;
    const bool written = server.serveOne(stream, last, closed);
    return written && !closed && !last;
}

void WebMonitor::Impl::route() {
    server.Get("/", [this](const auto& req, auto& res) { servePage(req, res); });
    server.Get("/index.html", [this](const auto& req, auto& res) { servePage(req, res); });
    server.Get("/status.json", [this](const auto& req, auto& res) { serveStatus(req, res); });
    server.Get("/stream.mjpeg", [this](const auto& req, auto& res) { serveStream(req, res); });
    server.Get("/control", [this](const auto& req, auto& res) { serveSignIn(req, res); });
    server.Post("/mode", [this](const httplib::Request& req, httplib::Response& res,
                                const httplib::ContentReader& reader) {
        serveControl(req, res, reader, Path::Mode);
    });
    server.Post("/record", [this](const httplib::Request& req, httplib::Response& res,
                                  const httplib::ContentReader& reader) {
        serveControl(req, res, reader, Path::Record);
    });
    // Everything else: 405 for a known path, 404 otherwise (bodies drained, bounded).
    auto other = [this](const httplib::Request& req, httplib::Response& res,
                        const httplib::ContentReader& reader) { serveOther(req, res, &reader); };
    server.Get(".*", [this](const auto& req, auto& res) { serveOther(req, res, nullptr); });
    server.Options(".*", [this](const auto& req, auto& res) { serveOther(req, res, nullptr); });
    server.Post(".*", other);
    server.Put(".*", other);
    server.Patch(".*", other);
    server.Delete(".*", other);
}

bool WebMonitor::Impl::readBody(const httplib::Request& req, httplib::Response& res,
                                const httplib::ContentReader& reader, std::string& body) const {
    // Without a length the body would be read until the client closes (the hub refuses
    // chunked bodies before this).
    if (!req.has_header("Content-Length")) {
        answer(res, 411, "POST needs a Content-Length");
        return false;
    }
    bool tooLarge = false;
    const bool complete = reader([&](const char* data, size_t length) {
        if (body.size() + length > settings.maxBodyBytes) {
            tooLarge = true;
            return false;
        }
        body.append(data, length);
        return true;
    });
    if (complete) return true;
    // The hub answers a Content-Length above the limit (413) before a worker sees it.
    if (res.status == 413 || tooLarge)
        answer(res, 413, fmt::format("body above {} bytes", settings.maxBodyBytes));
    else
        answer(res, 400, "incomplete body");
    return false;
}

void WebMonitor::Impl::servePage(const httplib::Request&, httplib::Response& res) const {
    res.set_header("Cache-Control", "no-cache");
    res.set_header("X-Content-Type-Options", "nosniff");
    // Offline box: the page loads nothing but its own origin.
    res.set_header("Content-Security-Policy",
                   "default-src 'self'; style-src 'unsafe-inline'; script-src 'unsafe-inline'; "
                   "img-src 'self' blob:; frame-ancestors 'none'");
    res.set_content(kMonitorPage, "text/html; charset=utf-8");
}

void WebMonitor::Impl::serveStatus(const httplib::Request&, httplib::Response& res) const {
    const std::string text = hooks.statusJson ? hooks.statusJson() : std::string("{}");
    nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
    // A camera's or a file's name may hold any bytes: the answer is valid JSON whatever they are.
    if (j.is_discarded()) j = nlohmann::json::parse(validUtf8(text), nullptr, false);
    if (j.is_discarded()) {
        answer(res, 500, "the service's status is not JSON");
        return;
    }
    if (j.is_object() && (!j.contains("web") || j["web"].is_null())) j["web"] = toJson(stats());
    // Whether the page should offer its controls (a sign-in) or say that control is off.
    if (j.is_object() && j["web"].is_object()) j["web"]["control"] = !settings.token.empty();
    res.set_header("Cache-Control", "no-store");
    res.set_content(j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace),
                    "application/json");
}

void WebMonitor::Impl::serveStream(const httplib::Request&, httplib::Response& res) {
    int current = viewers.load();
    do {
        if (current >= settings.maxStreams) {
            res.set_header("Retry-After", "2");
            answer(res, 503,
                   fmt::format("{} viewers already watch (the limit); try again later", current));
            return;
        }
    } while (!viewers.compare_exchange_weak(current, current + 1));
    ++streamsServed;
    encoder->addViewer();
    res.set_header("Cache-Control", "no-cache, no-store");
    res.set_header("Pragma", "no-cache");
    auto viewer = std::make_shared<ViewerState>();
    auto provider = [this, viewer](size_t, httplib::DataSink& sink) {
        return sendFrame(*viewer, sink);
    };
    res.set_content_provider(fmt::format("multipart/x-mixed-replace; boundary={}", kBoundary),
                             provider, [this](bool) {
                                 encoder->removeViewer();
                                 --viewers;
                             });
}

// Sends the next frame to one viewer (waiting up to kViewerWait for it); false ends the stream.
bool WebMonitor::Impl::sendFrame(ViewerState& viewer, httplib::DataSink& sink) {
    std::shared_ptr<const EncodedFrame> frame =
        encoder->waitNewer(viewer.lastSequence, kViewerWait);
    if (!frame) {
        if (++viewer.idleWaits < kResendAfterWaits || viewer.lastSequence == 0) return true;
        frame = encoder->waitNewer(viewer.lastSequence - 1, std::chrono::milliseconds(0));
        if (!frame) return true;
    } else if (viewer.lastSequence && frame->sequence > viewer.lastSequence + 1) {
        viewerFramesDropped += frame->sequence - viewer.lastSequence - 1;
    }
    viewer.idleWaits = 0;
    viewer.lastSequence = frame->sequence;
    // Each part ends with the next boundary: a browser shows a part once the boundary after
    // it arrives, so sending it at once saves a frame of latency.
    const std::string head =
        fmt::format("{}Content-Type: image/jpeg\r\nContent-Length: {}\r\n\r\n",
                    viewer.started ? "" : fmt::format("--{}\r\n", kBoundary), frame->jpeg.size());
    const std::string tail = fmt::format("\r\n--{}\r\n", kBoundary);
    viewer.started = true;
    const Clock::time_point start = Clock::now();
    if (sink.write(head.data(), head.size()) &&
        sink.write(frame->jpeg.data(), frame->jpeg.size()) &&
        sink.write(tail.data(), tail.size())) {
        ++framesSent;
        return true;
    }
    // A write that failed after the write timeout: the viewer stopped taking bytes. What was
    // encoded meanwhile never reached it: its drops too.
    if (Clock::now() - start >= std::chrono::milliseconds(settings.writeTimeoutMs) * 9 / 10)
        ++viewersStalled;
    viewerFramesDropped += encoder->latestSequence() - viewer.lastSequence;
    return false;
}

// Whether the request presented the token; else answers 403 (control off) or 401.
bool WebMonitor::Impl::mayControl(const httplib::Request& req, httplib::Response& res) const {
    if (settings.token.empty()) {
        answer(res, 403, "control is off: no [web] token is configured");
        return false;
    }
    if (!bearerTokenMatches(req.get_header_value("Authorization"), settings.token)) {
        res.set_header("WWW-Authenticate", "Bearer");
        answer(res, 401, "control needs the header Authorization: Bearer TOKEN");
        return false;
    }
    return true;
}

// The page's sign-in: whether a token may control, checked without doing anything.
void WebMonitor::Impl::serveSignIn(const httplib::Request& req, httplib::Response& res) const {
    res.set_header("Cache-Control", "no-store");
    if (mayControl(req, res)) answer(res, 200, "signed in");
}

void WebMonitor::Impl::serveControl(const httplib::Request& req, httplib::Response& res,
                                    const httplib::ContentReader& reader, Path path) {
    std::string body;
    if (!readBody(req, res, reader, body) || !mayControl(req, res)) return;
    const std::string what = trimmed(body);
    std::string command;
    if (path == Path::Mode && (what == "preview" || what == "refine"))
        command = "mode " + what;
    else if (path == Path::Mode && what == "toggle")
        command = "toggle";
    else if (path == Path::Record && (what == "start" || what == "stop"))
        command = "record " + what;
    if (command.empty()) {
        answer(res, 400,
               path == Path::Mode ? "POST /mode takes preview, refine or toggle"
                                  : "POST /record takes start or stop");
        return;
    }
    ++commands;
    const std::string reply = hooks.command ? hooks.command(command) : std::string("{}");
    const nlohmann::json j = nlohmann::json::parse(reply, nullptr, false);
    // The service refused (a record start without space, say): a conflict with its state.
    res.status = j.is_object() && j.value("ok", false) ? 200 : 409;
    res.set_header("Cache-Control", "no-store");
    res.set_content(reply, "application/json");
}

void WebMonitor::Impl::serveOther(const httplib::Request& req, httplib::Response& res,
                                  const httplib::ContentReader* reader) const {
    // Drains a body (bounded) so that a kept-alive connection's next request parses.
    std::string body;
    if (reader && req.has_header("Content-Length") && !readBody(req, res, *reader, body)) return;
    switch (pathOf(req.path)) {
        case Path::Page:
        case Path::Stream:
        case Path::Status:
        case Path::Control:
            res.set_header("Allow", "GET, HEAD");
            answer(res, 405, fmt::format("{} takes GET", req.path));
            return;
        case Path::Mode:
        case Path::Record:
            res.set_header("Allow", "POST");
            answer(res, 405, fmt::format("{} takes POST", req.path));
            return;
        case Path::Other:
            answer(res, 404, "not found: the monitor serves /, /stream.mjpeg and /status.json");
            return;
    }
}

WebStats WebMonitor::Impl::stats() const {
    const EncoderStats e = encoder->stats();
    WebStats s;
    s.viewers = viewers.load();
    s.streamsServed = streamsServed;
    s.framesSubmitted = e.submitted;
    s.framesEncoded = e.encoded;
    s.framesSent = framesSent;
    s.viewerFramesDropped = viewerFramesDropped;
    s.viewersStalled = viewersStalled;
    s.encodeMs = e.meanEncodeMs;
    s.jpegBytes = e.lastJpegBytes;
    s.requests = requests;
    s.commands = commands;
    for (const RejectedCount& r : kRejectedCounts)
        s.*r.count = rejected[size_t(r.status - 400)].load();
    const ConnectionStats connections = hub->stats();
    s.connections = connections.open;
    s.connectionsRefused = connections.refused;
    s.silentConnections = connections.silent;
    return s;
}

namespace {

// The port a listening socket is bound to; -1 when it is not a bound IP socket.
int boundPort(int fd) {
    sockaddr_storage a{};
    socklen_t size = sizeof a;
    if (::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &size) != 0) return -1;
    if (a.ss_family == AF_INET) return ntohs(reinterpret_cast<sockaddr_in&>(a).sin_port);
    if (a.ss_family == AF_INET6) return ntohs(reinterpret_cast<sockaddr_in6&>(a).sin6_port);
    return -1;
}

}  // namespace

Result<std::unique_ptr<WebMonitor>> WebMonitor::create(const WebMonitorSettings& settings,
                                                       WebMonitorHooks hooks) {
    Result<ListenAddress> address = parseListenAddress(settings.listen);
    if (!address) return address.error();
    if (settings.maxStreams < 1 || settings.maxStreams > 64)
        return makeError("[web] max_streams must be 1..64, not {}", settings.maxStreams);
    if (settings.requestThreads < 1 || settings.requestThreads > 64)
        return makeError("[web] request_threads must be 1..64, not {}", settings.requestThreads);
    if (settings.readTimeoutMs < 1 || settings.writeTimeoutMs < 1 ||
        settings.keepAliveTimeoutS < 1 || settings.requestDeadlineMs < 1)
        return makeError("[web] timeouts must be positive");
    if (settings.maxConnectionsPerAddress < 1 ||
        settings.maxConnections < settings.maxConnectionsPerAddress)
        return makeError(
            "[web] connection bounds: {} per address, {} in all; need 1 <= per "
            "address <= in all",
            settings.maxConnectionsPerAddress, settings.maxConnections);
    Result<std::unique_ptr<StreamEncoder>> encoder =
        StreamEncoder::create({.fps = settings.streamFps,
                               .width = settings.streamWidth,
                               .jpegQuality = settings.jpegQuality});
    if (!encoder) return encoder.error();

    auto impl = std::make_unique<Impl>();
    impl->settings = settings;
    impl->hooks = std::move(hooks);
    impl->encoder = std::move(*encoder);
    Impl* raw = impl.get();
    Result<std::unique_ptr<ConnectionHub>> hub = ConnectionHub::create(
        {.maxConnections = settings.maxConnections,
         .maxPerAddress = settings.maxConnectionsPerAddress,
         .maxHeaderBytes = settings.maxHeaderBytes,
         .maxHeaderLines = settings.maxHeaderLines,
         .maxBodyBytes = settings.maxBodyBytes,
         .idleTimeout = std::chrono::seconds(settings.keepAliveTimeoutS),
         .readTimeout = std::chrono::milliseconds(settings.readTimeoutMs),
         .requestDeadline = std::chrono::milliseconds(settings.requestDeadlineMs),
         .workers = settings.maxStreams + settings.requestThreads},
        [raw](Connection& c) { return raw->serve(c); }, [raw](int status) { raw->count(status); });
    if (!hub) return hub.error();
    impl->hub = std::move(*hub);
    impl->configure();
    impl->route();
    errno = 0;
    if (settings.listenFd >= 0) {
        impl->server.adopt(settings.listenFd);
        impl->port = boundPort(settings.listenFd);
    } else if (address->port == 0) {
        impl->port = impl->server.bind_to_any_port(address->host);
    } else if (impl->server.bind_to_port(address->host, address->port)) {
        impl->port = address->port;
    } else {
        impl->port = -1;
    }
    if (impl->port >= 0 && settings.listenFd < 0) impl->server.raiseBacklog();
    if (impl->port < 0)
        return makeError(
            "[web] listen = \"{}\": cannot listen there ({}); is the address this "
            "box's and the port free?",
            settings.listen, errno ? std::strerror(errno) : "address not usable");
    impl->listenThread = std::thread([raw] {
        runGuarded("web listen", [raw] { raw->server.listen_after_bind(); });
        raw->listenDone = true;
    });
    logInfo("web monitor on http://{}:{}/ ({} fps, {} px wide, control {})", address->host,
            impl->port, settings.streamFps, settings.streamWidth,
            settings.token.empty() ? "off (no token)" : "with token");
    return std::unique_ptr<WebMonitor>(new WebMonitor(std::move(impl)));
}

WebMonitor::WebMonitor(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

WebMonitor::~WebMonitor() {
    // stop() is a no-op until the listen thread has started listening.
    while (!impl_->server.is_running() && !impl_->listenDone)
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
    impl_->server.stop();
    impl_->encoder->stop();
    if (impl_->listenThread.joinable()) impl_->listenThread.join();
    impl_->hub->stop();
}

void WebMonitor::submitFrame(WebFrame frame) { impl_->encoder->submit(std::move(frame)); }

WebStats WebMonitor::stats() const { return impl_->stats(); }

int WebMonitor::port() const { return impl_->port; }

}  // namespace previs
