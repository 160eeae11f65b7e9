#include "systemd/notify.h"

#include <fmt/format.h>
#include <systemd/sd-daemon.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <string>

#include "base/log.h"

namespace previs::systemd {

namespace {

// sd_notify() returns > 0 when sent, 0 when no manager listens, < 0 (-errno) on failure. The
// watchdog is fed several times a minute: warn once, not on every call.
void send(const std::string& message) {
    int ret = sd_notify(0, message.c_str());
    if (ret >= 0) return;
    // Atomic: the render thread feeds the watchdog while others send status.
    static std::atomic<bool> warned{false};
    if (!warned.exchange(true)) {
        logWarning(
            "cannot notify systemd through NOTIFY_SOCKET ({}): {}; further failures are "
            "not logged",
            std::getenv("NOTIFY_SOCKET") ? std::getenv("NOTIFY_SOCKET") : "unset",
            std::strerror(-ret));
    }
}

}  // namespace

void notifyReady() { send("READY=1"); }

void notifyStatus(std::string_view status) {
    std::string message = "STATUS=";
    message.append(status);
    for (size_t i = 7; i < message.size(); ++i) {
        if (message[i] == '\n') message[i] = ' ';
    }
    send(message);
}

void notifyStopping() { send("STOPPING=1"); }

void notifyReloading() {
    // CLOCK_MONOTONIC in microseconds, as the manager compares it with its own clock.
    timespec now{};
    clock_gettime(CLOCK_MONOTONIC, &now);
    uint64_t usec =
        static_cast<uint64_t>(now.tv_sec) * 1000000u + static_cast<uint64_t>(now.tv_nsec) / 1000u;
    send(fmt::format("RELOADING=1\nMONOTONIC_USEC={}", usec));
}

void notifyWatchdog() { send("WATCHDOG=1"); }

std::optional<std::chrono::microseconds> watchdogInterval() {
    uint64_t usec = 0;
    // unset_environment=0: a restart of the render loop in the same process asks again.
    if (sd_watchdog_enabled(0, &usec) <= 0 || usec == 0) return std::nullopt;
    return std::chrono::microseconds(usec);
}

bool underSystemd() {
    const char* socket = std::getenv("NOTIFY_SOCKET");
    return socket && *socket;
}

}  // namespace previs::systemd
