#pragma once

// The status LED (DESIGN.md §1): an optional GPIO output line, on while refining.

#include <memory>
#include <string>

#include "io/gpio_button.h"

namespace previs {

class StatusLed {
public:
    // `chip` and `line` as for ButtonSettings. The LED starts off.
    static Result<std::unique_ptr<StatusLed>> create(const std::string& chip,
                                                     const std::string& line, bool activeLow);
    // Turns the LED off and releases the line.
    ~StatusLed();

    StatusLed(const StatusLed&) = delete;
    StatusLed& operator=(const StatusLed&) = delete;

    // A failure (the chip went away) is logged once, not returned: a dark LED must not stop
    // the service. Not thread-safe: call from one thread.
    void set(bool on);

    const std::string& description() const { return line_.description; }

private:
    explicit StatusLed(GpioLine line) : line_(std::move(line)) {}

    GpioLine line_;
    bool failing_ = false;
};

}  // namespace previs
