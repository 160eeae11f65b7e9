// PressClassifier (debounce, short and long presses) case by case, and the GpioButton and
// StatusLed checks that need no GPIO chip. The device behaviour is tested in the VM
// (io_vm_test.cpp).
#include <gtest/gtest.h>

#include <random>

#include "io/gpio_button.h"
#include "io/press_classifier.h"
#include "io/status_led.h"

namespace previs {

// Readable failures ("short press", not the enum's bytes); found by gtest through ADL.
void PrintTo(ButtonEvent event, std::ostream* os);
void PrintTo(ButtonEvent event, std::ostream* os) { *os << toString(event); }

namespace {

using Events = std::vector<ButtonEvent>;
constexpr auto kShort = ButtonEvent::ShortPress;
constexpr auto kLong = ButtonEvent::LongPress;

// A monotonic clock far from 0, as the kernel's is.
constexpr int64_t kT0 = 1'000'000'000'000;
constexpr int64_t ms(double m) { return kT0 + int64_t(m * 1'000'000); }
constexpr int64_t kUs = 1000;

// Defaults of ButtonSettings: 20 ms debounce, 1.5 s long press.
PressClassifier makeClassifier() {
    PressClassifier c(20, 1500);
    c.reset(ms(0), false);
    return c;
}

// `count` level changes starting at `startNs`, `stepNs` apart, first to `firstLevel`.
Events bounce(PressClassifier& c, int64_t startNs, int64_t stepNs, int count, bool firstLevel) {
    Events all;
    bool level = firstLevel;
    for (int i = 0; i < count; ++i, level = !level) {
        Events e = c.edge(startNs + i * stepNs, level);
        all.insert(all.end(), e.begin(), e.end());
    }
    return all;
}

TEST(PressClassifier, CleanShortPressFiresOnDebouncedRelease) {
    PressClassifier c = makeClassifier();
    EXPECT_EQ(c.edge(ms(100), true), Events{});
    EXPECT_EQ(c.tick(ms(119.9)), Events{});
    EXPECT_FALSE(c.pressed());
    EXPECT_EQ(c.tick(ms(120)), Events{});  // a press is confirmed, but says nothing yet
    EXPECT_TRUE(c.pressed());
    EXPECT_EQ(c.edge(ms(300), false), Events{});
    EXPECT_EQ(c.tick(ms(319.9)), Events{});
    EXPECT_EQ(c.tick(ms(320)), Events{kShort});
    EXPECT_FALSE(c.pressed());
    EXPECT_EQ(c.tick(ms(5000)), Events{});
}

TEST(PressClassifier, DeadlinesSayWhenToTick) {
    PressClassifier c = makeClassifier();
    EXPECT_EQ(c.nextDeadlineNs(), std::nullopt);
    c.edge(ms(100), true);
    EXPECT_EQ(c.nextDeadlineNs(), ms(120));
    c.tick(ms(120));
    EXPECT_EQ(c.nextDeadlineNs(), ms(1600));  // long press, from the first edge of the hold
    c.edge(ms(300), false);
    EXPECT_EQ(c.nextDeadlineNs(), ms(320));
    c.tick(ms(320));
    EXPECT_EQ(c.nextDeadlineNs(), std::nullopt);
}

TEST(PressClassifier, PressShorterThanDebounceIsIgnored) {
    PressClassifier c = makeClassifier();
    EXPECT_EQ(c.edge(ms(100), true), Events{});
    EXPECT_EQ(c.edge(ms(119.999), false), Events{});
    EXPECT_EQ(c.tick(ms(1000)), Events{});
    EXPECT_FALSE(c.pressed());
    EXPECT_EQ(c.tick(ms(10000)), Events{});
}

TEST(PressClassifier, PressExactlyAtTheDebounceBoundaryCounts) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    // The release edge lands exactly debounceMs after the press: the press was stable for the
    // whole debounce time, so it counts.
    EXPECT_EQ(c.edge(ms(120), false), Events{});
    EXPECT_TRUE(c.pressed());
    EXPECT_EQ(c.tick(ms(139.999)), Events{});
    EXPECT_EQ(c.tick(ms(140)), Events{kShort});
}

TEST(PressClassifier, OneNanosecondShortOfTheBoundaryDoesNot) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    EXPECT_EQ(c.edge(ms(120) - 1, false), Events{});
    EXPECT_FALSE(c.pressed());
    EXPECT_EQ(c.tick(ms(1000)), Events{});
}

TEST(PressClassifier, FiftyBouncesWithinTenMsThenHeldIsOneShortPress) {
    PressClassifier c = makeClassifier();
    // 50 level changes, 200 us apart (9.8 ms in all), ending pressed (the 50th is a release,
    // the 51st the final press).
    Events e = bounce(c, ms(100), 200 * kUs, 51, true);
    EXPECT_EQ(e, Events{});
    EXPECT_TRUE(c.rawPressed());
    EXPECT_FALSE(c.pressed());
    EXPECT_EQ(c.tick(ms(200)), Events{});
    EXPECT_TRUE(c.pressed());
    EXPECT_EQ(c.edge(ms(400), false), Events{});
    EXPECT_EQ(c.tick(ms(1000)), Events{kShort});
    EXPECT_EQ(c.tick(ms(5000)), Events{});
}

TEST(PressClassifier, BouncesOnPressAndReleaseAreOneShortPress) {
    PressClassifier c = makeClassifier();
    Events all = bounce(c, ms(100), 150 * kUs, 51, true);  // ends pressed
    Events e = c.tick(ms(150));
    all.insert(all.end(), e.begin(), e.end());
    e = bounce(c, ms(400), 150 * kUs, 51, false);  // ends released, at 407.5 ms
    all.insert(all.end(), e.begin(), e.end());
    EXPECT_EQ(all, Events{});
    EXPECT_EQ(c.tick(ms(427.4)), Events{});  // 20 ms after the last bounce, not the first
    EXPECT_EQ(c.tick(ms(427.5)), Events{kShort});
}

TEST(PressClassifier, FiftyBouncesThatEndReleasedAreNoPress) {
    PressClassifier c = makeClassifier();
    Events e = bounce(c, ms(100), 200 * kUs, 50, true);  // ends released after 9.8 ms
    EXPECT_EQ(e, Events{});
    EXPECT_EQ(c.tick(ms(1000)), Events{});
    EXPECT_FALSE(c.pressed());
}

TEST(PressClassifier, BouncesWithoutTicksAreDecidedByTheNextEdge) {
    // A loaded machine: the thread never woke at the deadlines, only edges arrive.
    PressClassifier c = makeClassifier();
    EXPECT_EQ(bounce(c, ms(100), 100 * kUs, 51, true), Events{});
    EXPECT_EQ(c.edge(ms(300), false), Events{});       // confirms the press, starts the release
    EXPECT_EQ(c.edge(ms(900), true), Events{kShort});  // confirms the release first
    EXPECT_EQ(c.edge(ms(905), false), Events{});       // a 5 ms glitch: no press
    EXPECT_EQ(c.tick(ms(2000)), Events{});
}

TEST(PressClassifier, LongPressFiresAtTheThresholdWhileHeld) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    EXPECT_EQ(c.tick(ms(200)), Events{});
    EXPECT_EQ(c.tick(ms(1599.999)), Events{});
    EXPECT_EQ(c.tick(ms(1600)), Events{kLong});
    EXPECT_EQ(c.nextDeadlineNs(), std::nullopt);
    EXPECT_EQ(c.tick(ms(4000)), Events{});  // once per hold
    EXPECT_TRUE(c.pressed());
}

TEST(PressClassifier, ReleaseAfterLongPressEmitsNothing) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    EXPECT_EQ(c.tick(ms(1600)), Events{kLong});
    // A bouncy release.
    EXPECT_EQ(bounce(c, ms(3000), 300 * kUs, 31, false), Events{});
    EXPECT_EQ(c.tick(ms(3100)), Events{});
    EXPECT_FALSE(c.pressed());
    // The next press is an ordinary one again.
    c.edge(ms(4000), true);
    c.edge(ms(4100), false);
    EXPECT_EQ(c.tick(ms(4200)), Events{kShort});
}

TEST(PressClassifier, LongPressIsFoundByAReleaseEdgeWhenNoTickCame) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    // The thread slept through the threshold; the hold still lasted 2 s by the kernel's clock.
    EXPECT_EQ(c.edge(ms(2100), false), Events{kLong});
    EXPECT_EQ(c.tick(ms(3000)), Events{});
}

TEST(PressClassifier, LateTickDecidesInTimeOrder) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    c.edge(ms(1000), false);  // held 0.9 s: short
    EXPECT_EQ(c.tick(ms(9000)), Events{kShort});
}

TEST(PressClassifier, PressHeldOneNanosecondShortOfLongIsShort) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    EXPECT_EQ(c.edge(ms(1600) - 1, false), Events{});
    EXPECT_EQ(c.tick(ms(1700)), Events{kShort});
}

TEST(PressClassifier, GlitchDuringAHoldDoesNotEndIt) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    c.tick(ms(200));
    EXPECT_EQ(c.edge(ms(1000), false), Events{});
    EXPECT_EQ(c.edge(ms(1005), true), Events{});  // 5 ms: contact chatter, still held
    EXPECT_EQ(c.tick(ms(1600)), Events{kLong});
    c.edge(ms(2000), false);
    EXPECT_EQ(c.tick(ms(2100)), Events{});
}

TEST(PressClassifier, GlitchAcrossTheThresholdDelaysTheLongPressToTheReturn) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    c.tick(ms(200));
    EXPECT_EQ(c.edge(ms(1590), false), Events{});
    EXPECT_EQ(c.tick(ms(1600)), Events{});             // released at the threshold: undecided
    EXPECT_EQ(c.edge(ms(1605), true), Events{kLong});  // back after 15 ms: it was a glitch
}

TEST(PressClassifier, ButtonHeldAtResetIsIgnoredUntilReleased) {
    PressClassifier c(20, 1500);
    c.reset(ms(0), true);
    EXPECT_TRUE(c.pressed());
    EXPECT_EQ(c.tick(ms(5000)), Events{});  // no long press for a hold we did not see begin
    c.edge(ms(6000), false);
    EXPECT_EQ(c.tick(ms(6100)), Events{});  // and its release says nothing
    c.edge(ms(7000), true);
    c.edge(ms(7100), false);
    EXPECT_EQ(c.tick(ms(7200)), Events{kShort});
}

TEST(PressClassifier, RepeatedLevelsAndOldTimestampsAreHarmless) {
    PressClassifier c = makeClassifier();
    c.edge(ms(100), true);
    c.edge(ms(110), true);  // the kernel's v1 events may report the same level twice
    EXPECT_EQ(c.nextDeadlineNs(), ms(120));  // the repeat did not restart the debounce
    c.tick(ms(130));
    c.edge(ms(300), false);
    EXPECT_EQ(c.edge(ms(250), false), Events{});  // earlier than seen: taken as 300 ms
    EXPECT_EQ(c.tick(ms(320)), Events{kShort});
}

TEST(PressClassifier, ZeroDebounceTakesEveryEdge) {
    PressClassifier c(0, 1500);
    c.reset(ms(0), false);
    EXPECT_EQ(c.edge(ms(100), true), Events{});
    EXPECT_TRUE(c.pressed());
    EXPECT_EQ(c.edge(ms(100.001), false), Events{kShort});
}

// Random presses, each with a bounce train on press and on release shorter than the debounce
// time: exactly one event per press, of the kind its hold time says.
TEST(PressClassifier, RandomBouncyPressesAreCountedExactly) {
    std::mt19937 rng(1234);
    std::uniform_int_distribution<int> bounces(0, 30);
    std::uniform_int_distribution<int64_t> stepNs(10 * kUs, 300 * kUs);
    std::uniform_int_distribution<int64_t> holdMs(40, 2500);
    std::uniform_int_distribution<int64_t> gapMs(40, 500);
    std::bernoulli_distribution tickLate(0.5);

    PressClassifier c = makeClassifier();
    Events got, want;
    int64_t t = ms(10);
    for (int press = 0; press < 300; ++press) {
        auto add = [&](Events e) { got.insert(got.end(), e.begin(), e.end()); };
        const int64_t step = stepNs(rng);
        const int n = 2 * bounces(rng) + 1;  // odd: ends at the new level
        ASSERT_LT(n * step, ms(20) - kT0);
        const int64_t pressAt = t;
        add(bounce(c, pressAt, step, n, true));
        const int64_t stableFrom = pressAt + (n - 1) * step;
        int64_t hold = holdMs(rng) * 1'000'000;
        // Release bounces within the debounce time count as still held, so a hold this close
        // to the threshold is decided by them (the boundary has its own tests).
        if (hold > 1'470'000'000 && hold < 1'530'000'000) hold += 60'000'000;
        const int64_t releaseAt = stableFrom + hold;
        if (!tickLate(rng)) add(c.tick(stableFrom + 25'000'000));  // else: only edges decide
        add(bounce(c, releaseAt, step, n, false));
        t = releaseAt + (n - 1) * step + gapMs(rng) * 1'000'000;
        if (!tickLate(rng)) add(c.tick(t - 1'000'000));
        // The hold is timed from the edge that began the stable press to the release's first
        // edge.
        want.push_back(hold >= 1'500'000'000 ? kLong : kShort);
    }
    Events last = c.tick(t + ms(100) - kT0);
    got.insert(got.end(), last.begin(), last.end());
    EXPECT_EQ(got, want);
}

// The checks that come before any device is touched.
TEST(GpioButton, RejectsALongPressNotLongerThanTheDebounce) {
    ButtonSettings s;
    s.chip = "vmtest";
    s.line = "mode-button";
    s.debounceMs = 50;
    s.longPressMs = 50;
    auto b = GpioButton::create(s, {});
    ASSERT_FALSE(b);
    EXPECT_NE(b.message().find("long_press_ms 50 must be longer than debounce_ms 50"),
              std::string::npos)
        << b.message();
}

TEST(GpioButton, RejectsANegativeDebounce) {
    ButtonSettings s;
    s.chip = "vmtest";
    s.line = "mode-button";
    s.debounceMs = -1;
    auto b = GpioButton::create(s, {});
    ASSERT_FALSE(b);
    EXPECT_NE(b.message().find("debounce_ms -1"), std::string::npos) << b.message();
}

// A chip that is not there may yet come (an expander that probes late): the button starts
// without it, names what it looks for, and keeps looking (the VM test io_vm sees it come).
TEST(GpioButton, AMissingChipStartsItAbsentAndIsNamed) {
    ButtonSettings s;
    s.chip = "/dev/gpiochip-previs-test-missing";
    s.line = "mode-button";
    auto b = GpioButton::create(s, {});
    ASSERT_TRUE(b) << b.message();
    EXPECT_FALSE((*b)->connected());
    const std::string why = (*b)->absentReason();
    EXPECT_NE(why.find("gpio: cannot open chip /dev/gpiochip-previs-test-missing: No such file or "
                       "directory"),
              std::string::npos)
        << why;
    EXPECT_NE(why.find("chips: "), std::string::npos) << why;
    (*b)->stop();  // prompt while it is looking
}

TEST(StatusLed, AnUnknownChipStartsItDark) {
    auto led = StatusLed::create("no-such-gpio-chip", "status-led", false);
    ASSERT_TRUE(led) << led.message();
    EXPECT_FALSE((*led)->connected());
    (*led)->set(
        true);  // nothing to drive: no error, no crash; it looks again at most once a second
    EXPECT_FALSE((*led)->connected());
}

}  // namespace
}  // namespace previs
