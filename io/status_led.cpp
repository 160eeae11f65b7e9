#include "io/status_led.h"

#include <gpiod.h>

#include <cerrno>
#include <cstring>

#include "base/log.h"

namespace previs {

Result<std::unique_ptr<StatusLed>> StatusLed::create(const std::string& chip,
                                                     const std::string& line, bool activeLow) {
    std::unique_ptr<StatusLed> led(new StatusLed(chip, line, activeLow));
    GpioFailure failure;
    auto requested = requestGpioLine(chip, line, GpioLineUse::Output, activeLow, false, &failure);
    led->lastAttempt_ = std::chrono::steady_clock::now();
    if (!requested) {
        if (failure == GpioFailure::Wrong) return requested.error();
        logWarning("status LED: {}; starting without it, looking for it every {} s",
                   requested.message(), kRetry.count());
        led->failing_ = true;
        return led;
    }
    logInfo("status LED: {}{}", requested->description, activeLow ? " (active low)" : "");
    led->line_ = std::move(*requested);
    return led;
}

StatusLed::~StatusLed() { set(false); }

bool StatusLed::connected() const {
    std::lock_guard lock(mutex_);
    return bool(line_.line);
}

bool StatusLed::reopen(bool on) {
    const auto now = std::chrono::steady_clock::now();
    if (now - lastAttempt_ < kRetry) return false;
    lastAttempt_ = now;
    auto requested = requestGpioLine(chip_, lineName_, GpioLineUse::Output, activeLow_, on);
    if (!requested) {
        logDebug("status LED: still away: {}", requested.message());
        return false;
    }
    line_ = std::move(*requested);
    failing_ = false;
    logInfo("status LED: {} is there", line_.description);
    return true;
}

void StatusLed::set(bool on) {
    std::lock_guard lock(mutex_);
    if (!line_.line) {
        reopen(on);  // requested at the level asked for
        return;
    }
    if (gpiod_line_set_value(line_.line.get(), on ? 1 : 0) < 0) {
        if (!failing_)
            logWarning("status LED: cannot set {}: {}; looking for it again every {} s",
                       line_.description, std::strerror(errno), kRetry.count());
        failing_ = true;
        line_ = {};
        lastAttempt_ = std::chrono::steady_clock::now();
    }
}

}  // namespace previs
