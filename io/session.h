#pragma once

// The recorded session (DESIGN.md §5, docs/session-format.md v3): the one owner of the format.
// Readers for every file a session folder holds (capture/recorded_source.h replays the camera
// frames it lists), and the crash-safe writer the take recorder and the demo generator use.

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/result.h"
#include "base/unique_fd.h"

namespace previs {

// docs/session-format.md: the newest version this previs reads and the one it writes.
constexpr int kSessionFormatVersion = 3;

// The largest file a session may name (a frame, a lighting map): checked before decoding, since a
// take that left the box is untrusted input.
constexpr uint64_t kMaxSessionFileBytes = uint64_t(256) << 20;
// The largest index a session may hold (a camera's index.csv, poses.csv, events.csv,
// lighting/index.csv), checked before it is read: a camera index of 64 MiB lists some 700 000
// frames (over 6 h at 30 fps), while a sparse or endless file costs nothing.
constexpr uint64_t kMaxSessionIndexBytes = uint64_t(64) << 20;
// session.toml: a few lines.
constexpr uint64_t kMaxSessionTomlBytes = uint64_t(1) << 20;

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
    std::string configDirInTake;         // config_dir as session.toml gives it ("" without one)
    std::vector<SessionCamera> cameras;  // sorted by name

    // The camera with this role, or nullptr.
    const SessionCamera* cameraWithRole(const std::string& role) const;
};

// Reads session.toml, checks format and version, and lists the cameras present (folders
// under cameras/ with an index.csv, each index parsed). The folder is untrusted whatever
// version it declares: a config_dir outside it, or a camera folder that is a symbolic link, is
// refused. Nothing is written or removed (a reader ignores *.tmp files).
Result<SessionInfo> openSession(const std::string& dir);

// A path a session names (a frame file, a copied config file, `config_dir`): relative, without
// "..", resolving inside `root` through no symbolic link, to an existing regular file of at most
// kMaxSessionFileBytes (or folder when `folder`). Returns the path under `root`, or one line
// naming `what` and the path.
Result<std::string> containedPath(const std::string& root, const std::string& relative,
                                  const std::string& what, bool folder = false);

// fsync()s a folder, so the entries (new files, renames) in it survive a power cut.
Status syncFolder(const std::string& dir);

// Reads a regular file of at most kMaxSessionFileBytes without following a symbolic link
// (base/bounded_file.h: a FIFO or a device is refused, never waited on).
Result<std::vector<uint8_t>> readSessionFile(const std::string& path);

// One line of cameras/<name>/index.csv.
struct RecordedFrameEntry {
    uint64_t sequence = 0;
    uint64_t timestampNs = 0;
    std::string file;  // absolute path
    uint32_t width = 0;
    uint32_t height = 0;
    // v3: CLOCK_REALTIME at capture, and the frame's timecode label ("HH:MM:SS:FF"); absent in
    // older sessions.
    std::optional<uint64_t> wallClockNs;
    std::string timecode;
    // The rate the label counts at as the recorder wrote it ("30", "29.97df": TimecodeRate's
    // names), empty in takes from before the column (then timecode/timecode.h's labelRate rule).
    std::string timecodeRate;
    // v3: the frame's exposure in stops relative to the camera's radiometry (0 = as calibrated,
    // −4 = a sixteenth of the light), when the camera brackets; absent otherwise.
    std::optional<float> exposureStops;
};

// Parses cameras/<name>/index.csv of a session; a truncated last line (a crash mid-append) is
// ignored, a malformed complete line — a bad field, a path out of the folder, a sequence or
// timestamp going back — is an error naming file and line, or with `skipped`
// (a final render: the rest still renders) reported there and left out.
Result<std::vector<RecordedFrameEntry>> loadCameraIndex(
    const std::string& cameraDir, std::vector<std::string>* skipped = nullptr);

// One lighting snapshot the renderer used: lighting/index.csv.
struct LightingRecord {
    uint64_t timestampNs = 0;  // the fisheye frame it was made from
    std::string mapFile;       // absolute path of lighting/<n>.exr
    std::string lightsJson;    // the estimated lights (`previs lights` JSON), "" for none
};
Result<std::vector<LightingRecord>> loadLighting(const std::string& dir);

// Tracked: the tracker's pose on that frame; Filtered: the live pose filter's (what the preview
// composited); Lost: no pose on that frame; Truth: the ground truth, where known.
enum class PoseKind { Tracked, Lost, Truth, Filtered };

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
    // the folder its relative paths start at: a folder inside the session, relative to it
    // (readers refuse anything else, docs/session-format.md).
    std::string configToml;
    std::string configDir;
    std::string created;        // RFC 3339; empty: now (UTC)
    std::string previsVersion;  // empty: this build's
    // The index files are fdatasync'ed at least this often (and on flush()): a power cut loses
    // at most this much of the take.
    std::chrono::milliseconds flushInterval{1000};
};

// What a camera index line says of a frame besides its monotonic timestamp (v2 and v3 columns).
struct FrameStamp {
    std::optional<uint64_t> wallClockNs;  // CLOCK_REALTIME
    std::string timecode;                 // "HH:MM:SS:FF", the frame's label
    std::optional<float> exposureStops;   // a bracketing camera's exposure (RecordedFrameEntry)
    std::string timecodeRate;             // the label's rate, "30", "29.97df"
};

// Appends a session folder in the crash-safe write order of docs/session-format.md: a frame
// file is complete (tmp + fdatasync + rename) before its index line is appended with a single
// write(); a flush (at least every flushInterval, and on flush()) fsyncs the folders that gained
// entries before the index files, so no durable line names a file that is not.
class SessionWriter {
public:
    // Creates `dir` (its parent must exist) and writes session.toml and config.toml. Refuses a
    // folder that already holds a session.
    static Result<SessionWriter> create(const std::string& dir,
                                        const SessionWriterOptions& options = {});

    SessionWriter(SessionWriter&&) = default;
    SessionWriter& operator=(SessionWriter&&) = default;
    ~SessionWriter();

    // One frame of `camera` as its bytes: `ext` "png", "jpg" or a raw format's fourcc in lower
    // case ("yuyv": planes without line padding, capture/pixel_format.h), stored as
    // cameras/<camera>/<sequence, 12 digits>.<ext>. Sequences must increase and timestamps not
    // decrease per camera.
    Status writeFrame(const std::string& camera, uint64_t sequence, uint64_t timestampNs,
                      std::span<const uint8_t> encoded, const std::string& ext, uint32_t width,
                      uint32_t height, const FrameStamp& stamp = {});
    // A lighting snapshot: `writeMap(file)` writes the environment map as OpenEXR into `file`
    // (lighting/<n>.exr's temporary, made durable and renamed here), then its index line follows.
    Status writeLighting(uint64_t timestampNs,
                         const std::function<Status(AtomicFile& file)>& writeMap,
                         const std::string& lightsJson);
    Status writePose(const PoseRecord& pose);
    Status writeEvent(const SessionEvent& event);
    // One line (ending in a newline) of a take's own record file `relPath`, created with the
    // line `header` on first use, in the crash-safe order of the index files: e.g. freed.csv, a
    // tracker's packets as received.
    Status appendRecord(const std::string& relPath, const std::string& header,
                        const std::string& line);
    // Makes everything written so far durable (index files and folder entries).
    Status flush();
    // The writer syncs as it writes, so what came just before a quiet spell would wait for the
    // next write: its owner calls flushIfDue() when idle too, by flushDue() at the latest, so
    // nothing written waits longer than flushInterval to be durable.
    Status flushIfDue();
    // When what is written but not yet durable must be made so; none when nothing waits.
    std::optional<std::chrono::steady_clock::time_point> flushDue() const;

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
    bool unsynced() const;
    // Creates a folder under dir_ (and its missing parents), to be made durable at the next flush.
    Status createFolder(const std::string& relPath);

    std::string dir_;
    std::map<std::string, Index> indices_;
    std::set<std::string> newFolders_;  // folders (and their parents) created since the last flush
                                        // // by path relative to dir_
    std::chrono::steady_clock::time_point lastSync_;
    std::chrono::milliseconds flushInterval_{1000};
    uint64_t lightingSnapshots_ = 0;
    bool newEntries_ = false;  // folder entries (renames, new files) not yet fsync'ed
};

}  // namespace previs
