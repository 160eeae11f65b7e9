#pragma once

// Shared by the web tests: a fake service behind the hooks, a monitor on a free port, an MJPEG
// viewer on a raw socket that counts the complete JPEG parts it received.

#include <atomic>
#include <chrono>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>
#include <vector>

#include "tests/web/raw_http.h"
#include "web/web_monitor.h"

namespace previs::test {

// The state the hooks expose: mode and recording, and every command that reached it.
struct FakeService {
    std::mutex mutex;
    std::string mode = "preview";
    bool recording = false;
    std::vector<std::string> commands;
    std::atomic<bool> refuse{false};  // answer {"ok": false}

    std::string status() {
        std::lock_guard lock(mutex);
        return nlohmann::json{{"mode", mode}, {"fps", 29.97}, {"recording", recording}}.dump();
    }
    std::string command(const std::string& c) {
        std::lock_guard lock(mutex);
        commands.push_back(c);
        if (refuse) return R"({"ok":false,"error":"refused"})";
        if (c == "toggle") mode = mode == "preview" ? "refine" : "preview";
        if (c.rfind("mode ", 0) == 0) mode = c.substr(5);
        if (c == "record start") recording = true;
        if (c == "record stop") recording = false;
        return nlohmann::json{{"ok", true}, {"mode", mode}}.dump();
    }
    std::string currentMode() {
        std::lock_guard lock(mutex);
        return mode;
    }
    size_t commandCount() {
        std::lock_guard lock(mutex);
        return commands.size();
    }
};

inline WebMonitorSettings testSettings() {
    WebMonitorSettings s;
    s.listen = "127.0.0.1:0";
    s.token = "s3cret-token";
    return s;
}

inline std::unique_ptr<WebMonitor> startMonitor(FakeService& service,
                                                WebMonitorSettings settings = testSettings()) {
    Result<std::unique_ptr<WebMonitor>> m = WebMonitor::create(
        settings, {.statusJson = [&service] { return service.status(); },
                   .command = [&service](const std::string& c) { return service.command(c); }});
    if (!m) return nullptr;
    return std::move(*m);
}

// Complete JPEG parts in an MJPEG byte stream (after the HTTP header).
inline int completeParts(const std::string& bytes) {
    size_t pos = bytes.find("\r\n\r\n");
    if (pos == std::string::npos) return 0;
    int parts = 0;
    const std::string key = "Content-Length: ";
    while ((pos = bytes.find(key, pos)) != std::string::npos) {
        const size_t bodyStart = bytes.find("\r\n\r\n", pos);
        if (bodyStart == std::string::npos) break;
        const size_t length = std::stoul(bytes.substr(pos + key.size(), bodyStart - pos));
        if (bodyStart + 4 + length > bytes.size()) break;
        ++parts;
        pos = bodyStart + 4 + length;
    }
    return parts;
}

// A viewer reading /stream.mjpeg on its own thread until destroyed.
class StreamViewer {
public:
    explicit StreamViewer(int port) : connection_(port) {
        connection_.send("GET /stream.mjpeg HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n");
        thread_ = std::thread([this] {
            while (!stop_) {
                const bool open = connection_.receiveFor(std::chrono::milliseconds(50));
                {
                    std::lock_guard lock(mutex_);
                    parts_ = completeParts(connection_.buffer());
                    if (connection_.buffer().size() >= 12 && status_ == 0)
                        status_ = parseReply(connection_.buffer()).status;
                }
                if (!open) break;
            }
        });
    }
    ~StreamViewer() {
        stop_ = true;
        thread_.join();
    }
    int frames() {
        std::lock_guard lock(mutex_);
        return parts_;
    }
    int status() {
        std::lock_guard lock(mutex_);
        return status_;
    }
    std::string head() {
        std::lock_guard lock(mutex_);
        return parseReply(connection_.buffer()).head;
    }
    // Waits until `n` frames arrived; false after `timeout`.
    bool waitFrames(int n, std::chrono::milliseconds timeout) {
        const auto end = std::chrono::steady_clock::now() + timeout;
        while (frames() < n) {
            if (std::chrono::steady_clock::now() >= end) return false;
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
        return true;
    }

private:
    RawConnection connection_;
    std::thread thread_;
    std::atomic<bool> stop_{false};
    std::mutex mutex_;
    int parts_ = 0;
    int status_ = 0;
};

// Polls `condition` every 10 ms for up to `timeout`.
template <typename Condition>
bool eventually(Condition condition, std::chrono::milliseconds timeout = std::chrono::seconds(10)) {
    const auto end = std::chrono::steady_clock::now() + timeout;
    while (!condition()) {
        if (std::chrono::steady_clock::now() >= end) return false;
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return true;
}

}  // namespace previs::test
