#pragma once

// The box's one piece of state a crew changes (issue 7): preview or refinement. The button
// thread and the control socket drive the same machine; the render thread reads it. A change
// is a version bump, so the render thread notices a toggle even if two arrive between frames.

#include <cstdint>
#include <mutex>
#include <optional>
#include <string_view>

namespace previs {

enum class Mode {
    Preview,  // live: every camera frame composited with its own pose, few samples
    Refine,   // frozen frame, pose and lighting; samples accumulate
};
const char* toString(Mode mode);
std::optional<Mode> parseMode(std::string_view name);  // "preview" | "refine"

class ModeMachine {
public:
    explicit ModeMachine(Mode initial = Mode::Preview) : mode_(initial) {}

    Mode mode() const;
    // Every change so far (a toggle and its undo are two).
    uint64_t version() const;
    // `source` names who asked, for the log ("button", "ctl", "session").
    Mode toggle(std::string_view source);
    Mode set(Mode mode, std::string_view source);

private:
    mutable std::mutex mutex_;
    Mode mode_;
    uint64_t version_ = 0;
};

}  // namespace previs
