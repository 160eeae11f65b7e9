#pragma once

// The recorded session (DESIGN.md §5, docs/session-format.md v2): a reader for what a session
// folder holds besides the camera frames (capture/recorded_source.h replays those), and the
// crash-safe writer the recorder and the demo generator use.

#include <array>
#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/result.h"
#include "capture/unique_fd.h"

namespace previs {

// docs/session-format.md: the newest version this previs reads and the one it writes.
constexpr int kSessionFormatVersion = 2;

struct SessionCamera {
    std::string name;   // the folder under cameras/
    std::string role;   // "scene", "fisheye" or empty (not named in session.toml)
    std::string dir;    // SESSION/cameras/<name>
    size_t frames = 0;  // complete lines of its index.csv
};

struct SessionInfo {
    std::string dir;
    int version = 0;
    std::string created;        // RFC 3339
    std::string clock;          // "CLOCK_MONOTONIC"
    std::string previsVersion;  // of the recorder
    // The service config in effect (config.toml, empty when the session has none) and the
    // folder its relative paths are resolved against (docs/session-format.md, config.toml).
    std::string configPath;
    std::string configDir;
    std::vector<SessionCamera> cameras;  // sorted by name

    // The camera with this role, or nullptr.
    const SessionCamera* cameraWithRole(const std::string& role) const;
};

// Reads session.toml, checks format and version, and lists the cameras present (folders
// under cameras/ with an index.csv, each index parsed).
Result<SessionInfo> openSession(const std::string& dir);

enum class PoseKind { Tracked, Lost, Truth };

const char* poseKindName(PoseKind kind);

struct PoseRecord {
    uint64_t timestampNs = 0;
    // The scene camera's frame sequence the pose belongs to (v1 files have none).
    std::optional<uint64_t> frame;
    PoseKind kind = PoseKind::Tracked;
    // worldFromCamera, row-major, OpenCV camera axes (x right, y down, z forward), metres;
    // absent for a lost frame.
    std::optional<std::array<double, 16>> worldFromCamera;
    std::optional<double> reprojErrorPx;  // tracked poses only
    int tags = 0;
};

// poses.csv (an empty list when the session has none).
Result<std::vector<PoseRecord>> loadPoses(const std::string& dir);

struct SessionEvent {
    uint64_t timestampNs = 0;
    std::string source;  // "mode-button", "ctl"
    std::string event;   // "short-press", "long-press"; "mode=preview|refine|toggle"
};

// events.csv (an empty list when the session has none). Events of a source or kind this
// previs does not know are skipped; `skippedUnknown` (if given) receives their count.
Result<std::vector<SessionEvent>> loadEvents(const std::string& dir,
                                             size_t* skippedUnknown = nullptr);

struct SessionWriterOptions {
    // Camera name → role ("scene", "fisheye"), written to session.toml. Frames may also go to
    // cameras not listed here (they get no role).
    std::map<std::string, std::string> cameraRoles;
    // The service config in effect, copied to config.toml as is (empty: no config.toml), and
    // the folder its relative paths start at: absolute, or relative to the session folder.
    std::string configToml;
    std::string configDir;
    std::string created;        // RFC 3339; empty: now (UTC)
    std::string previsVersion;  // empty: this build's
};

// Appends a session folder in the crash-safe write order of docs/session-format.md: a frame
// file is complete (tmp + fdatasync + rename) before its index line is appended with a single
// write(), and the index files are fdatasync'ed at least once a second and on flush().
class SessionWriter {
public:
    // Creates `dir` (its parent must exist) and writes session.toml and config.toml. Refuses a
    // folder that already holds a session.
    static Result<SessionWriter> create(const std::string& dir,
                                        const SessionWriterOptions& options = {});

    SessionWriter(SessionWriter&&) = default;
    SessionWriter& operator=(SessionWriter&&) = default;
    ~SessionWriter();

    // One frame of `camera` as encoded bytes (`ext` "png" or "jpg"), stored as
    // cameras/<camera>/<sequence, 12 digits>.<ext>. Sequences must increase and timestamps not
    // decrease per camera.
    Status writeFrame(const std::string& camera, uint64_t sequence, uint64_t timestampNs,
                      std::span<const uint8_t> encoded, const std::string& ext, uint32_t width,
                      uint32_t height);
    Status writePose(const PoseRecord& pose);
    Status writeEvent(const SessionEvent& event);
    // Makes everything written so far durable (index files and folder entries).
    Status flush();

    const std::string& dir() const { return dir_; }

private:
    struct Index {
        UniqueFD fd;
        std::string path;
        bool dirty = false;
        // Per camera: what the next line must exceed (docs/session-format.md).
        std::optional<uint64_t> lastSequence;
        uint64_t lastTimestampNs = 0;
    };

    SessionWriter() = default;
    Result<Index*> openIndex(const std::string& relPath, const std::string& header);
    Status appendLine(Index& index, const std::string& line);
    Status syncIfDue();

    std::string dir_;
    std::map<std::string, Index> indices_;  // by path relative to dir_
    std::chrono::steady_clock::time_point lastSync_;
    bool newEntries_ = false;  // folder entries (renames, new files) not yet fsync'ed
};

}  // namespace previs
