#pragma once

// previsd's side of the systemd service contract (sd_notify(3), daemon(7)): readiness, status
// text, stop/reload announcements and the watchdog keep-alive. Every call is a no-op when no
// service manager listens (NOTIFY_SOCKET unset), so previsd behaves the same from a shell.
//
// Failures to reach the manager are not the caller's problem: they are logged once and
// otherwise ignored (a daemon must not stop because its supervisor went away).

#include <chrono>
#include <optional>
#include <string_view>

namespace previs::systemd {

// READY=1: startup is complete (config loaded, devices open, control socket listening). With
// Type=notify, systemctl start returns and dependent units start only after this.
void notifyReady();

// STATUS=<text>: one line shown by `systemctl status`. Newlines are replaced by spaces because
// the protocol is newline-separated.
void notifyStatus(std::string_view status);

// STOPPING=1: a clean shutdown has begun (send it before the slow part of stopping).
void notifyStopping();

// RELOADING=1 with MONOTONIC_USEC (systemd >= 253 wants the timestamp); send notifyReady()
// again when the reload is done.
void notifyReloading();

// WATCHDOG=1: the keep-alive. The unit's WatchdogSec= restarts previsd when none arrives in
// time, so call it from the loop whose progress matters (the render loop), never from a
// timer thread that would keep a hung pipeline alive.
void notifyWatchdog();

// The watchdog timeout the manager enforces for this process (WATCHDOG_USEC, when
// WATCHDOG_PID is unset or our pid), or nullopt when there is no watchdog. Sending is the
// caller's job: sd_watchdog_enabled(3) recommends notifyWatchdog() at least every half of this
// interval.
std::optional<std::chrono::microseconds> watchdogInterval();

// True when a service manager expects notifications (NOTIFY_SOCKET is set), e.g. to log to
// the journal without timestamps.
bool underSystemd();

}  // namespace previs::systemd
