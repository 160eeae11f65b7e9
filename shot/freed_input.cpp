#include "shot/freed_input.h"

#include <algorithm>

#include "base/log.h"
#include "base/monotonic_clock.h"
#include "config/service_config.h"

namespace previs {
namespace {

// Packets kept: seconds at a tracker's highest rate, more than any delay to look back over.
constexpr size_t kKeptPackets = 600;

}  // namespace

FreedInput::FreedInput(const TrackingConfig& tracking, PacketSink record)
    : cameraId_(tracking.freedCameraId),
      calibration_(tracking.freedCalibration.value_or(FreedCalibration{})),
      record_(std::move(record)) {
    stats_.calibrated = tracking.freedCalibration.has_value();
}

Result<std::unique_ptr<FreedInput>> FreedInput::listen(const TrackingConfig& tracking,
                                                       UniqueFD passed, PacketSink record) {
    std::unique_ptr<FreedInput> in(new FreedInput(tracking, std::move(record)));
    if (passed.isValid()) {
        in->socket_.emplace(UdpSocket::adoptReceiver(std::move(passed)));
    } else {
        Result<UdpSocket> socket = UdpSocket::receiver(tracking.freedListen);
        if (!socket)
            return makeError("[tracking] listen = '{}': {}", tracking.freedListen,
                             socket.message());
        in->socket_.emplace(std::move(*socket));
    }
    in->thread_ = std::thread([raw = in.get()] { raw->run(); });
    return in;
}

Result<std::unique_ptr<FreedInput>> FreedInput::recorded(const std::string& csvPath,
                                                         const TrackingConfig& tracking) {
    Result<FreedRecording> recording = loadFreedRecording(csvPath, tracking.freedCameraId);
    if (!recording) return recording.error();
    std::unique_ptr<FreedInput> in(new FreedInput(tracking, nullptr));
    in->series_ = std::move(recording->stageFromBody);
    in->stats_.packets = in->series_.size();
    return in;
}

void FreedInput::stop() {
    stop_.store(true);
    if (thread_.joinable()) thread_.join();
}

void FreedInput::run() {
    std::vector<uint8_t> buffer(2048);
    while (!stop_.load()) {
        const int n = socket_->receive(buffer, 100);
        if (n < 0) continue;
        const int64_t now = monotonicNowNs();
        // A datagram larger than the buffer is cut to it, still far from FreeD's 29 bytes.
        const std::span<const uint8_t> datagram(buffer.data(), std::min(size_t(n), buffer.size()));
        const FreedParse parse = decodeFreed(datagram, cameraId_);
        // Only what the pose is read from goes into the take: the configured tracker's valid
        // packets (a refused datagram is counted, never recorded, so a flood of junk costs the
        // take nothing).
        if (record_ && parse.ok()) record_(now, datagram);
        add(now, parse);
    }
}

void FreedInput::add(int64_t receivedNs, const FreedParse& parse) {
    std::lock_guard lock(mutex_);
    if (!parse.ok()) {
        ++stats_.rejected[size_t(parse.error)];
        return;
    }
    ++stats_.packets;
    series_.push_back({receivedNs, worldFromFreed(parse.packet)});
    if (series_.size() > 2 * kKeptPackets)
        series_.erase(series_.begin(), series_.end() - ptrdiff_t(kKeptPackets));
    arrived_.notify_all();
}

std::optional<cv::Matx44d> FreedInput::worldFromCamera(int64_t frameNs,
                                                       std::chrono::milliseconds wait) {
    const int64_t at = frameNs + int64_t(calibration_.delayMs * 1e6);
    std::unique_lock lock(mutex_);
    // The packet after the frame's instant may still be on its way (a positive delay).
    arrived_.wait_for(lock, wait,
                      [&] { return !series_.empty() && series_.back().timestampNs >= at; });
    return freedWorldFromCamera(calibration_, series_, frameNs);
}

FreedInputStats FreedInput::stats() const {
    std::lock_guard lock(mutex_);
    return stats_;
}

}  // namespace previs
