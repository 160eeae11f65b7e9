#include "shot/mode_machine.h"

#include "base/log.h"

namespace previs {

const char* toString(Mode mode) { return mode == Mode::Preview ? "preview" : "refine"; }

std::optional<Mode> parseMode(std::string_view name) {
    if (name == "preview") return Mode::Preview;
    if (name == "refine") return Mode::Refine;
    return std::nullopt;
}

Mode ModeMachine::mode() const {
    std::lock_guard lock(mutex_);
    return mode_;
}

uint64_t ModeMachine::version() const {
    std::lock_guard lock(mutex_);
    return version_;
}

Mode ModeMachine::toggle(std::string_view source) {
    std::lock_guard lock(mutex_);
    const Mode from = mode_;
    mode_ = mode_ == Mode::Preview ? Mode::Refine : Mode::Preview;
    ++version_;
    logInfo("mode: {} -> {} ({})", toString(from), toString(mode_), source);
    return mode_;
}

Mode ModeMachine::set(Mode mode, std::string_view source) {
    std::lock_guard lock(mutex_);
    if (mode_ != mode) {
        logInfo("mode: {} -> {} ({})", toString(mode_), toString(mode), source);
        mode_ = mode;
        ++version_;
    }
    return mode_;
}

}  // namespace previs
