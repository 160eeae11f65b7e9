#include "io/status_led.h"

#include <gpiod.h>

#include <cerrno>
#include <cstring>

#include "base/log.h"

namespace previs {

Result<std::unique_ptr<StatusLed>> StatusLed::create(const std::string& chip,
                                                     const std::string& line, bool activeLow) {
    auto requested = requestGpioLine(chip, line, GpioLineUse::Output, activeLow, false);
    if (!requested) return requested.error();
    logInfo("status LED: {}{}", requested->description, activeLow ? " (active low)" : "");
    return std::unique_ptr<StatusLed>(new StatusLed(std::move(*requested)));
}

StatusLed::~StatusLed() { set(false); }

void StatusLed::set(bool on) {
    if (gpiod_line_set_value(line_.line.get(), on ? 1 : 0) < 0) {
        if (!failing_)
            logWarning("status LED: cannot set {}: {}; the LED may show the wrong mode",
                       line_.description, std::strerror(errno));
        failing_ = true;
        return;
    }
    failing_ = false;
}

}  // namespace previs
