#pragma once

// Camera sources (DESIGN.md §1, §6): one thread per camera delivering immutable frames through a
// latest-value slot, surviving the device going away and coming back (§7).

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "base/latest_value_slot.h"
#include "base/result.h"
#include "base/stage_watch.h"
#include "capture/frame.h"

namespace previs {

// The hand-over between a capture thread and its consumer (DESIGN.md §6).
using FrameSlot = LatestValueSlot<Frame>;

// A device-level frame producer, driven by one thread: a V4L2 device, a recorded session. It
// may fail at any read (a camera unplugged); the owner then destroys it and builds a new one.
class FrameReader {
public:
    virtual ~FrameReader() = default;

    virtual Status start() = 0;
    // Waits up to `timeoutMs` for the next frame. true: `frame` was filled (all fields but
    // `sequence`); false: no frame within the timeout, a frame the source withheld (a
    // bracketing camera's while its exposure control lands), or the end of a finite source (see
    // finished()); an error: the source is gone or broken and must be reopened.
    virtual Result<bool> read(int timeoutMs, Frame& frame) = 0;
    // A finite source (a recording) has delivered its last frame.
    virtual bool finished() const { return false; }
    // A live device: silence longer than CaptureOptions::stallTimeoutMs means it is dead. A
    // recording's gaps are its recorded timing, never a stall.
    virtual bool isLive() const { return true; }
    // Frames the device delivered that could not be converted (skipped, never published).
    virtual uint64_t badFrames() const { return 0; }
    // Frames a bracketing camera withheld while its exposure control landed (never published;
    // capture/exposure_bracket.h).
    virtual uint64_t withheldFrames() const { return 0; }
};

// Builds a started-or-startable reader; called again after every failure.
using FrameReaderFactory = std::function<Result<std::unique_ptr<FrameReader>>()>;

enum class CaptureState {
    Stopped,
    Opening,    // first attempt to open the device
    Streaming,  // frames flowing
    Lost,       // the device failed or is absent; reopening every retryIntervalMs
    Finished,   // a finite source ran out
};
const char* toString(CaptureState state);

struct CaptureStats {
    CaptureState state = CaptureState::Stopped;
    uint64_t delivered = 0;   // frames published to the slot
    uint64_t dropped = 0;     // published but replaced before the consumer took them
    uint64_t badFrames = 0;   // frames the source returned that could not be converted
    uint64_t withheld = 0;    // frames a bracketing camera withheld while its exposure landed
    uint64_t reconnects = 0;  // times streaming resumed after the device was lost
    std::string problem;      // while lost: why ("no such device", a control that did not apply)
};

// What consumers see of a camera, live or recorded.
class CameraSource {
public:
    virtual ~CameraSource() = default;

    // Begins delivering frames. Succeeds even while the device is absent (the source keeps
    // trying); fails only when the source cannot run at all.
    virtual Status start() = 0;
    // Stops and joins; frames already published stay readable in frames().
    virtual void stop() = 0;
    virtual FrameSlot& frames() = 0;
    virtual CaptureStats stats() const = 0;
    virtual const std::string& name() const = 0;
};

struct CaptureOptions {
    // For log lines, e.g. "scene camera /dev/video0".
    std::string name = "camera";
    // Poll granularity: bounds how long stop() waits for the thread.
    int readTimeoutMs = 100;
    // How often a lost device is reopened; short enough that a replugged camera is back within
    // a blink, long enough not to spin on a device that is gone for good.
    int retryIntervalMs = 250;
    // No frame for this long while streaming counts as lost (a camera that delivers nothing):
    // several frame periods at the slowest useful rate, plus slack for a loaded machine.
    int stallTimeoutMs = 3000;
    // Called on the capture thread with every frame before it is published (the take recorder's
    // tap: it must return at once, e.g. by queueing). Unset: none.
    std::function<void(const std::shared_ptr<const Frame>&)> onFrame;
    // The service's watch over this thread (base/stage_watch.h): a read or an open that does not
    // return is a hang. Null: not watched.
    Stage* stage = nullptr;
};

// A CameraSource running a FrameReader on its own thread.
class CaptureThread : public CameraSource {
public:
    CaptureThread(FrameReaderFactory factory, CaptureOptions options);
    ~CaptureThread() override;
    CaptureThread(const CaptureThread&) = delete;
    CaptureThread& operator=(const CaptureThread&) = delete;

    Status start() override;
    void stop() override;
    FrameSlot& frames() override { return slot_; }
    CaptureStats stats() const override;
    const std::string& name() const override { return options_.name; }

    CaptureState state() const { return state_.load(); }

private:
    void run();
    void setState(CaptureState state, const std::string& detail);
    // Sleeps up to `ms`, returning early (true) when stop() was requested.
    bool waitForStop(int ms);

    const FrameReaderFactory factory_;
    const CaptureOptions options_;
    FrameSlot slot_;

    std::atomic<CaptureState> state_{CaptureState::Stopped};
    std::atomic<uint64_t> delivered_{0};
    std::atomic<uint64_t> reconnects_{0};
    std::atomic<uint64_t> badFrames_{0};
    std::atomic<uint64_t> withheld_{0};
    mutable std::mutex problemMutex_;
    std::string problem_;  // CaptureStats::problem, under problemMutex_

    std::mutex stopMutex_;
    std::condition_variable stopCv_;
    bool stopRequested_ = false;
    std::thread thread_;
};

}  // namespace previs
