#pragma once

// The tracked camera on the set's network (issue 39): for each tracked frame one FreeD D1 packet
// ([freed], docs/freed.md) and one SMPTE RIS OpenTrackIO sample ([opentrackio],
// docs/opentrackio.md), sent from the tracking thread as soon as the pose exists. Sending never
// blocks: a full socket buffer drops the datagram (counted). The pose sent is the one tracked on
// that very frame, stamped with its capture time (issue 54): a receiver composites its own render
// against that frame, and the live pose filter ([tracking] pose_filter) lags a moving camera, so
// it stays the box's display's own.

#include <atomic>
#include <memory>
#include <optional>
#include <vector>

#include "base/result.h"
#include "config/network_config.h"
#include "net/lens_sample.h"
#include "net/opentrackio.h"
#include "net/udp_socket.h"
#include "shot/pipeline_stages.h"
#include "systemd/listen_fds.h"
#include "timecode/frame_rate.h"
#include "timecode/timecode.h"

namespace previs {

struct CameraConfig;

struct TrackingOutStats {
    bool freed = false, openTrackIo = false;  // configured
    // Packets handed to the kernel; `held` of them repeat the last pose while tracking is lost
    // ([freed] when_lost = "hold"); `clamped`: a position beyond FreeD's ±131 m.
    uint64_t freedPackets = 0, freedHeld = 0, freedClamped = 0;
    uint64_t openTrackIoSamples = 0, openTrackIoDatagrams = 0;
    // Datagrams the kernel refused: a full send buffer (dropped) or an error such as nobody
    // listening on a unicast port yet (failed).
    uint64_t dropped = 0, failed = 0;
    uint64_t lostNotSent = 0;  // frames without a trusted pose: nothing sent
    // From the frame's capture to its packets handed to the kernel, milliseconds: the last and
    // the largest so far.
    double lastDelayMs = 0.0, maxDelayMs = 0.0;
};

class TrackingOut {
public:
    // Opens the configured senders (none configured: nullptr, nothing to do per frame). A bad
    // address or an unresolvable host is an error naming the key.
    // `passed`: the sockets systemd made for the unit ("freed", "opentrackio"), sent from
    // when present (docs/systemd.md); else previsd opens its own.
    static Result<std::unique_ptr<TrackingOut>> create(const NetworkConfig& network,
                                                       const CameraConfig& sceneCamera,
                                                       systemd::ListenFds& passed);

    // The tracking thread, once per tracked frame.
    void send(const TrackedFrame& frame, const std::optional<Timecode>& timecode, bool recording);
    TrackingOutStats stats() const;

private:
    TrackingOut(const NetworkConfig& network, LensSample lens, std::optional<FrameRate> rate);
    void sendFreed(const cv::Matx44d& worldFromCamera, bool held);
    void sendOpenTrackIo(const TrackedFrame& frame, const cv::Matx44d& worldFromCamera,
                         const std::optional<Timecode>& timecode, bool recording, bool held);
    void countSend(UdpSocket::SendStatus status);

    FreedOutConfig freedConfig_;
    LensSample lens_;
    // OpenTrackIO's sampleRate: the scene camera's configured fps, else measured on the frames.
    std::optional<FrameRate> configuredRate_;
    FrameRateMeter measuredRate_;
    std::optional<UdpSocket> freed_, openTrackIo_;
    std::optional<OpenTrackIOEncoder> encoder_;
    std::optional<cv::Matx44d> lastTrusted_;  // the tracking thread's
    std::atomic<uint64_t> freedPackets_{0}, freedHeld_{0}, freedClamped_{0};
    std::atomic<uint64_t> samples_{0}, datagrams_{0}, dropped_{0}, failed_{0}, lostNotSent_{0};
    std::atomic<double> lastDelayMs_{0.0}, maxDelayMs_{0.0};
};

// The lens the protocols describe, from the scene camera's calibration.
LensSample lensSample(const CameraConfig& camera);

}  // namespace previs
