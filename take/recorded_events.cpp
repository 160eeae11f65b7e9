#include "take/recorded_events.h"

#include <algorithm>
#include <filesystem>

#include "capture/recorded_source.h"

namespace previs {

void applySessionEvent(ModeMachine& modes, const SessionEvent& e) {
    if (e.source == "session" && e.event == "restart") {
        modes.set(Mode::Preview, "session start over");
    } else if (e.source == "mode-button" && e.event == "short-press") {
        modes.toggle("session mode-button");
    } else if ((e.source == "ctl" || e.source == "take") && e.event.rfind("mode=", 0) == 0) {
        const std::string what = e.event.substr(5);
        if (what == "toggle")
            modes.toggle("session ctl");
        else if (std::optional<Mode> m = parseMode(what))
            modes.set(*m, "session ctl");
    }
}

Result<std::optional<RecordedEvents>> RecordedEvents::load(const std::string& sceneCameraDir) {
    namespace fs = std::filesystem;
    const fs::path session =
        fs::path(sceneCameraDir).lexically_normal().parent_path().parent_path();
    if (!fs::exists(session / "events.csv")) return std::optional<RecordedEvents>();
    Result<std::vector<SessionEvent>> events = loadEvents(session.string());
    if (!events) return events.error();
    Result<std::vector<RecordedFrameEntry>> frames = loadCameraIndex(sceneCameraDir);
    if (!frames) return frames.error();
    RecordedEvents out;
    for (const SessionEvent& e : *events) {
        auto at = std::lower_bound(
            frames->begin(), frames->end(), e.timestampNs,
            [](const RecordedFrameEntry& f, uint64_t t) { return f.timestampNs < t; });
        if (at == frames->end()) continue;  // after the last frame: never seen
        out.events_.push_back({at->sequence, e});
    }
    if (out.events_.empty()) return std::optional<RecordedEvents>();
    return std::optional<RecordedEvents>(std::move(out));
}

std::vector<SessionEvent> RecordedEvents::due(uint32_t sequence) {
    std::vector<SessionEvent> out;
    // Frames since the last one seen: (last, sequence], or [0, sequence] after a restart.
    const bool restarted = last_ && sequence < *last_;
    restarted_ = restarted;
    for (const Tied& t : events_) {
        const bool after = !last_ || restarted || t.frameSequence > *last_;
        if (after && t.frameSequence <= sequence) out.push_back(t.event);
    }
    last_ = sequence;
    return out;
}

}  // namespace previs
