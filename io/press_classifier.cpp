#include "io/press_classifier.h"

#include <algorithm>

#include "base/log.h"

namespace previs {

const char* toString(ButtonEvent event) {
    switch (event) {
        case ButtonEvent::ShortPress:
            return "short press";
        case ButtonEvent::LongPress:
            return "long press";
    }
    return "?";
}

PressClassifier::PressClassifier(int debounceMs, int longPressMs)
    : debounceNs_(int64_t(debounceMs) * 1'000'000), longPressNs_(int64_t(longPressMs) * 1'000'000) {
    PV_ASSERT(debounceMs >= 0 && debounceMs < longPressMs);
}

void PressClassifier::reset(int64_t nowNs, bool pressed) {
    raw_ = stable_ = pressed;
    rawSinceNs_ = pressStartNs_ = lastNs_ = nowNs;
    pressConsumed_ = pressed;
}

std::vector<ButtonEvent> PressClassifier::edge(int64_t timestampNs, bool pressed) {
    std::vector<ButtonEvent> out;
    const int64_t t = std::max(timestampNs, lastNs_);
    // Decide what became true before this edge, with the old level, then take the new level.
    advance(t, out);
    if (pressed != raw_) {
        raw_ = pressed;
        rawSinceNs_ = t;
    }
    advance(t, out);
    return out;
}

std::vector<ButtonEvent> PressClassifier::tick(int64_t nowNs) {
    std::vector<ButtonEvent> out;
    advance(std::max(nowNs, lastNs_), out);
    return out;
}

std::optional<int64_t> PressClassifier::nextDeadlineNs() const {
    if (raw_ != stable_) return rawSinceNs_ + debounceNs_;
    if (stable_ && !pressConsumed_) return pressStartNs_ + longPressNs_;
    return std::nullopt;
}

// The raw level has been constant since rawSinceNs_; events are decided in time order.
void PressClassifier::advance(int64_t nowNs, std::vector<ButtonEvent>& out) {
    lastNs_ = nowNs;
    if (raw_ != stable_ && nowNs >= rawSinceNs_ + debounceNs_) {
        stable_ = raw_;
        if (stable_) {
            // The hold is timed from the edge that began the stable level, not from when it
            // was confirmed: the hold time is what the user did.
            pressStartNs_ = rawSinceNs_;
            pressConsumed_ = false;
        } else if (!pressConsumed_) {
            out.push_back(ButtonEvent::ShortPress);
        }
    }
    // A long press fires at the threshold, while still held, not at release: the user holding
    // the button gets feedback that the hold registered and knows when to let go; waiting for
    // the release would leave them guessing how long is long enough. A glitch (raw released,
    // not yet stable) pauses the decision rather than ending the press.
    if (stable_ && raw_ && !pressConsumed_ && nowNs >= pressStartNs_ + longPressNs_) {
        pressConsumed_ = true;
        out.push_back(ButtonEvent::LongPress);
    }
}

}  // namespace previs
