#include "daemon/control_server.h"

#include <poll.h>
#include <pthread.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <optional>

#include "base/guarded_thread.h"
#include "base/log.h"

namespace previs {

namespace {

// A command line is short; anything longer is not a client of ours.
constexpr size_t kMaxCommandBytes = 4096;
// How long a connected client may take to send its line (a stuck client holds the only server
// thread for at most this long).
constexpr int kClientTimeoutMs = 1000;

Result<sockaddr_un> socketAddress(const std::string& path) {
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    if (path.empty() || path.size() >= sizeof(addr.sun_path))
        return makeError("control socket path '{}' is empty or longer than {} bytes", path,
                         sizeof(addr.sun_path) - 1);
    std::memcpy(addr.sun_path, path.c_str(), path.size() + 1);
    return addr;
}

// Sends all of `data`, waiting at most `timeoutMs` for the peer to take it.
bool sendAll(int fd, const std::string& data, int timeoutMs) {
    size_t sent = 0;
    while (sent < data.size()) {
        pollfd p{fd, POLLOUT, 0};
        if (::poll(&p, 1, timeoutMs) <= 0) return false;
        const ssize_t n = ::send(fd, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) return false;
        sent += size_t(n);
    }
    return true;
}

// Reads up to the first '\n' (or EOF), waiting at most `timeoutMs` in all.
std::optional<std::string> readLine(int fd, int timeoutMs) {
    std::string line;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(timeoutMs);
    char buf[512];
    while (line.size() < kMaxCommandBytes) {
        const int left = int(std::chrono::duration_cast<std::chrono::milliseconds>(
                                 deadline - std::chrono::steady_clock::now())
                                 .count());
        if (left <= 0) return std::nullopt;
        pollfd p{fd, POLLIN, 0};
        const int r = ::poll(&p, 1, left);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) return std::nullopt;
        const ssize_t n = ::recv(fd, buf, sizeof(buf), 0);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) return std::nullopt;
        if (n == 0) return line.empty() ? std::nullopt : std::optional(line);
        line.append(buf, size_t(n));
        if (auto nl = line.find('\n'); nl != std::string::npos) return line.substr(0, nl);
    }
    return std::nullopt;
}

}  // namespace

Result<std::unique_ptr<ControlServer>> ControlServer::create(const std::string& path,
                                                             Handler handler) {
    Result<sockaddr_un> addr = socketAddress(path);
    if (!addr) return addr.error();
    std::error_code ec;
    const std::filesystem::path folder = std::filesystem::path(path).parent_path();
    if (!folder.empty()) std::filesystem::create_directories(folder, ec);

    // A socket file left by a crashed previsd is replaced; one that answers is another previsd.
    if (std::filesystem::exists(path, ec)) {
        if (controlRequest(path, "ping", 500))
            return makeError(
                "control socket {}: another previsd is running there; stop it or "
                "set [control] socket to another path",
                path);
        ::unlink(path.c_str());
    }
    UniqueFD fd(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC | SOCK_NONBLOCK, 0));
    if (!fd.isValid()) return makeError("control socket: socket(): {}", std::strerror(errno));
    if (::bind(fd.get(), reinterpret_cast<const sockaddr*>(&*addr), sizeof(*addr)) != 0)
        return makeError(
            "control socket {}: cannot bind: {} (is the folder writable? set "
            "[control] socket or RUNTIME_DIRECTORY)",
            path, std::strerror(errno));
    // Owner and group only: the socket changes the box's mode.
    ::chmod(path.c_str(), 0660);
    if (::listen(fd.get(), 8) != 0)
        return makeError("control socket {}: listen: {}", path, std::strerror(errno));
    std::unique_ptr<ControlServer> server(
        new ControlServer(path, std::move(fd), std::move(handler)));
    if (!server->wake_.isValid())
        return makeError("control socket: eventfd: {}", std::strerror(errno));
    // Every thread waits on the same non-blocking listener; one wins each connection.
    for (int i = 0; i < kServingThreads; ++i)
        server->threads_.emplace_back(
            [s = server.get()] { runGuarded("control socket", [s] { s->run(); }); });
    return server;
}

ControlServer::ControlServer(std::string path, UniqueFD listener, Handler handler)
    : path_(std::move(path)),
      listener_(std::move(listener)),
      wake_(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK)),
      handler_(std::move(handler)) {}

ControlServer::~ControlServer() {
    const uint64_t one = 1;
    if (wake_.isValid()) [[maybe_unused]]
        ssize_t n = ::write(wake_.get(), &one, sizeof(one));
    for (std::thread& thread : threads_) thread.join();
    ::unlink(path_.c_str());
}

void ControlServer::run() {
    pthread_setname_np(pthread_self(), "pv-control");
    for (;;) {
        pollfd fds[2] = {{listener_.get(), POLLIN, 0}, {wake_.get(), POLLIN, 0}};
        const int r = ::poll(fds, 2, -1);
        if (r < 0 && errno == EINTR) continue;
        if (r < 0) {
            logError("control socket {}: poll: {}; the socket stops answering", path_,
                     std::strerror(errno));
            return;
        }
        if (fds[1].revents) return;  // never read: it stays readable for every thread
        if (!(fds[0].revents & POLLIN)) continue;
        UniqueFD client(::accept4(listener_.get(), nullptr, nullptr, SOCK_CLOEXEC));
        if (!client.isValid()) continue;
        serve(client.get());
    }
}

void ControlServer::serve(int client) {
    std::optional<std::string> line = readLine(client, kClientTimeoutMs);
    if (!line) return;
    if (!line->empty() && line->back() == '\r') line->pop_back();
    std::string reply;
    try {
        reply = *line == "ping" ? std::string("{\"ok\": true}") : handler_(*line);
    } catch (const std::exception& e) {  // a handler bug must not end the service
        logError("control socket {}: command failed: {}", path_, e.what());
        reply = "{\"ok\": false, \"error\": \"internal error\"}";
    }
    sendAll(client, reply + "\n", kClientTimeoutMs);
}

Result<std::string> controlRequest(const std::string& path, const std::string& command,
                                   int timeoutMs) {
    Result<sockaddr_un> addr = socketAddress(path);
    if (!addr) return addr.error();
    UniqueFD fd(::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0));
    if (!fd.isValid()) return makeError("socket(): {}", std::strerror(errno));
    if (::connect(fd.get(), reinterpret_cast<const sockaddr*>(&*addr), sizeof(*addr)) != 0)
        return makeError(
            "cannot reach previsd at {}: {} (is previsd running? pass --socket "
            "PATH if its config names another socket)",
            path, std::strerror(errno));
    if (!sendAll(fd.get(), command + "\n", timeoutMs))
        return makeError("previsd at {} did not take the command", path);
    std::optional<std::string> reply = readLine(fd.get(), timeoutMs);
    if (!reply) return makeError("previsd at {} did not answer within {} ms", path, timeoutMs);
    return *reply;
}

}  // namespace previs
