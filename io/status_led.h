#pragma once

// The status LED (DESIGN.md §1): an optional GPIO output line, on while refining.

#include <chrono>
#include <memory>
#include <mutex>
#include <string>

#include "io/gpio_button.h"

namespace previs {

class StatusLed {
public:
    // `chip` and `line` as for ButtonSettings. The LED starts off. As for the button, a line
    // that is absent (GpioFailure::Absent) is not an error: the LED starts dark and set() looks
    // for it again; a line the present chip does not have is.
    static Result<std::unique_ptr<StatusLed>> create(const std::string& chip,
                                                     const std::string& line, bool activeLow);
    // Turns the LED off and releases the line.
    ~StatusLed();

    StatusLed(const StatusLed&) = delete;
    StatusLed& operator=(const StatusLed&) = delete;

    // Thread-safe. A failure (the chip went away) is logged once, not returned: a dark LED must
    // not stop the service. The line is then released and requested again, at most once every
    // kRetry, by the calls that follow, so the LED comes back with its chip, as the button does.
    void set(bool on);
    // False while the line is away.
    bool connected() const;

    static constexpr std::chrono::seconds kRetry{1};

private:
    StatusLed(std::string chip, std::string line, bool activeLow)
        : chip_(std::move(chip)), lineName_(std::move(line)), activeLow_(activeLow) {}
    // Requests the line, driven to `on`; false (logged once per loss) when it is still away.
    bool reopen(bool on);

    const std::string chip_, lineName_;
    const bool activeLow_;
    mutable std::mutex mutex_;
    GpioLine line_;  // empty while away
    bool failing_ = false;
    std::chrono::steady_clock::time_point lastAttempt_{};
};

}  // namespace previs
