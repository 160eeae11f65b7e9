#pragma once

// The control socket (DESIGN.md §3 `previs ctl`): a Unix stream socket; a client sends one
// command line ("status", "mode refine", "toggle"), gets one JSON line back and the connection
// closes. One thread serves clients one at a time (a command takes microseconds); a client that
// sends nothing is dropped after a timeout, so it cannot block the others for long.

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "base/result.h"
#include "base/unique_fd.h"

namespace previs {

class ControlServer {
public:
    // Answers one command line with one line (JSON, no newline).
    using Handler = std::function<std::string(const std::string& command)>;

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
    std::thread thread_;
};

// The client side (`previs ctl`): sends `command`, returns the reply line.
Result<std::string> controlRequest(const std::string& path, const std::string& command,
                                   int timeoutMs = 5000);

}  // namespace previs
