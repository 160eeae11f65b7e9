#pragma once

// The control socket (DESIGN.md §3 `previs ctl`): a Unix stream socket; a client sends one
// command line ("status", "mode refine", "toggle"), gets one JSON line back and the connection
// closes. A few threads serve clients, each one at a time: most commands take microseconds, but
// `record stop` waits while the take drains to disk, and the socket must keep answering (status)
// meanwhile. A client that sends nothing is dropped after a timeout, so it cannot hold a thread
// for long.

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "base/result.h"
#include "base/unique_fd.h"

namespace previs {

class ControlServer {
public:
    // Answers one command line with one line (JSON, no newline).
    // Called from several threads at once.
    using Handler = std::function<std::string(const std::string& command)>;
    // Clients served at the same time; more wait in the listen backlog.
    static constexpr int kServingThreads = 4;

    // Binds `path` (a stale socket file from a crashed run is replaced; a live one — another
    // previsd answering there — is an error) and starts serving.
    static Result<std::unique_ptr<ControlServer>> create(const std::string& path, Handler handler);
    ~ControlServer();
    ControlServer(const ControlServer&) = delete;
    ControlServer& operator=(const ControlServer&) = delete;

    const std::string& path() const { return path_; }

private:
    ControlServer(std::string path, UniqueFD listener, Handler handler);
    void run();
    void serve(int client);

    std::string path_;
    UniqueFD listener_;
    UniqueFD wake_;  // eventfd: wakes the thread to stop
    Handler handler_;
    std::vector<std::thread> threads_;
};

// The client side (`previs ctl`): sends `command`, returns the reply line.
Result<std::string> controlRequest(const std::string& path, const std::string& command,
                                   int timeoutMs = 5000);

}  // namespace previs
