#pragma once

// `previs replay` (DESIGN.md §3): the service pipeline over a recorded session in lock step —
// every scene-camera frame is tracked (at the service's pace), lit by the fisheye frames
// recorded before it, stepped by the service's own shot controller (shot/shot_controller.h) on
// the session's clock, and written; nothing is dropped because a stage was slow. Same session
// and config ⇒ the same pixels: frames are written without the (timing-dependent) status
// overlay, and every step is sized by recorded time, not by this machine's speed.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "base/result.h"
#include "shot/mode_machine.h"
#include "shot/shot_controller.h"

namespace previs {

class GpuContext;
class LightingStage;
class PipelineRenderer;
class RecordedReader;
class TrackingStage;
struct Frame;
struct LiveLighting;
struct ServiceConfig;
struct SessionEvent;

struct ReplayOptions {
    std::string sessionDir;
    std::string configPath;  // "" = the session's own config.toml
    std::string outDir = "replay";
    // Fixed mode for the whole session (its button events are then ignored); nullopt = start in
    // preview and follow the recorded button and ctl events.
    std::optional<Mode> mode;
    bool exr = false;  // also write frame_NNNNNN.exr (linear composite)
    bool quiet = false;
};

// 0 on success, 1 on a runtime failure, 2 on a bad session, config or option (one line logged).
int runReplay(const ReplayOptions& options);

// The loop behind runReplay, one scene frame per next(): `previs replay` writes what it shows,
// `previs bench --only shot` measures it.
class SessionReplay {
public:
    // A failure to open: its exit code (2: the session, config or scene is bad; 1: the machine).
    struct OpenError {
        Error error;
        int exitCode = 2;
    };
    static std::variant<std::unique_ptr<SessionReplay>, OpenError> open(
        const std::string& sessionDir, const ServiceConfig& config, std::optional<Mode> mode);
    ~SessionReplay();

    struct Step {
        std::shared_ptr<Frame> frame;  // the scene camera's frame this step consumed
        ShotStep shot;
    };
    // The next scene frame through tracking, lighting and the shot; nullopt after the last.
    Result<std::optional<Step>> next();

    PipelineRenderer& renderer() { return *renderer_; }
    const ShotController& shot() const { return *shot_; }
    // The lighting snapshot in effect (null before the first).
    const std::shared_ptr<const LiveLighting>& lighting() const { return currentLighting_; }
    // Events of sources this previs does not know, skipped.
    size_t unknownEvents() const { return unknownEvents_; }

private:
    SessionReplay() = default;
    Status lightUpTo(uint64_t timestampNs);

    std::unique_ptr<GpuContext> gpu_;
    std::unique_ptr<PipelineRenderer> renderer_;
    std::unique_ptr<TrackingStage> tracking_;
    std::unique_ptr<LightingStage> lighting_;
    std::unique_ptr<RecordedReader> sceneReader_, fisheyeReader_;
    std::vector<SessionEvent> events_;
    size_t nextEvent_ = 0, unknownEvents_ = 0;
    std::optional<Mode> fixedMode_;
    uint64_t sceneSequence_ = 0, fisheyeSequence_ = 0;
    std::shared_ptr<Frame> pendingFisheye_;
    std::shared_ptr<const LiveLighting> currentLighting_;
    std::unique_ptr<ModeMachine> modes_;
    ManualShotClock clock_;
    std::unique_ptr<ShotController> shot_;
    TrackingPace pace_;
};

}  // namespace previs
