#pragma once

// The take recorder (DESIGN.md §3 "Recording", §5, §6; issue 36): while a take rolls, every
// scene and fisheye frame as captured, the tracked poses, the lighting snapshots and the
// button/ctl events go through one bounded queue to a writer thread that appends them to a
// session folder in its crash-safe order (io/session.h). Capture, tracking and lighting only
// queue (never wait on the disk); a frame the queue cannot take is counted and logged.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <variant>

#include "base/result.h"
#include "capture/frame.h"
#include "config/service_config.h"
#include "io/session.h"
#include "render/plate_consistency.h"
#include "shot/pipeline_stages.h"
#include "timecode/timecode_source.h"

namespace previs {

// What `status --json` reports as "record" (DESIGN.md §3).
struct RecordStatus {
    bool recording = false;
    std::string path;      // the take's folder (the last take's after it stopped)
    uint64_t frames = 0;   // scene-camera frames written
    uint64_t dropped = 0;  // frames the recorder could not take (queue full)
    // FreeD packets left out of freed.csv: beyond kFreedRecordHz or FreeD's share of the queue.
    uint64_t freedDropped = 0;
    uint64_t bytes = 0;  // bytes written to the take
    uint64_t freeBytes = 0;
    double seconds = 0.0;  // how long the take has rolled (wall time since its start)
    // Set when the take stopped by itself (a full disk, a write error); cleared by the next start.
    std::string stoppedBecause;
};

class TakeRecorder {
public:
    explicit TakeRecorder(ServiceConfig config);
    ~TakeRecorder();
    TakeRecorder(const TakeRecorder&) = delete;
    TakeRecorder& operator=(const TakeRecorder&) = delete;

    // Start and stop are one state machine that any thread may drive at once (the page, the
    // control socket, the button, SIGTERM): idle → starting → rolling → stopping → idle.
    //
    // Creates the take's folder under [record] dir — `YYYY-MM-DD_HHMMSS[_NAME]`, NAME letters,
    // digits, '-' and '_' — copies in what the config names (take/take_files.h), and starts
    // the writer. `lighting`: the snapshot in effect, so the take is lit from its first frame.
    // Refuses (one line) while a take starts, rolls or stops, when the folder cannot be written
    // or when its disk has less than [record] min_free_mb free.
    Result<std::string> start(const std::string& name,
                              std::shared_ptr<const LiveLighting> lighting = nullptr);
    // Writes what is queued, makes it durable and ends the take; returns its folder. A stop
    // while the take starts waits for the start, then stops it; a stop while another stops
    // waits for that one and answers its outcome.
    Result<std::string> stop();
    bool recording() const;
    RecordStatus status() const;
    // Set while a take rolls: the cameras then keep each frame's bytes as captured
    // (CaptureOptions::keepCaptured), and cost nothing for it otherwise.
    const std::atomic<bool>* keepCapturedFlag() const { return &keepCaptured_; }

    // Producers (any thread; each returns at once, and does nothing when not recording).
    void addFrame(const std::string& camera, std::shared_ptr<const Frame> frame);
    void addPose(const TrackedFrame& tracked);
    // An event without a timestamp gets the last scene frame's (+1 ns): a replay fires it
    // after that frame, on the same clock as the frames.
    void addEvent(SessionEvent event);
    // A tracker's valid FreeD packet as received ([tracking] listen; shot/freed_input.h passes
    // only the configured camera's): the take's freed.csv. At most kFreedRecordHz (bursts of
    // kFreedBurst) and 1/kFreedQueueShare of [record] queue_mb; the rest counted in freedDropped.
    void addFreedPacket(int64_t receivedNs, std::span<const uint8_t> datagram);
    // Far above any tracker's rate (FreeD runs at the video rate, 240 Hz at most).
    static constexpr int kFreedRecordHz = 1000;
    static constexpr int kFreedBurst = 250;
    static constexpr uint64_t kFreedQueueShare = 32;
    void addLighting(std::shared_ptr<const LiveLighting> lighting);
    // A plate-consistency reading (render/plate_consistency.h): the take's plate_consistency.csv.
    void addPlateConsistency(const PlateConsistencyReading& reading);
    // Where the scene camera's frames get their timecode ([timecode], docs/timecode.md); set
    // before the cameras start, outliving the recorder. None: the time of day.
    void setTimecodeSource(TimecodeSource* source) { timecodeSource_ = source; }

private:
    struct FreedPacket {
        int64_t receivedNs = 0;
        std::vector<uint8_t> bytes;
    };
    struct FrameItem {
        std::string camera;
        std::shared_ptr<const Frame> frame;
        // The scene camera's timecode from the service's source (LTC or the clock), taken as
        // the frame arrives, and the rate it counts at ("30", "29.97df"); empty: the time of day
        // at the camera's rate.
        std::string timecode;
        std::string timecodeRate;
    };
    using Item =
        std::variant<FrameItem, PoseRecord, SessionEvent, std::shared_ptr<const LiveLighting>,
                     FreedPacket, PlateConsistencyReading>;

    // A token bucket on the packets' receipt times: kFreedRecordHz, kFreedBurst deep.
    struct FreedRate {
        double tokens = kFreedBurst;
        int64_t lastNs = 0;
        bool take(int64_t nowNs);
    };

    struct Take;  // the writer's state, owned by its thread
    // start()'s work once it owns the starting phase: the folder, the files, the writer.
    Result<std::string> openTake(const std::string& name,
                                 std::shared_ptr<const LiveLighting> lighting);
    // Each camera's label rule under config_, and its rate where the config decides it.
    Status setLabelRules(Take& take) const;
    void runWriter(std::unique_ptr<Take> take);
    Status write(Take& take, Item& item);
    Status writeFrame(Take& take, const FrameItem& item);
    void push(Item item, size_t bytes);
    void finishWriter();

    const ServiceConfig config_;
    const uint64_t queueLimitBytes_;

    mutable std::mutex mutex_;
    std::condition_variable wake_;
    std::deque<std::pair<Item, size_t>> queue_;
    size_t queuedBytes_ = 0;
    size_t freedQueuedBytes_ = 0;  // FreeD's part of queuedBytes_
    FreedRate freedRate_;
    bool accepting_ = false;  // a take rolls and takes items
    bool draining_ = false;   // stop(): write what is queued, then end
    RecordStatus status_;
    std::chrono::steady_clock::time_point rollingSince_{};  // the take's start (status.seconds)
    // Who may touch writer_: only the thread that moved the phase to Starting or Stopping
    // (under mutex_), so the writer is started once and joined once.
    enum class Phase { Idle, Starting, Rolling, Stopping };
    Phase phase_ = Phase::Idle;
    std::condition_variable phaseChanged_;
    uint64_t stopsFinished_ = 0;  // a stop that waited for another answers with its folder
    std::string lastStopped_;
    std::atomic<uint64_t> lastSceneNs_{0};
    std::atomic<bool> keepCaptured_{false};
    TimecodeSource* timecodeSource_ = nullptr;
    std::thread writer_;
};

}  // namespace previs
