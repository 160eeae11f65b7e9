// The mode button and status LED against the kernel's GPIO character device, inside the test VM
// (../shared/vmtest): gpio-sim's chip 'vmtest' with lines mode-button, aux-button, status-led and
// spare. A test presses by writing the simulated pull (idle pull-down, press pull-up) and reads
// an output line's driven value, both through gpio-sim's sysfs. Outside the VM the binary exits
// 77, which CTest reports as skipped.
#include <fcntl.h>
#include <gpiod.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <thread>

#include "base/log.h"
#include "io/gpio_button.h"
#include "io/status_led.h"
#include "tests/support/vm_test_main.h"

namespace previs {

// Readable failures ("short press", not the enum's bytes); found by gtest through ADL.
void PrintTo(ButtonEvent event, std::ostream* os);
void PrintTo(ButtonEvent event, std::ostream* os) { *os << toString(event); }

namespace {

using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

// Generous: the VM runs code 3–20x slower than the host.
constexpr auto kEventTimeout = 5s;
// How long "nothing more happens" is watched: many times the 20 ms debounce.
constexpr auto kQuietTime = 400ms;
constexpr const char* kConfigfs = "/sys/kernel/config/gpio-sim/vmtest";

std::string readLine(const std::string& path) {
    std::ifstream in(path);
    std::string s;
    std::getline(in, s);
    return s;
}

// gpio-sim's sysfs folder, found again each time: it moves when the chip is re-created.
std::string simDir() {
    const std::string dev = readLine(std::string(kConfigfs) + "/dev_name");
    const std::string chip = readLine(std::string(kConfigfs) + "/bank0/chip_name");
    if (!dev.empty() && !chip.empty()) return "/sys/devices/platform/" + dev + "/" + chip;
    return std::getenv("VMTEST_GPIO_SIM");
}

std::string chipPath() { return std::getenv("VMTEST_GPIOCHIP"); }

unsigned offsetOf(const std::string& name) {
    gpiod_chip* chip = gpiod_chip_open_by_label("vmtest");
    EXPECT_NE(chip, nullptr);
    if (!chip) return 0;
    gpiod_line* line = gpiod_chip_find_line(chip, name.c_str());
    EXPECT_NE(line, nullptr) << name;
    const unsigned offset = line ? gpiod_line_offset(line) : 0;
    gpiod_chip_close(chip);
    return offset;
}

bool writeFile(const std::string& path, const std::string& text) {
    std::ofstream out(path);
    out << text;
    out.flush();
    return bool(out);
}

// The simulated switch on one line: its pull is the outside world driving the input.
class SimLine {
public:
    explicit SimLine(const std::string& name) : offset_(offsetOf(name)) {
        const std::string dir = simDir() + "/sim_gpio" + std::to_string(offset_);
        pullFd_ = ::open((dir + "/pull").c_str(), O_WRONLY | O_CLOEXEC);
        valuePath_ = dir + "/value";
        EXPECT_GE(pullFd_, 0) << dir;
    }
    ~SimLine() {
        if (pullFd_ >= 0) ::close(pullFd_);
    }
    // As fast as a write(2) goes: the bounce trains use it too.
    bool setHigh(bool high) {
        const char* text = high ? "pull-up" : "pull-down";
        return ::pwrite(pullFd_, text, std::strlen(text), 0) == ssize_t(std::strlen(text));
    }
    int value() const {
        const std::string v = readLine(valuePath_);
        return v.empty() ? -1 : std::atoi(v.c_str());
    }
    unsigned offset() const { return offset_; }

private:
    unsigned offset_;
    int pullFd_ = -1;
    std::string valuePath_;
};

// Collects a button's events from its thread.
class EventLog {
public:
    std::function<void(ButtonEvent)> callback() {
        return [this](ButtonEvent e) {
            std::lock_guard lock(mutex_);
            events_.push_back(e);
            cv_.notify_all();
        };
    }
    // Waits until `count` events have arrived (or the timeout) and returns what has.
    std::vector<ButtonEvent> waitFor(size_t count,
                                     std::chrono::milliseconds timeout = kEventTimeout) {
        std::unique_lock lock(mutex_);
        cv_.wait_for(lock, timeout, [&] { return events_.size() >= count; });
        return events_;
    }
    std::vector<ButtonEvent> events() {
        std::lock_guard lock(mutex_);
        return events_;
    }

private:
    std::mutex mutex_;
    std::condition_variable cv_;
    std::vector<ButtonEvent> events_;
};

template <typename F>
bool waitUntil(F condition, std::chrono::milliseconds timeout) {
    const auto end = Clock::now() + timeout;
    while (!condition()) {
        if (Clock::now() > end) return false;
        std::this_thread::sleep_for(10ms);
    }
    return true;
}

ButtonSettings modeButton() {
    ButtonSettings s;
    s.chip = "vmtest";
    s.line = "mode-button";
    return s;
}

class IoVm : public ::testing::Test {
protected:
    void SetUp() override { ASSERT_TRUE(button_.setHigh(false)); }  // idle: released
    void TearDown() override { button_.setHigh(false); }

    SimLine button_{"mode-button"};
};

using Events = std::vector<ButtonEvent>;

TEST_F(IoVm, OpensByLabelAndLineName) {
    auto b = GpioButton::create(modeButton(), {});
    ASSERT_TRUE(b) << b.message();
    EXPECT_NE((*b)->description().find("'mode-button'"), std::string::npos);
    EXPECT_NE((*b)->description().find("vmtest (" + chipPath() + ")"), std::string::npos)
        << (*b)->description();
}

TEST_F(IoVm, OpensByPathAndOffset) {
    ButtonSettings s;
    s.chip = chipPath();
    s.line = std::to_string(button_.offset());
    auto b = GpioButton::create(s, {});
    ASSERT_TRUE(b) << b.message();
    EXPECT_NE((*b)->description().find("'mode-button'"), std::string::npos) << (*b)->description();
}

TEST_F(IoVm, OpensByChipName) {
    ButtonSettings s = modeButton();
    s.chip = chipPath().substr(chipPath().rfind('/') + 1);  // "gpiochip0"
    auto b = GpioButton::create(s, {});
    ASSERT_TRUE(b) << b.message();
}

TEST_F(IoVm, PressIsAShortPress) {
    EventLog log;
    auto b = GpioButton::create(modeButton(), log.callback());
    ASSERT_TRUE(b) << b.message();
    ASSERT_TRUE(button_.setHigh(true));
    std::this_thread::sleep_for(100ms);
    ASSERT_TRUE(button_.setHigh(false));
    EXPECT_EQ(log.waitFor(1), Events{ButtonEvent::ShortPress});
    std::this_thread::sleep_for(kQuietTime);
    EXPECT_EQ(log.events(), Events{ButtonEvent::ShortPress});
}

// The scenario: a press switches to refinement and lights the LED, a second press
// returns to preview and puts it out (the daemon's wiring, in miniature).
TEST_F(IoVm, PressesToggleTheModeAndTheLed) {
    SimLine ledLine("status-led");
    auto led = StatusLed::create("vmtest", "status-led", false);
    ASSERT_TRUE(led) << led.message();
    EXPECT_EQ(ledLine.value(), 0);
    std::atomic<bool> refining = false;
    EventLog log;
    auto onEvent = [&, record = log.callback()](ButtonEvent e) {
        if (e == ButtonEvent::ShortPress) {
            refining = !refining;
            (*led)->set(refining);
        }
        record(e);
    };
    auto b = GpioButton::create(modeButton(), onEvent);
    ASSERT_TRUE(b) << b.message();

    for (int press = 1; press <= 2; ++press) {
        ASSERT_TRUE(button_.setHigh(true));
        std::this_thread::sleep_for(80ms);
        ASSERT_TRUE(button_.setHigh(false));
        ASSERT_EQ(log.waitFor(press).size(), size_t(press));
        const int want = press == 1 ? 1 : 0;
        EXPECT_TRUE(waitUntil([&] { return ledLine.value() == want; }, 2000ms))
            << "press " << press << ": LED line reads " << ledLine.value();
    }
    EXPECT_FALSE(refining);
    (*b)->stop();
}

// 50 level changes as fast as write(2) goes (well within 10 ms on the host; the VM is slower),
// on both the press and the release: one press. 100 edges also overflow the kernel's 16-event
// queue, so the button must read the level back to see the last one.
TEST_F(IoVm, FiftyBouncesToggleOnce) {
    EventLog log;
    ButtonSettings s = modeButton();
    auto b = GpioButton::create(s, log.callback());
    ASSERT_TRUE(b) << b.message();

    auto train = [&](bool finalHigh) {
        auto last = Clock::now();
        auto longestGap = Clock::duration::zero();
        const auto start = last;
        for (int i = 0; i <= 50; ++i) {  // 50 bounces, then the final level
            EXPECT_TRUE(button_.setHigh(i % 2 == 0 ? finalHigh : !finalHigh));
            const auto now = Clock::now();
            longestGap = std::max(longestGap, now - last);
            last = now;
        }
        const auto ms = [](auto d) { return std::chrono::duration<double, std::milli>(d).count(); };
        std::printf("bounce train: 51 writes in %.2f ms, longest gap %.2f ms\n", ms(last - start),
                    ms(longestGap));
        return longestGap;
    };
    // Three presses: an edge lost at the end of a train is a matter of timing, so one press
    // could pass by luck.
    constexpr size_t kPresses = 3;
    auto longestGap = Clock::duration::zero();
    for (size_t press = 1; press <= kPresses; ++press) {
        longestGap = std::max(longestGap, train(true));
        std::this_thread::sleep_for(150ms);
        longestGap = std::max(longestGap, train(false));
        if (longestGap >= std::chrono::milliseconds(s.debounceMs))
            GTEST_SKIP() << "the VM stalled for longer than the debounce time inside a bounce "
                            "train: it was not a bounce train";
        EXPECT_EQ(log.waitFor(press).size(), press);
    }
    std::this_thread::sleep_for(kQuietTime);
    EXPECT_EQ(log.events(), Events(kPresses, ButtonEvent::ShortPress));
}

TEST_F(IoVm, HoldIsALongPressAtTheThreshold) {
    EventLog log;
    ButtonSettings s = modeButton();
    s.longPressMs = 400;
    auto b = GpioButton::create(s, log.callback());
    ASSERT_TRUE(b) << b.message();
    const auto pressedAt = Clock::now();
    ASSERT_TRUE(button_.setHigh(true));
    // Still held: a long press fires at the threshold, not at the release.
    EXPECT_EQ(log.waitFor(1), Events{ButtonEvent::LongPress});
    const auto firedAfter = Clock::now() - pressedAt;
    EXPECT_GE(firedAfter, 400ms);
    ASSERT_TRUE(button_.setHigh(false));
    std::this_thread::sleep_for(kQuietTime);
    EXPECT_EQ(log.events(), Events{ButtonEvent::LongPress});  // its release says nothing
}

TEST_F(IoVm, ActiveLowButtonPressesOnLow) {
    EventLog log;
    ButtonSettings s = modeButton();
    s.activeLow = true;
    // Idle pull-down is "held" for an active-low button: a press we did not see begin.
    auto b = GpioButton::create(s, log.callback());
    ASSERT_TRUE(b) << b.message();
    ASSERT_TRUE(button_.setHigh(true));  // released
    std::this_thread::sleep_for(kQuietTime);
    EXPECT_EQ(log.events(), Events{});
    ASSERT_TRUE(button_.setHigh(false));  // pressed
    std::this_thread::sleep_for(100ms);
    ASSERT_TRUE(button_.setHigh(true));
    EXPECT_EQ(log.waitFor(1), Events{ButtonEvent::ShortPress});
}

TEST_F(IoVm, LedDrivesTheLineAndActiveLowInverts) {
    SimLine ledLine("status-led");
    {
        auto led = StatusLed::create(chipPath(), "status-led", false);
        ASSERT_TRUE(led) << led.message();
        EXPECT_EQ(ledLine.value(), 0);
        (*led)->set(true);
        EXPECT_EQ(ledLine.value(), 1);
        (*led)->set(false);
        EXPECT_EQ(ledLine.value(), 0);
    }
    auto led = StatusLed::create("vmtest", std::to_string(ledLine.offset()), true);
    ASSERT_TRUE(led) << led.message();
    EXPECT_EQ(ledLine.value(), 1);  // off, active low
    (*led)->set(true);
    EXPECT_EQ(ledLine.value(), 0);
    (*led)->set(false);
    EXPECT_EQ(ledLine.value(), 1);
}

TEST_F(IoVm, BadChipAndLineAreNamedWithWhatExists) {
    // A chip that is not there may yet come (an expander probing late): the button starts
    // without it, and says what it looks for and what there is.
    ButtonSettings s = modeButton();
    s.chip = "vmtset";
    {
        auto absent = GpioButton::create(s, {});
        ASSERT_TRUE(absent) << absent.message();
        EXPECT_FALSE((*absent)->connected());
        const std::string why = (*absent)->absentReason();
        EXPECT_NE(why.find("gpio: no chip named or labelled 'vmtset'"), std::string::npos) << why;
        EXPECT_NE(why.find("'vmtest'"), std::string::npos) << why;
    }

    // A line the present chip does not have only the config can mend: an error.
    s = modeButton();
    s.line = "mode-buton";
    auto b = GpioButton::create(s, {});
    ASSERT_FALSE(b);
    EXPECT_EQ(b.message(), "gpio: no line 'mode-buton' on chip vmtest (" + chipPath() +
                               "); lines: mode-button, aux-button, status-led, spare");

    s.line = "99";
    b = GpioButton::create(s, {});
    ASSERT_FALSE(b);
    EXPECT_NE(b.message().find("gpio: no line 99 on chip vmtest"), std::string::npos)
        << b.message();

    auto led = StatusLed::create("vmtest", "no-led", false);
    ASSERT_FALSE(led);
    EXPECT_NE(led.message().find("no line 'no-led'"), std::string::npos) << led.message();
}

TEST_F(IoVm, BusyLineNamesItsUser) {
    auto first = GpioButton::create(modeButton(), {});
    ASSERT_TRUE(first) << first.message();
    // Busy is absent for now (another program may let go of it): the second starts without it.
    auto second = GpioButton::create(modeButton(), {});
    ASSERT_TRUE(second) << second.message();
    EXPECT_FALSE((*second)->connected());
    EXPECT_NE((*second)->absentReason().find("is busy (used by 'previs')"), std::string::npos)
        << (*second)->absentReason();
}

TEST_F(IoVm, StopIsPrompt) {
    auto b = GpioButton::create(modeButton(), {});
    ASSERT_TRUE(b) << b.message();
    std::this_thread::sleep_for(50ms);
    const auto start = Clock::now();
    (*b)->stop();
    // The thread waits on a stop eventfd, not a polling period; 2 s allows for a slow VM.
    EXPECT_LT(Clock::now() - start, 2s);
    (*b)->stop();  // idempotent
}

// Last: it re-creates the chip. gpio-sim's chip goes away (configfs live 0) and comes back; the
// button finds it again and works.
TEST_F(IoVm, ButtonSurvivesTheChipGoingAway) {
    EventLog log;
    auto b = GpioButton::create(modeButton(), log.callback());
    ASSERT_TRUE(b) << b.message();
    ASSERT_TRUE(writeFile(std::string(kConfigfs) + "/live", "0"));
    EXPECT_TRUE(waitUntil([&] { return !(*b)->connected(); }, 10000ms));
    ASSERT_TRUE(writeFile(std::string(kConfigfs) + "/live", "1"));
    EXPECT_TRUE(waitUntil([&] { return (*b)->connected(); }, 10000ms));

    SimLine again("mode-button");  // the sysfs folder may have moved
    ASSERT_TRUE(again.setHigh(true));
    std::this_thread::sleep_for(100ms);
    ASSERT_TRUE(again.setHigh(false));
    EXPECT_EQ(log.waitFor(1), Events{ButtonEvent::ShortPress});
}

// At boot previsd may start before the GPIO expander has probed: the button and the LED start
// without their chip and work once it appears.
TEST_F(IoVm, ButtonAndLedAbsentAtStartWorkOnceTheChipAppears) {
    ASSERT_TRUE(writeFile(std::string(kConfigfs) + "/live", "0"));
    EventLog log;
    auto b = GpioButton::create(modeButton(), log.callback());
    ASSERT_TRUE(b) << b.message();
    EXPECT_FALSE((*b)->connected());
    EXPECT_NE((*b)->absentReason().find("vmtest"), std::string::npos) << (*b)->absentReason();
    auto led = StatusLed::create("vmtest", "status-led", false);
    ASSERT_TRUE(led) << led.message();
    EXPECT_FALSE((*led)->connected());
    (*led)->set(true);  // nothing to drive yet: no error, no crash

    ASSERT_TRUE(writeFile(std::string(kConfigfs) + "/live", "1"));
    EXPECT_TRUE(waitUntil([&] { return (*b)->connected(); }, 10000ms));
    EXPECT_TRUE((*b)->absentReason().empty()) << (*b)->absentReason();
    SimLine button("mode-button");
    ASSERT_TRUE(button.setHigh(true));
    std::this_thread::sleep_for(100ms);
    ASSERT_TRUE(button.setHigh(false));
    EXPECT_EQ(log.waitFor(1), Events{ButtonEvent::ShortPress});
    // set() looks for the line again at most once a second, so within a few calls it drives it.
    SimLine ledLine("status-led");
    EXPECT_TRUE(waitUntil(
        [&] {
            (*led)->set(true);
            return ledLine.value() == 1;
        },
        10000ms));
    EXPECT_TRUE((*led)->connected());
}

// The LED, like the button, comes back with its chip (a USB expander replugged).
TEST_F(IoVm, LedComesBackWithItsChip) {
    auto led = StatusLed::create("vmtest", "status-led", false);
    ASSERT_TRUE(led) << led.message();
    (*led)->set(true);
    ASSERT_TRUE(writeFile(std::string(kConfigfs) + "/live", "0"));
    EXPECT_TRUE(waitUntil(
        [&] {
            (*led)->set(false);
            return !(*led)->connected();
        },
        10000ms));
    ASSERT_TRUE(writeFile(std::string(kConfigfs) + "/live", "1"));
    SimLine ledLine("status-led");
    EXPECT_TRUE(waitUntil(
        [&] {
            (*led)->set(true);
            return (*led)->connected() && ledLine.value() == 1;
        },
        10000ms));
    (*led)->set(false);
    EXPECT_EQ(ledLine.value(), 0);
}

}  // namespace
}  // namespace previs

int main(int argc, char** argv) {
    // IO_TRACE=1: the button's debug log too (presses, levels read back after dropped edges).
    if (std::getenv("IO_TRACE")) previs::setLogLevel(previs::LogLevel::Debug);
    return previs::testing::runVmTests(argc, argv, "test_io_vm");
}
