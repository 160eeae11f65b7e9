#pragma once

// The browser monitor (issue 39, DESIGN.md `[web] listen`, docs/web-monitor.md): an HTTP server
// on the set's network with one page (`/`), the live composite as MJPEG (`/stream.mjpeg`), the
// service status (`/status.json`, with `web.control`: whether a token is configured) and, for a
// client presenting the configured bearer token, the mode and record controls (`POST /mode`,
// `POST /record`); `GET /control` checks a token without acting (the page's sign-in). Built on
// Debian's cpp-httplib.
//
// How previsd uses it:
//   auto web = WebMonitor::create(settings, {
//       .statusJson = [&] { return statusJson(service.status()); },   // the ctl status object
//       .command = [&](const std::string& c) { return service.handleCommand(c); }});
//   ... on the display thread, after each frame shown: web->submitFrame(webFrameOf(frame));
//   ... in the status object: j["web"] = toJson(web->stats());
// submitFrame never blocks (a pointer swap); everything else runs on the monitor's own threads:
// one encoder thread, one thread that holds the connections while they are idle or still sending
// (web/http_connections.h) and a fixed pool of HTTP workers for whole requests. Destroying the
// monitor stops them all.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "base/result.h"
#include "web/web_frame.h"

namespace previs {

struct WebMonitorSettings {
    std::string listen;  // "HOST:PORT" ("[::1]:8080" for IPv6); port 0 = any free port
    // A listening TCP socket to serve on instead of binding `listen` (systemd's socket
    // activation: the service itself has no network); the monitor owns it from create() on.
    int listenFd = -1;
    std::string token;              // the bearer token; "" = controls refused (403), viewing open
    double streamFps = 10.0;        // MJPEG frames per second at most
    int streamWidth = 640;          // MJPEG width; the height keeps the aspect; never upscaled
    int jpegQuality = 80;           // 1..100
    int maxStreams = 4;             // concurrent /stream.mjpeg viewers; one more gets 503
    int requestThreads = 8;         // workers for everything else (page, status, control, errors)
    int readTimeoutMs = 5000;       // a client silent this long in the middle of a request: 408
    int requestDeadlineMs = 10000;  // a request not whole this long after its first byte: 408
    int writeTimeoutMs = 5000;      // a viewer that takes no bytes this long is dropped
    int keepAliveTimeoutS = 5;      // a connection idle this long (no request begun) is closed
    size_t maxBodyBytes = 1024;     // POST bodies above this: 413
    size_t maxHeaderBytes = 8192;   // all header lines together above this: 431
    size_t maxHeaderLines = 100;    // more header lines than this: 431
    // Connections open at once, from one client address and in all; one more is answered 503
    // and closed at once (so a crowd of clients cannot take the process's descriptors).
    int maxConnectionsPerAddress = 16;
    int maxConnections = 64;
    // The names this monitor is reached by (Host check against DNS rebinding): requests whose
    // Host is none of these, the listen address's host, "localhost" or an IP literal get 421.
    std::vector<std::string> hostNames;
};

// What the monitor asks the service. Both are called on an HTTP worker thread, concurrently with
// the service's own threads and with each other: they must be thread-safe and quick (no I/O
// waits); an exception they throw is caught and answered 500.
struct WebMonitorHooks {
    // The object `previs ctl status --json` prints (previsd: statusJson(status())). Served at
    // /status.json with a "web" member (toJson(stats())) added when it has none.
    std::function<std::string()> statusJson;
    // A control-socket command — "toggle", "mode preview", "mode refine", "record start",
    // "record stop" — and its JSON reply, {"ok": true, ...} or {"ok": false, "error": "..."}
    // (previsd: Service::handleCommand). Called only for a request that presented the token.
    std::function<std::string(const std::string& command)> command;
};

// What the monitor counts (in the service status as "web"). Rejected requests by kind: each is
// answered with its status code and the connection's worker freed; none reaches the hooks.
struct WebStats {
    int viewers = 0;                   // /stream.mjpeg responses being sent now
    uint64_t streamsServed = 0;        // viewers accepted so far
    uint64_t framesSubmitted = 0;      // submitFrame calls
    uint64_t framesEncoded = 0;        // JPEG encodes (one per stream frame, whatever the viewers)
    uint64_t framesSent = 0;           // frames written to viewers, all viewers together
    uint64_t viewerFramesDropped = 0;  // encoded frames a viewer skipped (it was still sending)
    uint64_t viewersStalled = 0;       // viewers dropped after writeTimeoutMs without progress
    double encodeMs = 0.0;             // mean downscale + JPEG encode time per frame
    size_t jpegBytes = 0;              // size of the newest encoded frame
    uint64_t requests = 0;             // HTTP requests answered (all codes)
    uint64_t commands = 0;             // control commands passed to the hook
    int connections = 0;               // connections open now
    uint64_t badRequest = 0;           // 400: unparsable request line or header, bad body
    uint64_t unauthorized = 0;         // 401: POST without the right bearer token
    uint64_t forbidden = 0;            // 403: control with no token configured
    uint64_t notFound = 0;             // 404
    uint64_t methodNotAllowed = 0;     // 405
    uint64_t requestTimeout = 0;       // 408: a request not whole within its deadline
    uint64_t misdirected = 0;          // 421: a Host that is not this monitor's (rebinding)
    uint64_t lengthRequired = 0;       // 411: POST without Content-Length, or chunked
    uint64_t payloadTooLarge = 0;      // 413: body above maxBodyBytes
    uint64_t uriTooLong = 0;           // 414: request line above 8 KiB
    uint64_t headersTooLarge = 0;      // 431: headers above maxHeaderBytes or maxHeaderLines
    uint64_t busy = 0;                 // 503: a stream beyond maxStreams
    uint64_t internalError = 0;        // 500: a hook threw
    uint64_t connectionsRefused = 0;   // 503 at connect: maxConnections(PerAddress) reached
    uint64_t silentConnections = 0;    // closed before a whole request (idle, a client that
                                       // hung up or a browser's spare connection)
};

nlohmann::json toJson(const WebStats& stats);

struct ListenAddress {
    std::string host;
    int port = 0;
};
// "HOST:PORT", "[V6]:PORT"; errors name the option and the expected form.
Result<ListenAddress> parseListenAddress(const std::string& listen);

// Whether an Authorization header value is "Bearer TOKEN" with the configured token. The
// comparison takes the same time wherever the first difference is (no timing oracle on the
// set's network); an empty configured token never matches.
bool bearerTokenMatches(const std::string& authorization, const std::string& token);

// Whether a Host header value names this monitor: empty (a client that sends none is no
// browser), an IP literal, "localhost" (or a name under it), or one of `names` (any case, a
// trailing dot ignored); the port is not looked at. A page served from any other name reached
// this box through DNS rebinding and must not read it.
bool hostIsThisMonitor(const std::string& host, const std::vector<std::string>& names);

// `text` with every byte that is not part of well-formed UTF-8 replaced by U+FFFD.
std::string validUtf8(const std::string& text);

class WebMonitor {
public:
    // Binds the listen address (errors: a bad address, a port in use) and starts serving.
    static Result<std::unique_ptr<WebMonitor>> create(const WebMonitorSettings& settings,
                                                      WebMonitorHooks hooks);
    ~WebMonitor();
    WebMonitor(const WebMonitor&) = delete;
    WebMonitor& operator=(const WebMonitor&) = delete;

    // The display thread, for every frame shown; returns after a pointer swap, never waits for
    // an encode or a viewer.
    void submitFrame(WebFrame frame);

    WebStats stats() const;
    // The bound port (the chosen one when `listen` asked for port 0).
    int port() const;

private:
    struct Impl;
    explicit WebMonitor(std::unique_ptr<Impl> impl);
    std::unique_ptr<Impl> impl_;
};

}  // namespace previs
