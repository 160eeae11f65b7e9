#include "io/gpio_button.h"

#include <gpiod.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <vector>

#include "base/guarded_thread.h"
#include "base/log.h"

namespace previs {

void GpiodChipCloser::operator()(gpiod_chip* chip) const { gpiod_chip_close(chip); }
void GpiodLineReleaser::operator()(gpiod_line* line) const { gpiod_line_release(line); }

namespace {

using ChipPtr = std::unique_ptr<gpiod_chip, GpiodChipCloser>;

// Lines are requested under this consumer name (gpioinfo shows it).
constexpr const char* kConsumer = "previs";
// How often a lost chip is looked for again, and how long a quiet line waits before its level is
// read back (catching edges the kernel dropped).
constexpr int kRetryMs = 1000;
// libgpiod reads at most this many edges per call (the kernel's v1 event queue holds 16).
constexpr unsigned kEventBatch = 16;

int64_t monotonicNs() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return int64_t(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string chipDescription(gpiod_chip* chip) {
    return fmt::format("{} (/dev/{})", gpiod_chip_label(chip), gpiod_chip_name(chip));
}

std::vector<std::string> chipPaths() {
    std::vector<std::string> paths;
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator("/dev", ec))
        if (entry.path().filename().string().starts_with("gpiochip"))
            paths.push_back(entry.path().string());
    std::sort(paths.begin(), paths.end());
    return paths;
}

// What a user could have meant, for an error message: "gpiochip0 'vmtest' (4 lines), ...".
std::string listChips() {
    std::string list;
    for (const std::string& path : chipPaths()) {
        if (!list.empty()) list += ", ";
        ChipPtr chip(gpiod_chip_open(path.c_str()));
        if (!chip) {
            list += fmt::format("{} (cannot open: {})", path, std::strerror(errno));
            continue;
        }
        list += fmt::format("{} '{}' ({} lines)", gpiod_chip_name(chip.get()),
                            gpiod_chip_label(chip.get()), gpiod_chip_num_lines(chip.get()));
    }
    return list.empty() ? "none (no /dev/gpiochip*: is the GPIO driver loaded?)" : list;
}

std::string listLines(gpiod_chip* chip) {
    std::string names;
    unsigned unnamed = 0;
    const unsigned count = gpiod_chip_num_lines(chip);
    for (unsigned offset = 0; offset < count; ++offset) {
        gpiod_line* line = gpiod_chip_get_line(chip, offset);
        const char* name = line ? gpiod_line_name(line) : nullptr;
        if (!name || !*name) {
            ++unnamed;
            continue;
        }
        if (!names.empty()) names += ", ";
        names += name;
    }
    if (unnamed > 0)
        names += fmt::format("{}{} unnamed (give an offset, 0-{})", names.empty() ? "" : "; ",
                             unnamed, count - 1);
    return names;
}

std::string openHint(int err) {
    return err == EACCES ? " (run as root, or add the user to the group that owns it)" : "";
}

Result<ChipPtr> openChip(const std::string& name) {
    if (name.empty()) return makeError("gpio: no chip given; chips: {}", listChips());
    if (name.find('/') != std::string::npos) {
        ChipPtr chip(gpiod_chip_open(name.c_str()));
        if (!chip) {
            const int err = errno;
            return makeError("gpio: cannot open chip {}: {}{}; chips: {}", name, std::strerror(err),
                             openHint(err), listChips());
        }
        return chip;
    }
    std::string failures;
    for (const std::string& path : chipPaths()) {
        ChipPtr chip(gpiod_chip_open(path.c_str()));
        if (!chip) {
            const int err = errno;
            failures +=
                fmt::format("; cannot open {}: {}{}", path, std::strerror(err), openHint(err));
            continue;
        }
        if (name == gpiod_chip_name(chip.get()) || name == gpiod_chip_label(chip.get()))
            return chip;
    }
    return makeError("gpio: no chip named or labelled '{}'{}; chips: {}", name, failures,
                     listChips());
}

Result<gpiod_line*> findLine(gpiod_chip* chip, const std::string& line) {
    const bool isOffset =
        !line.empty() && line.size() <= 9 &&
        std::all_of(line.begin(), line.end(), [](char c) { return c >= '0' && c <= '9'; });
    const unsigned count = gpiod_chip_num_lines(chip);
    if (isOffset) {
        const unsigned offset = unsigned(std::stoul(line));
        if (offset >= count)
            return makeError("gpio: no line {} on chip {}: it has lines 0-{} ({})", offset,
                             chipDescription(chip), count - 1, listLines(chip));
        gpiod_line* l = gpiod_chip_get_line(chip, offset);
        if (!l)
            return makeError("gpio: cannot get line {} of chip {}: {}", offset,
                             chipDescription(chip), std::strerror(errno));
        return l;
    }
    gpiod_line* l = line.empty() ? nullptr : gpiod_chip_find_line(chip, line.c_str());
    if (!l)
        return makeError("gpio: no line '{}' on chip {}; lines: {}", line, chipDescription(chip),
                         listLines(chip));
    return l;
}

std::string lineDescription(gpiod_chip* chip, gpiod_line* line) {
    const char* name = gpiod_line_name(line);
    return fmt::format("line '{}' ({}) on chip {}", name ? name : "", gpiod_line_offset(line),
                       chipDescription(chip));
}

}  // namespace

Result<GpioLine> requestGpioLine(const std::string& chipName, const std::string& lineName,
                                 GpioLineUse use, bool activeLow, bool initialOn,
                                 GpioFailure* failure) {
    GpioFailure ignored;
    GpioFailure& kind = failure ? *failure : ignored;
    kind = GpioFailure::Absent;
    auto chip = openChip(chipName);
    if (!chip) return chip.error();
    auto line = findLine(chip->get(), lineName);
    if (!line) {
        kind = GpioFailure::Wrong;
        return line.error();
    }
    const std::string description = lineDescription(chip->get(), *line);

    gpiod_line_request_config config{};
    config.consumer = kConsumer;
    config.request_type = use == GpioLineUse::BothEdges ? GPIOD_LINE_REQUEST_EVENT_BOTH_EDGES
                                                        : GPIOD_LINE_REQUEST_DIRECTION_OUTPUT;
    // Active-low in the kernel, so edges, values and gpioinfo all speak the logical level.
    // Bias stays as it is: the board's pull resistor decides (and gpio-sim's pull is its input).
    config.flags = activeLow ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
    if (gpiod_line_request(*line, &config, initialOn ? 1 : 0) < 0) {
        const int err = errno;
        if (err == EBUSY) {
            gpiod_line_update(*line);
            const char* user = gpiod_line_consumer(*line);
            return makeError(
                "gpio: {} is busy (used by '{}'); stop the program holding it "
                "(gpioinfo lists users)",
                description, user ? user : "?");
        }
        return makeError("gpio: cannot request {} as {}: {}{}", description,
                         use == GpioLineUse::BothEdges ? "input with edge events" : "output",
                         std::strerror(err), openHint(err));
    }
    GpioLine result;
    result.chip = std::move(*chip);
    result.line.reset(*line);
    result.description = description;
    return result;
}

Result<std::unique_ptr<GpioButton>> GpioButton::create(const ButtonSettings& settings,
                                                       std::function<void(ButtonEvent)> onEvent) {
    if (settings.debounceMs < 0 || settings.debounceMs > 1000)
        return makeError(
            "button: debounce_ms {} is out of range: give 0-1000 (20 suits most "
            "switches)",
            settings.debounceMs);
    if (settings.longPressMs <= settings.debounceMs)
        return makeError("button: long_press_ms {} must be longer than debounce_ms {}",
                         settings.longPressMs, settings.debounceMs);
    GpioFailure failure;
    auto line = requestGpioLine(settings.chip, settings.line, GpioLineUse::BothEdges,
                                settings.activeLow, false, &failure);
    if (!line && failure == GpioFailure::Wrong) return line.error();
    UniqueFD stopFd(eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK));
    if (!stopFd.isValid())
        return makeError("button: cannot create an eventfd: {}", std::strerror(errno));
    std::string description =
        line ? line->description
             : fmt::format("line '{}' on chip '{}'", settings.line, settings.chip);
    std::unique_ptr<GpioButton> button(new GpioButton(settings, std::move(onEvent),
                                                      line ? std::move(*line) : GpioLine{},
                                                      std::move(description), std::move(stopFd)));
    if (line) {
        const int level = gpiod_line_get_value(button->line_.line.get());
        if (level < 0)
            return makeError("gpio: cannot read {}: {}", button->description_,
                             std::strerror(errno));
        button->classifier_.reset(monotonicNs(), level == 1);
    } else {
        // The thread's first step is then to look for it (run() → reopen()).
        button->connected_ = false;
        button->absentReason_ = line.message();
        logWarning("button: {}; starting without it, looking for it every {} s", line.message(),
                   kRetryMs / 1000);
    }
    // A failure here leaves the box without its button (the control socket still works): said
    // once, in the log, by runGuarded.
    button->thread_ = std::thread([b = button.get()] { runGuarded("button", [b] { b->run(); }); });
    if (!line) return button;
    logInfo("button: watching {}{}", button->description_,
            settings.activeLow ? " (active low)" : "");
    return button;
}

GpioButton::GpioButton(const ButtonSettings& settings, std::function<void(ButtonEvent)> onEvent,
                       GpioLine line, std::string description, UniqueFD stopFd)
    : settings_(settings),
      onEvent_(std::move(onEvent)),
      line_(std::move(line)),
      description_(std::move(description)),
      stopFd_(std::move(stopFd)),
      classifier_(settings.debounceMs, settings.longPressMs) {}

GpioButton::~GpioButton() { stop(); }

std::string GpioButton::absentReason() const {
    std::lock_guard lock(absentMutex_);
    return absentReason_;
}

void GpioButton::stop() {
    if (!thread_.joinable()) return;
    const uint64_t one = 1;
    // An eventfd write of 1 cannot fail short of a counter overflow.
    [[maybe_unused]] ssize_t n = ::write(stopFd_.get(), &one, sizeof(one));
    thread_.join();
    line_ = {};
}

void GpioButton::run() {
    for (;;) {
        if (!line_.line && !reopen()) return;
        const int lineFd = gpiod_line_event_get_fd(line_.line.get());
        pollfd fds[2] = {{lineFd, POLLIN, 0}, {stopFd_.get(), POLLIN, 0}};
        // Wake at the classifier's next decision, when the level is due to be read back after a
        // burst of edges, and at least every kRetryMs to check the line.
        int timeoutMs = kRetryMs;
        std::optional<int64_t> deadline = classifier_.nextDeadlineNs();
        if (resyncAtNs_ && (!deadline || *resyncAtNs_ < *deadline)) deadline = resyncAtNs_;
        if (deadline) {
            const int64_t waitNs = *deadline - monotonicNs();
            timeoutMs = int(std::clamp<int64_t>((waitNs + 999'999) / 1'000'000, 0, kRetryMs));
        }
        const int ready = ::poll(fds, 2, timeoutMs);
        if (ready < 0 && errno == EINTR) continue;
        if (fds[1].revents) return;
        std::string lost;
        if (ready < 0) {
            lost = fmt::format("poll: {}", std::strerror(errno));
        } else if (fds[0].revents & (POLLERR | POLLHUP | POLLNVAL)) {
            lost = "its event fd hung up";
        } else {
            // The clock first, then every edge queued by then: tick() never runs ahead of an
            // edge that already happened.
            const int64_t nowNs = monotonicNs();
            if (!readEvents())
                lost = fmt::format("reading edges: {}", std::strerror(errno));
            else if (ready == 0 && !resync(nowNs))
                lost = fmt::format("reading the line: {}", std::strerror(errno));
            else
                emit(classifier_.tick(nowNs));
        }
        if (!lost.empty()) {
            logWarning("button: lost {} ({}); looking for it again every {} s", description_, lost,
                       kRetryMs / 1000);
            line_ = {};
            connected_ = false;
        }
    }
}

bool GpioButton::readEvents() {
    gpiod_line_event events[kEventBatch];
    // A bounded drain: a line that never stops chattering must not keep the thread from
    // noticing stop().
    for (int batch = 0; batch < 8; ++batch) {
        pollfd fd{gpiod_line_event_get_fd(line_.line.get()), POLLIN, 0};
        const int ready = ::poll(&fd, 1, 0);
        if (ready < 0) return errno == EINTR;
        if (ready == 0) return true;
        if (fd.revents & (POLLERR | POLLHUP | POLLNVAL)) return false;
        const int n = gpiod_line_event_read_multiple(line_.line.get(), events, kEventBatch);
        if (n < 0) return false;
        for (int i = 0; i < n; ++i) {
            // Kernel timestamps (CLOCK_MONOTONIC since Linux 5.7), not our arrival time.
            const int64_t tsNs =
                int64_t(events[i].ts.tv_sec) * 1'000'000'000 + events[i].ts.tv_nsec;
            // The last edge of a burst may be missing: the kernel's v1 queue holds 16 events,
            // and gpio-sim (like other interrupt controllers) drops an edge that comes while the
            // previous one is still being handled. So the level is read back once the line has
            // been quiet for the debounce time, before anything is decided on it.
            resyncAtNs_ =
                tsNs + std::max<int64_t>(int64_t(settings_.debounceMs) * 1'000'000, 1'000'000);
            emit(classifier_.edge(tsNs, events[i].event_type == GPIOD_LINE_EVENT_RISING_EDGE));
        }
    }
    return true;
}

bool GpioButton::resync(int64_t nowNs) {
    resyncAtNs_.reset();
    // A removed chip hangs up the event fd (seen on Linux 6.1); asking the chip fd too (ENODEV
    // once gone) catches a loss that did not wake us, at one ioctl a second.
    if (gpiod_line_update(line_.line.get()) < 0) return false;
    const int level = gpiod_line_get_value(line_.line.get());
    if (level < 0) return false;
    if ((level == 1) != classifier_.rawPressed()) {
        logDebug("button: {} reads {} after its last edge; edges were dropped", description_,
                 level);
        emit(classifier_.edge(nowNs, level == 1));
    }
    return true;
}

void GpioButton::emit(const std::vector<ButtonEvent>& events) {
    for (ButtonEvent event : events) {
        if (event == ButtonEvent::LongPress)
            logInfo("button: long press on {} (starts or stops a take)", description_);
        else
            logDebug("button: short press on {}", description_);
        if (onEvent_) onEvent_(event);
    }
}

bool GpioButton::reopen() {
    bool reported = false;
    for (;;) {
        pollfd fd{stopFd_.get(), POLLIN, 0};
        if (::poll(&fd, 1, kRetryMs) > 0) return false;
        auto line = requestGpioLine(settings_.chip, settings_.line, GpioLineUse::BothEdges,
                                    settings_.activeLow);
        if (!line) {
            // The loss was logged once already; the details only for debugging.
            if (!reported) logDebug("button: still away: {}", line.message());
            reported = true;
            continue;
        }
        const int level = gpiod_line_get_value(line->line.get());
        if (level < 0) continue;
        line_ = std::move(*line);
        classifier_.reset(monotonicNs(), level == 1);
        resyncAtNs_.reset();
        {
            std::lock_guard lock(absentMutex_);
            absentReason_.clear();
        }
        connected_ = true;
        logInfo("button: {} is there", line_.description);
        return true;
    }
}

}  // namespace previs
