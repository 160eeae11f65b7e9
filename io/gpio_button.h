#pragma once

// The mode button (DESIGN.md §1, §6): a GPIO input line watched by libgpiod (Debian's 1.6) on
// its own thread, debounced and classified into short and long presses by PressClassifier.
// libgpiod stays behind this header: its types are only named, never included.

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "base/result.h"
#include "base/unique_fd.h"
#include "io/press_classifier.h"

struct gpiod_chip;
struct gpiod_line;

namespace previs {

struct GpiodChipCloser {
    void operator()(gpiod_chip* chip) const;
};
struct GpiodLineReleaser {
    void operator()(gpiod_line* line) const;
};

// One requested GPIO line and the chip it belongs to (a libgpiod line lives inside its chip
// object, and closing the chip frees it). Members in this order so destruction releases the line
// before closing the chip; assignment does the same by hand (the default one would assign the
// chip first, closing it under the still-held line).
struct GpioLine {
    GpioLine() = default;
    GpioLine(GpioLine&&) noexcept = default;
    GpioLine& operator=(GpioLine&& other) noexcept {
        line.reset();
        chip = std::move(other.chip);
        line = std::move(other.line);
        description = std::move(other.description);
        return *this;
    }

    std::unique_ptr<gpiod_chip, GpiodChipCloser> chip;
    std::unique_ptr<gpiod_line, GpiodLineReleaser> line;
    std::string description;  // "line 'mode-button' (3) on chip vmtest (/dev/gpiochip0)"
};

enum class GpioLineUse { BothEdges, Output };

// Why a line could not be had. Absent: its chip is not there, not permitted yet or the line is
// busy, which time may mend (a USB or I²C expander that probes late, udev's rule not applied yet
// at boot, another program holding it): the button and the LED start without it and keep
// looking. Wrong: the chip is there and has no such line, which only the config can mend.
enum class GpioFailure { Absent, Wrong };

// The lookup the button and the LED share. `chip`: a path ("/dev/gpiochip0"), a chip name
// ("gpiochip0") or a label ("vmtest"); `line`: a line name ("mode-button") or an offset ("5").
// An output starts at logical `initialOn`. The error names what was asked for and lists what
// exists; `failure`, when given, says which kind it is.
Result<GpioLine> requestGpioLine(const std::string& chip, const std::string& line, GpioLineUse use,
                                 bool activeLow, bool initialOn = false,
                                 GpioFailure* failure = nullptr);

struct ButtonSettings {
    std::string chip;        // path "/dev/gpiochip0", name "gpiochip0" or label "vmtest"
    std::string line;        // name "mode-button" or offset "5"
    bool activeLow = false;  // pressed = line low (a button to ground with a pull-up)
    int debounceMs = 20;     // a level counts once it has been stable this long
    int longPressMs = 1500;  // held this long: LongPress (at the threshold), no ShortPress
};

class GpioButton {
public:
    // Requests the line and starts the button thread. `onEvent` runs on that thread: keep it
    // short and do not call stop() from it. A line that is absent (GpioFailure::Absent) is not
    // an error: the button starts disconnected, says why once in the log and in absentReason(),
    // and its thread looks for the line every second. Bad settings and a line that the present
    // chip does not have are errors.
    static Result<std::unique_ptr<GpioButton>> create(const ButtonSettings& settings,
                                                      std::function<void(ButtonEvent)> onEvent);
    ~GpioButton();

    GpioButton(const GpioButton&) = delete;
    GpioButton& operator=(const GpioButton&) = delete;

    // Ends the thread (promptly: it waits on the line and a stop eventfd) and releases the line.
    // Idempotent.
    void stop();

    // False while the chip is away (the thread is looking for it again).
    bool connected() const { return connected_.load(); }
    // Why it is not connected, as first found at start ("" once it was connected).
    std::string absentReason() const;

    // "line 'mode-button' (0) on chip vmtest (/dev/gpiochip0)"
    const std::string& description() const { return description_; }

private:
    GpioButton(const ButtonSettings& settings, std::function<void(ButtonEvent)> onEvent,
               GpioLine line, std::string description, UniqueFD stopFd);

    void run();
    // Reads pending edges into the classifier. False when the line is gone.
    bool readEvents();
    // Feeds the line's current level when it differs from the classifier's (edges the kernel
    // dropped in a bounce train). False when the line is gone.
    bool resync(int64_t nowNs);
    void emit(const std::vector<ButtonEvent>& events);
    // After the chip went away: retries every second until it is back or stop() is called.
    bool reopen();

    ButtonSettings settings_;
    std::function<void(ButtonEvent)> onEvent_;
    GpioLine line_;                  // empty while the chip is away
    const std::string description_;  // as first found (read by other threads)
    UniqueFD stopFd_;                // eventfd: stop() writes, the thread's poll() wakes
    PressClassifier classifier_;
    std::optional<int64_t> resyncAtNs_;  // when to read the level back after a burst of edges
    std::atomic<bool> connected_{true};
    mutable std::mutex absentMutex_;
    std::string absentReason_;  // under absentMutex_
    std::thread thread_;
};

}  // namespace previs
