#include "daemon/tracking_out.h"

#include <chrono>
#include <cmath>

#include "base/log.h"
#include "base/monotonic_clock.h"
#include "net/freed.h"

namespace previs {
namespace {

void storeMax(std::atomic<double>& max, double value) {
    double seen = max.load();
    while (value > seen && !max.compare_exchange_weak(seen, value)) {
    }
}

OtrkTimecode otrkTimecode(const Timecode& t) {
    OtrkTimecode out;
    out.hours = t.hours();
    out.minutes = t.minutes();
    out.seconds = t.seconds();
    out.frames = t.frames();
    out.rateNum = uint32_t(t.rate().num());
    out.rateDenom = uint32_t(t.rate().den());
    out.dropFrame = t.dropFrame();
    return out;
}

}  // namespace

LensSample lensSample(const CameraConfig& camera) {
    LensSample lens;
    if (!camera.calibration) return lens;
    const CameraCalibration& c = *camera.calibration;
    lens.fxPx = c.fx();
    lens.fyPx = c.fy();
    lens.cxPx = c.cx();
    lens.cyPx = c.cy();
    lens.widthPx = c.imageSize().width;
    lens.heightPx = c.imageSize().height;
    lens.distortion = c.distortion();
    lens.fisheye = c.model() == DistortionModel::Fisheye;
    return lens;
}

Result<std::unique_ptr<TrackingOut>> TrackingOut::create(const NetworkConfig& network,
                                                         const CameraConfig& sceneCamera,
                                                         systemd::ListenFds& passed) {
    if (network.freed.out.empty() && network.opentrackio.out.empty())
        return std::unique_ptr<TrackingOut>();
    std::optional<FrameRate> rate;
    if (sceneCamera.fps > 0.0) rate = snapFrameRate(sceneCamera.fps);
    std::unique_ptr<TrackingOut> out(new TrackingOut(network, lensSample(sceneCamera), rate));
    if (!network.freed.out.empty()) {
        Result<UdpSocket> socket = UdpSocket::sender(network.freed.out, passed.take("freed"));
        if (!socket)
            return makeError("[freed] out = '{}': {}", network.freed.out, socket.message());
        out->freed_.emplace(std::move(*socket));
    }
    const OpenTrackIoConfig& otio = network.opentrackio;
    if (!otio.out.empty()) {
        const uint8_t source = uint8_t(otio.sourceNumber);
        Result<UdpSocket> socket =
            otio.out == "multicast"
                ? UdpSocket::multicastSender(openTrackIOMulticastGroup(source), kOpenTrackIOPort,
                                             otio.multicastTtl, "", passed.take("opentrackio"))
                : UdpSocket::sender(otio.out, passed.take("opentrackio"));
        if (!socket) return makeError("[opentrackio] out = '{}': {}", otio.out, socket.message());
        out->openTrackIo_.emplace(std::move(*socket));
        OpenTrackIOSource who;
        who.sourceNumber = source;
        Result<OpenTrackIOEncoder> encoder = OpenTrackIOEncoder::create(who);
        if (!encoder) return makeError("[opentrackio]: {}", encoder.message());
        out->encoder_.emplace(std::move(*encoder));
    }
    return out;
}

TrackingOut::TrackingOut(const NetworkConfig& network, LensSample lens,
                         std::optional<FrameRate> rate)
    : freedConfig_(network.freed), lens_(std::move(lens)), configuredRate_(rate) {}

void TrackingOut::send(const TrackedFrame& frame, const std::optional<Timecode>& timecode,
                       bool recording) {
    if (frame.frame) measuredRate_.add(int64_t(frame.frame->timestampNs), frame.frame->sequence);
    // The pose of this very frame, not the display's filter (which lags a moving camera).
    const std::optional<cv::Matx44d>& own =
        frame.trackedWorldFromCamera ? frame.trackedWorldFromCamera : frame.worldFromCamera;
    if (!frame.lost && own) lastTrusted_ = own;
    const bool held = frame.lost && freedConfig_.holdWhenLost && lastTrusted_;
    // A lost frame's worldFromCamera is the last good one: never sent as if it were current.
    if (frame.lost && !held) {
        lostNotSent_.fetch_add(1, std::memory_order_relaxed);
        return;
    }
    if (!frame.lost && !own) return;
    const cv::Matx44d& pose = frame.lost ? *lastTrusted_ : *own;
    if (freed_) sendFreed(pose, held);
    if (openTrackIo_) sendOpenTrackIo(frame, pose, timecode, recording, held);
    const int64_t now = monotonicNowNs();
    const double delayMs = double(now - captureInstantNs(frame, now)) * 1e-6;
    lastDelayMs_.store(delayMs);
    storeMax(maxDelayMs_, delayMs);
}

void TrackingOut::sendFreed(const cv::Matx44d& worldFromCamera, bool held) {
    const FreedEncoded packet = encodeFreed(worldFromCamera, lens_, freedConfig_.cameraId);
    if (packet.clamped) freedClamped_.fetch_add(1, std::memory_order_relaxed);
    if (held) freedHeld_.fetch_add(1, std::memory_order_relaxed);
    countSend(freed_->send(packet.bytes));
    freedPackets_.fetch_add(1, std::memory_order_relaxed);
}

void TrackingOut::sendOpenTrackIo(const TrackedFrame& frame, const cv::Matx44d& worldFromCamera,
                                  const std::optional<Timecode>& timecode, bool recording,
                                  bool held) {
    OpenTrackIOFrame sample;
    sample.worldFromCamera = worldFromCamera;
    sample.timestampNs = frame.frame->wallClockNs;
    if (timecode) sample.timecode = otrkTimecode(*timecode);
    // The rate samples are sent at, the camera's (a 15 fps camera's timecode counts at 30): as
    // configured, else measured; left out until the second frame says it.
    const std::optional<FrameRate> rate = configuredRate_ ? configuredRate_ : measuredRate_.rate();
    sample.sampleRateNum = rate ? rate->num : 0;
    sample.sampleRateDenom = rate ? rate->den : 1;
    sample.trackerStatus = held ? "Optical Lost (holding the last pose)" : "Optical Good";
    sample.recording = recording;
    sample.lens = lens_;
    for (const std::vector<uint8_t>& datagram : encoder_->encode(sample)) {
        countSend(openTrackIo_->send(datagram));
        datagrams_.fetch_add(1, std::memory_order_relaxed);
    }
    samples_.fetch_add(1, std::memory_order_relaxed);
}

void TrackingOut::countSend(UdpSocket::SendStatus status) {
    if (status == UdpSocket::SendStatus::Dropped) dropped_.fetch_add(1, std::memory_order_relaxed);
    if (status == UdpSocket::SendStatus::Failed) failed_.fetch_add(1, std::memory_order_relaxed);
}

TrackingOutStats TrackingOut::stats() const {
    TrackingOutStats s;
    s.freed = freed_.has_value();
    s.openTrackIo = openTrackIo_.has_value();
    s.freedPackets = freedPackets_.load();
    s.freedHeld = freedHeld_.load();
    s.freedClamped = freedClamped_.load();
    s.openTrackIoSamples = samples_.load();
    s.openTrackIoDatagrams = datagrams_.load();
    s.dropped = dropped_.load();
    s.failed = failed_.load();
    s.lostNotSent = lostNotSent_.load();
    s.lastDelayMs = lastDelayMs_.load();
    s.maxDelayMs = maxDelayMs_.load();
    return s;
}

}  // namespace previs
