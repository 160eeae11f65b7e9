#pragma once

// FreeD D1 (Vinten/Radamec "free-d" protocol): one 29-byte packet per tracked frame, big-endian.
// Byte layout, axes, units and the mapping from our pose and lens: docs/freed.md.
//
// Sending (per tracked frame, on the tracking thread):
//     FreedEncoded packet = encodeFreed(worldFromCamera, lens, cameraId);
//     if (packet.clamped) count it (status) — the position was beyond ±131 m;
//     socket.send(packet.bytes);
// A lost pose sends nothing: do not call encodeFreed with a stale pose.
//
// Receiving ([tracking] source = "freed"):
//     FreedParse parse = decodeFreed(datagram, cameraId);
//     if (!parse.ok()) { count freedErrorName(parse.error); drop; }
//     else worldFromCamera = worldFromFreed(parse.packet);

#include <array>
#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <span>

#include "net/lens_sample.h"
#include "net/stage_pose.h"

namespace previs {

inline constexpr size_t kFreedPacketSize = 29;
inline constexpr uint8_t kFreedTypeD1 = 0xD1;
// Units of the 24-bit fields: angles in 1/32768°, positions in 1/64 mm.
inline constexpr double kFreedAngleUnitsPerDeg = 32768.0;
inline constexpr double kFreedPositionUnitsPerMm = 64.0;
// Zoom carries the focal length in 1/100 mm (as Z CAM's FreeD does), focus the focus distance in
// mm (0 when unknown). Both stay below 2^16 for real lenses (655.35 mm, 65.5 m): Unreal's
// generic FreeD preset masks these fields to 16 bits before auto-ranging them.
inline constexpr double kFreedZoomUnitsPerMm = 100.0;
inline constexpr double kFreedFocusUnitsPerM = 1000.0;

using FreedBytes = std::array<uint8_t, kFreedPacketSize>;

// The fields of a D1 packet in physical units (FreeD's own axes and signs: pan clockwise seen
// from above; X, Y, height = stage X, Y, Z).
struct FreedPacket {
    uint8_t cameraId = 0;
    double panDeg = 0, tiltDeg = 0, rollDeg = 0;
    double xMm = 0, yMm = 0, heightMm = 0;
    uint32_t zoom = 0, focus = 0;  // raw 24-bit values
    uint16_t spare = 0;
};

struct FreedEncoded {
    FreedBytes bytes{};
    // True when a position or angle was beyond the 24-bit range and was clamped to its end
    // (positions: ±131.072 m); the packet is still valid, the value is the range's end.
    bool clamped = false;
};

// (0x40 − Σ bytes[0..27]) mod 256, over the first 28 bytes.
uint8_t freedChecksum(std::span<const uint8_t> first28);

// The packet for a camera pose (OpenCV camera axes, our Y-up world in metres) and its lens.
FreedEncoded encodeFreed(const cv::Matx44d& worldFromCamera, const LensSample& lens,
                         uint8_t cameraId);
// The packet for fields given in FreeD's own units (tests, replay).
FreedEncoded encodeFreed(const FreedPacket& packet);

enum class FreedError {
    None,
    WrongSize,    // not 29 bytes
    WrongType,    // first byte not 0xD1
    BadChecksum,  // byte 28 is not (0x40 − Σ bytes 0..27) mod 256
    OtherCamera,  // a camera id other than the one configured
};
// A short stable name for status counters ("wrong_size", ...).
const char* freedErrorName(FreedError error);

struct FreedParse {
    FreedError error = FreedError::None;
    FreedPacket packet;  // valid only when ok()
    bool ok() const { return error == FreedError::None; }
};

// Validates and parses one datagram. With `cameraId` set, a packet for another camera is
// rejected (FreedError::OtherCamera); checks run in the order size, type, checksum, camera.
FreedParse decodeFreed(std::span<const uint8_t> datagram, std::optional<uint8_t> cameraId);

// The inverse of the encoder's mapping: the pose a packet describes.
cv::Matx44d worldFromFreed(const FreedPacket& packet);
// The stage pose (OpenTrackIO signs: pan = −FreeD pan) a packet describes.
StagePose stagePoseFromFreed(const FreedPacket& packet);

}  // namespace previs
