#pragma once

// FreeD in (issue 39, docs/freed.md "FreeD in"): a tracker's or PTZ head's packets, received on
// [tracking] listen, give the camera pose instead of the tags when [tracking] source = "freed".
// Each packet is stamped with CLOCK_MONOTONIC at receipt (the cameras' clock), kept for a few
// seconds, and recorded into a rolling take (freed.csv: the configured camera's valid packets as
// received, within the recorder's budget, take/take_recorder.h), so a take with the board in
// view calibrates the tracker (`previs freed-calibrate`) and a take with the tracker replays.
// A frame's pose is the packet series read at the frame's capture time plus the calibrated delay,
// mapped through the calibration's mount offset and world (net/freed_calibration.h).

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "base/result.h"
#include "base/unique_fd.h"
#include "net/freed.h"
#include "net/freed_calibration.h"
#include "net/udp_socket.h"

namespace previs {

struct TrackingConfig;

struct FreedInputStats {
    uint64_t packets = 0;  // accepted
    // Refused, by net/freed.h FreedError (index; 0 unused): wrong size, type, checksum, camera.
    std::array<uint64_t, 5> rejected{};
    bool calibrated = false;
};

class FreedInput {
public:
    // Each valid packet of the configured camera, as received (a refused datagram is counted in
    // stats(), never passed on).
    using PacketSink = std::function<void(int64_t receivedNs, std::span<const uint8_t> datagram)>;

    // Live: receives on [tracking] listen, or on `passed` (systemd's socket, docs/systemd.md),
    // on its own thread.
    static Result<std::unique_ptr<FreedInput>> listen(const TrackingConfig& tracking,
                                                      UniqueFD passed, PacketSink record);
    // Recorded: a take's freed.csv (replay, or a session camera played live).
    static Result<std::unique_ptr<FreedInput>> recorded(const std::string& csvPath,
                                                        const TrackingConfig& tracking);
    ~FreedInput() { stop(); }
    // Ends the receiving thread (and its calls into the take); the series stays readable.
    void stop();
    FreedInput(const FreedInput&) = delete;
    FreedInput& operator=(const FreedInput&) = delete;

    // The camera's worldFromCamera for the frame captured at `frameNs`: live, waits at most
    // `wait` for the packet of that instant (frame time + delay) to arrive. None when no packet
    // lies within kFreedMaxGapNs on both sides of it (net/freed_calibration.h).
    std::optional<cv::Matx44d> worldFromCamera(int64_t frameNs, std::chrono::milliseconds wait);
    FreedInputStats stats() const;
    bool live() const { return socket_.has_value(); }

private:
    FreedInput(const TrackingConfig& tracking, PacketSink record);
    void run();
    void add(int64_t receivedNs, const FreedParse& parse);

    std::optional<uint8_t> cameraId_;
    FreedCalibration calibration_;  // identity and no delay when none is configured
    PacketSink record_;
    std::optional<UdpSocket> socket_;
    mutable std::mutex mutex_;
    std::condition_variable arrived_;
    std::vector<TimedPose> series_;  // stageFromBody by receipt time, the last few seconds
    FreedInputStats stats_;
    std::atomic<bool> stop_{false};
    std::thread thread_;  // last: started once everything above is set
};

}  // namespace previs
