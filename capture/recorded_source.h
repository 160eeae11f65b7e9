#pragma once

// The recorded twin of a camera (DESIGN.md §1, §5): frames from a session folder's
// cameras/<name>/ (docs/session-format.md), behind the same FrameReader/CameraSource interfaces
// as a live device, in the spirit of libcamera's "virtual" pipeline handler.

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/result.h"
#include "capture/camera_source.h"
#include "io/session.h"

namespace previs {

// One recorded frame, decoded (its file read without following a link, its size checked first);
// an error names the file when it is missing, unreadable or not the indexed size.
Result<Frame> readRecordedFrame(const RecordedFrameEntry& entry);

// The longest pause a Recorded replay keeps between two frames: a longer recorded gap (a camera
// that was off for a while, or a broken clock: timestamps years apart) is replayed as this, with
// a warning, instead of a box that waits for years.
inline constexpr std::chrono::seconds kMaxReplayGap{2};

enum class ReplayTiming {
    Recorded,          // frames at their recorded intervals (gaps capped at kMaxReplayGap)
    AsFastAsPossible,  // deterministic CI runs, offline rendering
};

class RecordedReader : public FrameReader {
public:
    static Result<std::unique_ptr<RecordedReader>> create(const std::string& cameraDir,
                                                          ReplayTiming timing);

    Status start() override;
    Result<bool> read(int timeoutMs, Frame& frame) override;
    bool finished() const override { return next_ >= entries_.size(); }
    bool isLive() const override { return false; }
    uint64_t badFrames() const override { return badFrames_; }

private:
    RecordedReader(std::vector<RecordedFrameEntry> entries, ReplayTiming timing);

    std::vector<RecordedFrameEntry> entries_;
    // When each frame is due, from start(): the recorded intervals, each capped at kMaxReplayGap.
    std::vector<std::chrono::nanoseconds> due_;
    ReplayTiming timing_;
    size_t next_ = 0;
    std::chrono::steady_clock::time_point startTime_;
    uint64_t badFrames_ = 0;
};

// A CameraSource replaying cameras/<name>/ of a session on its own thread.
std::unique_ptr<CameraSource> makeRecordedSource(const std::string& cameraDir, ReplayTiming timing,
                                                 CaptureOptions options);

}  // namespace previs
