#include "net/freed.h"

#include <algorithm>
#include <cmath>

namespace previs {

namespace {

constexpr int32_t kMin24 = -(1 << 23);
constexpr int32_t kMax24 = (1 << 23) - 1;
constexpr uint32_t kMaxU24 = (1u << 24) - 1;

// Byte offsets of the D1 fields.
enum Offset : size_t {
    kType = 0,
    kCamera = 1,
    kPan = 2,
    kTilt = 5,
    kRoll = 8,
    kX = 11,
    kY = 14,
    kHeight = 17,
    kZoom = 20,
    kFocus = 23,
    kSpare = 26,
    kChecksum = 28,
};

// Rounds to the nearest unit and clamps to the signed 24-bit range, noting a clamp: a value
// beyond the range must not wrap to the other end (a camera 140 m away is not at −122 m).
int32_t toSigned24(double units, bool& clamped) {
    if (!std::isfinite(units)) {
        clamped = true;
        return 0;
    }
    double r = std::round(units);
    if (r < kMin24 || r > kMax24) clamped = true;
    return static_cast<int32_t>(std::clamp(r, double(kMin24), double(kMax24)));
}

uint32_t toUnsigned24(double units, bool& clamped) {
    if (!std::isfinite(units) || units < 0) return 0;
    double r = std::round(units);
    if (r > kMaxU24) clamped = true;
    return static_cast<uint32_t>(std::min(r, double(kMaxU24)));
}

void put24(uint8_t* p, uint32_t v) {
    p[0] = uint8_t(v >> 16);
    p[1] = uint8_t(v >> 8);
    p[2] = uint8_t(v);
}

uint32_t get24(const uint8_t* p) { return uint32_t(p[0]) << 16 | uint32_t(p[1]) << 8 | p[2]; }

int32_t getSigned24(const uint8_t* p) {
    uint32_t v = get24(p);
    return (v & 0x800000u) ? int32_t(v) - (1 << 24) : int32_t(v);
}

// Pan into (−180, 180] so the 24-bit field (±256°) never clamps an angle.
double wrapDeg(double deg) {
    double w = std::remainder(deg, 360.0);
    return w == -180.0 ? 180.0 : w;
}

}  // namespace

uint8_t freedChecksum(std::span<const uint8_t> first28) {
    uint8_t sum = 0x40;
    for (size_t i = 0; i < kChecksum && i < first28.size(); ++i) sum -= first28[i];
    return sum;
}

FreedEncoded encodeFreed(const FreedPacket& packet) {
    FreedEncoded out;
    uint8_t* b = out.bytes.data();
    bool& c = out.clamped;
    b[kType] = kFreedTypeD1;
    b[kCamera] = packet.cameraId;
    put24(b + kPan, uint32_t(toSigned24(packet.panDeg * kFreedAngleUnitsPerDeg, c)));
    put24(b + kTilt, uint32_t(toSigned24(packet.tiltDeg * kFreedAngleUnitsPerDeg, c)));
    put24(b + kRoll, uint32_t(toSigned24(packet.rollDeg * kFreedAngleUnitsPerDeg, c)));
    put24(b + kX, uint32_t(toSigned24(packet.xMm * kFreedPositionUnitsPerMm, c)));
    put24(b + kY, uint32_t(toSigned24(packet.yMm * kFreedPositionUnitsPerMm, c)));
    put24(b + kHeight, uint32_t(toSigned24(packet.heightMm * kFreedPositionUnitsPerMm, c)));
    put24(b + kZoom, std::min(packet.zoom, kMaxU24));
    put24(b + kFocus, std::min(packet.focus, kMaxU24));
    b[kSpare] = uint8_t(packet.spare >> 8);
    b[kSpare + 1] = uint8_t(packet.spare);
    b[kChecksum] = freedChecksum(out.bytes);
    return out;
}

FreedEncoded encodeFreed(const cv::Matx44d& worldFromCamera, const LensSample& lens,
                         uint8_t cameraId) {
    StagePose pose = stagePoseFromWorld(worldFromCamera);
    FreedPacket packet;
    packet.cameraId = cameraId;
    // FreeD's pan (and Unreal's yaw) turns clockwise seen from above: the stage pan negated.
    packet.panDeg = wrapDeg(-pose.panDeg);
    packet.tiltDeg = pose.tiltDeg;
    packet.rollDeg = pose.rollDeg;
    packet.xMm = pose.translationM[0] * 1000.0;
    packet.yMm = pose.translationM[1] * 1000.0;
    packet.heightMm = pose.translationM[2] * 1000.0;
    bool lensClamped = false;
    if (lens.valid()) {
        packet.zoom = toUnsigned24(lens.focalLengthMm() * kFreedZoomUnitsPerMm, lensClamped);
    }
    packet.focus = toUnsigned24(lens.focusDistanceM * kFreedFocusUnitsPerM, lensClamped);
    FreedEncoded out = encodeFreed(packet);
    out.clamped = out.clamped || lensClamped;
    return out;
}

const char* freedErrorName(FreedError error) {
    switch (error) {
        case FreedError::None:
            return "none";
        case FreedError::WrongSize:
            return "wrong_size";
        case FreedError::WrongType:
            return "wrong_type";
        case FreedError::BadChecksum:
            return "bad_checksum";
        case FreedError::OtherCamera:
            return "other_camera";
    }
    return "unknown";
}

FreedParse decodeFreed(std::span<const uint8_t> datagram, std::optional<uint8_t> cameraId) {
    FreedParse parse;
    if (datagram.size() != kFreedPacketSize) {
        parse.error = FreedError::WrongSize;
        return parse;
    }
    const uint8_t* b = datagram.data();
    if (b[kType] != kFreedTypeD1) {
        parse.error = FreedError::WrongType;
    } else if (b[kChecksum] != freedChecksum(datagram)) {
        parse.error = FreedError::BadChecksum;
    } else if (cameraId && b[kCamera] != *cameraId) {
        parse.error = FreedError::OtherCamera;
    }
    if (!parse.ok()) return parse;
    FreedPacket& p = parse.packet;
    p.cameraId = b[kCamera];
    p.panDeg = getSigned24(b + kPan) / kFreedAngleUnitsPerDeg;
    p.tiltDeg = getSigned24(b + kTilt) / kFreedAngleUnitsPerDeg;
    p.rollDeg = getSigned24(b + kRoll) / kFreedAngleUnitsPerDeg;
    p.xMm = getSigned24(b + kX) / kFreedPositionUnitsPerMm;
    p.yMm = getSigned24(b + kY) / kFreedPositionUnitsPerMm;
    p.heightMm = getSigned24(b + kHeight) / kFreedPositionUnitsPerMm;
    p.zoom = get24(b + kZoom);
    p.focus = get24(b + kFocus);
    p.spare = uint16_t(b[kSpare] << 8 | b[kSpare + 1]);
    return parse;
}

StagePose stagePoseFromFreed(const FreedPacket& packet) {
    StagePose pose;
    pose.panDeg = -packet.panDeg;
    pose.tiltDeg = packet.tiltDeg;
    pose.rollDeg = packet.rollDeg;
    pose.translationM = cv::Vec3d(packet.xMm, packet.yMm, packet.heightMm) / 1000.0;
    return pose;
}

cv::Matx44d worldFromFreed(const FreedPacket& packet) {
    return worldFromStagePose(stagePoseFromFreed(packet));
}

}  // namespace previs
