#pragma once

// Debounce and press classification for one push button, as pure logic: fed edges with their
// kernel timestamps and clock ticks, it decides short and long presses. No device, no thread, no
// clock of its own, so every case is a unit test.

#include <cstdint>
#include <optional>
#include <vector>

namespace previs {

enum class ButtonEvent { ShortPress, LongPress };

const char* toString(ButtonEvent event);

class PressClassifier {
public:
    // Requires 0 <= debounceMs < longPressMs (GpioButton::create checks user settings).
    PressClassifier(int debounceMs, int longPressMs);

    // Starts over with the line at `pressed` since `nowNs`. A press already in progress is
    // ignored (no event on its release): a button held while the service starts, or while the
    // chip was away, is not a decision the user made now.
    void reset(int64_t nowNs, bool pressed);

    // The line is at `pressed` from `timestampNs` on (CLOCK_MONOTONIC, from the kernel's event,
    // so a late thread does not stretch or shorten a press). Repeats of the current level are
    // harmless (the kernel's v1 event reports the level it reads, which may repeat in a bounce
    // train). Timestamps earlier than one already seen are taken as that one.
    std::vector<ButtonEvent> edge(int64_t timestampNs, bool pressed);

    // Time has reached `nowNs` with no edge since the last call.
    std::vector<ButtonEvent> tick(int64_t nowNs);

    // When tick() next has something to decide (a pending level change becoming stable, or a
    // held press reaching the long-press threshold), or nullopt while nothing is pending.
    std::optional<int64_t> nextDeadlineNs() const;

    // The debounced level.
    bool pressed() const { return stable_; }
    // The last level fed (not yet debounced).
    bool rawPressed() const { return raw_; }

private:
    void advance(int64_t nowNs, std::vector<ButtonEvent>& out);

    int64_t debounceNs_;
    int64_t longPressNs_;
    bool raw_ = false;
    int64_t rawSinceNs_ = 0;  // when raw_ last changed
    bool stable_ = false;
    int64_t pressStartNs_ = 0;    // the edge that began the current debounced press
    bool pressConsumed_ = false;  // long press fired (or press ignored): its release says nothing
    int64_t lastNs_ = 0;
};

}  // namespace previs
