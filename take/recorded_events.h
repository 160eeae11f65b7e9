#pragma once

// The recorded twin of the button and the control socket (DESIGN.md §1: every source has a live
// and a recorded implementation): the mode changes of a session's events.csv, fired as previsd
// plays the session's scene camera. Each event is tied to the first recorded frame at or after
// it, so it fires when that frame arrives — on every pass of a looping demo, whatever the
// machine's speed.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"
#include "io/session.h"
#include "shot/mode_machine.h"

namespace previs {

// A recorded event as the live machine would have seen it: a mode-button short press toggles,
// ctl "mode=preview|refine|toggle" sets or toggles, ("session", "restart") returns to preview
// (a looping take starts over as it was recorded). Other events are left alone.
void applySessionEvent(ModeMachine& modes, const SessionEvent& event);

class RecordedEvents {
public:
    // `sceneCameraDir` is SESSION/cameras/<name>; nullopt when the session has no events.
    static Result<std::optional<RecordedEvents>> load(const std::string& sceneCameraDir);

    // The events due when the frame with this recorded sequence arrives (in order; a sequence
    // lower than the last one means the recording started over).
    std::vector<SessionEvent> due(uint32_t recordedSequence);
    // Whether the last due() call saw the recording start over (its modes start over too).
    bool restarted() const { return restarted_; }
    size_t size() const { return events_.size(); }

private:
    struct Tied {
        uint64_t frameSequence;
        SessionEvent event;
    };
    std::vector<Tied> events_;  // by frame
    std::optional<uint32_t> last_;
    bool restarted_ = false;
};

}  // namespace previs
