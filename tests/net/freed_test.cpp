// FreeD D1: the packets are read back by a decoder written here from the byte layout (not the
// encoder's helpers), and by Unreal's Live Link FreeD arithmetic, and must give back the tracked
// pose within the format's quantisation.

#include "net/freed.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace previs {
namespace {

constexpr double kPi = std::numbers::pi;

// --- An independent reader of the 29-byte layout (docs/freed.md) ---------------------------

struct RawD1 {
    int type, camera;
    int32_t pan, tilt, roll, x, y, height;  // 24-bit two's complement, sign-extended
    uint32_t zoom, focus;
    int spare, checksum;
};

int32_t signed24(const uint8_t* p) {
    int32_t v = (p[0] << 16) | (p[1] << 8) | p[2];
    return v >= 0x800000 ? v - 0x1000000 : v;
}

RawD1 readD1(const FreedBytes& b) {
    auto u24 = [&](int i) { return uint32_t((b[i] << 16) | (b[i + 1] << 8) | b[i + 2]); };
    return {b[0],
            b[1],
            signed24(&b[2]),
            signed24(&b[5]),
            signed24(&b[8]),
            signed24(&b[11]),
            signed24(&b[14]),
            signed24(&b[17]),
            u24(20),
            u24(23),
            (b[26] << 8) | b[27],
            b[28]};
}

// --- What Unreal's Live Link FreeD source makes of a packet (LiveLinkFreeDSource.cpp) -------
// FRotator(Pitch = tilt, Yaw = pan, Roll = roll) in degrees; FVector(X = FreeD Y, Y = FreeD X,
// Z = height) in cm (raw / 640); negatives decoded as raw − 0xFFFFFF (one unit high, as Unreal
// does). The camera's axes in Unreal's world are the rows of FRotationMatrix.

struct UnrealCamera {
    cv::Vec3d forward, right, up;  // Unreal world axes (X forward, Y right, Z up; left-handed)
    cv::Vec3d locationCm;
};

double unrealSigned(const uint8_t* p) {
    int32_t v = (p[0] << 16) | (p[1] << 8) | p[2];
    if (p[0] & 0x80) v -= 0x00FFFFFF;
    return v;
}

UnrealCamera unrealView(const FreedBytes& b) {
    double yaw = unrealSigned(&b[2]) / 32768.0 * kPi / 180;
    double pitch = unrealSigned(&b[5]) / 32768.0 * kPi / 180;
    double roll = unrealSigned(&b[8]) / 32768.0 * kPi / 180;
    double sp = std::sin(pitch), cp = std::cos(pitch), sy = std::sin(yaw), cy = std::cos(yaw);
    double sr = std::sin(roll), cr = std::cos(roll);
    UnrealCamera c;
    c.forward = {cp * cy, cp * sy, sp};
    c.right = {sr * sp * cy - cr * sy, sr * sp * sy + cr * cy, -sr * cp};
    c.up = {-(cr * sp * cy + sr * sy), cy * sr - cr * sp * sy, cr * cp};
    c.locationCm = {unrealSigned(&b[14]) / 640.0, unrealSigned(&b[11]) / 640.0,
                    unrealSigned(&b[17]) / 640.0};
    return c;
}

// Where our world's axes lie in Unreal's (docs/freed.md): Unreal X = −z, Y = x, Z = y (a
// reflection: right-handed to left-handed). Physical directions, so no sign games with angles.
cv::Vec3d toUnreal(const cv::Vec3d& w) { return {-w[2], w[0], w[1]}; }

cv::Vec3d column(const cv::Matx44d& m, int c) { return {m(0, c), m(1, c), m(2, c)}; }

double angleBetween(const cv::Vec3d& a, const cv::Vec3d& b) {
    return std::atan2(cv::norm(a.cross(b)), a.dot(b));
}

cv::Matx44d pose(const cv::Matx33d& r, const cv::Vec3d& t) {
    return {r(0, 0), r(0, 1), r(0, 2), t[0], r(1, 0), r(1, 1), r(1, 2), t[1],
            r(2, 0), r(2, 1), r(2, 2), t[2], 0,       0,       0,       1};
}

cv::Matx33d randomRotation(std::mt19937_64& rng) {
    std::normal_distribution<double> n;
    cv::Vec4d q(n(rng), n(rng), n(rng), n(rng));
    q /= cv::norm(q);
    double w = q[0], x = q[1], y = q[2], z = q[3];
    return {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),
            2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
}

// The quantisation: each angle within half a unit of 1/32768°, so the rotation within the sum
// of three; each coordinate within half of 1/64 mm. Unreal's decode adds one unit.
constexpr double kAngleTolRad = (3 * 0.5 + 3) / 32768.0 * kPi / 180 + 1e-12;
constexpr double kPositionTolM = 0.5 / 64 / 1000 + 1e-12;

LensSample lens35() {
    LensSample lens;
    lens.widthPx = 1920;
    lens.heightPx = 1080;
    lens.fxPx = lens.fyPx = 1920 * 35.0 / 36.0;  // 35 mm on a 36 mm gate
    lens.cxPx = 960;
    lens.cyPx = 540;
    return lens;
}

// Checks one pose both ways: through the independent reader and through Unreal's arithmetic.
void expectRecovered(const cv::Matx44d& worldFromCamera, const FreedBytes& bytes) {
    // The camera's forward, right and up in our world (OpenCV axes: z forward, x right, y down).
    cv::Vec3d forward = column(worldFromCamera, 2), right = column(worldFromCamera, 0);
    cv::Vec3d up = -column(worldFromCamera, 1), t = column(worldFromCamera, 3);

    UnrealCamera ue = unrealView(bytes);
    EXPECT_LT(angleBetween(ue.forward, toUnreal(forward)), kAngleTolRad);
    EXPECT_LT(angleBetween(ue.right, toUnreal(right)), kAngleTolRad);
    EXPECT_LT(angleBetween(ue.up, toUnreal(up)), kAngleTolRad);
    cv::Vec3d expectedCm = toUnreal(t) * 100.0;
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(ue.locationCm[i], expectedCm[i], 1.5 / 640 + 1e-9);

    // Our own decoder's inverse mapping agrees with the pose, too.
    FreedParse parse = decodeFreed(bytes, std::nullopt);
    ASSERT_TRUE(parse.ok()) << freedErrorName(parse.error);
    cv::Matx44d back = worldFromFreed(parse.packet);
    EXPECT_LT(angleBetween(column(back, 2), forward), kAngleTolRad);
    EXPECT_LT(angleBetween(column(back, 0), right), kAngleTolRad);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(back(i, 3), t[i], kPositionTolM);
}

TEST(Freed, LayoutOfAKnownPacket) {
    // Fields chosen by hand and their bytes worked out by hand (two's complement, big-endian).
    FreedPacket p;
    p.cameraId = 1;
    p.panDeg = 90;      // 2949120 = 0x2D0000
    p.tiltDeg = -45;    // −1474560 = 0xE98000
    p.xMm = 1000;       // 64000 = 0x00FA00
    p.yMm = -2500;      // −160000 = 0xFD8F00
    p.heightMm = 1500;  // 96000 = 0x017700
    p.zoom = 3500;      // 35 mm in 1/100 mm = 0x000DAC
    FreedBytes expected = {0xD1, 0x01, 0x2D, 0x00, 0x00, 0xE9, 0x80, 0x00, 0x00, 0x00,
                           0x00, 0x00, 0xFA, 0x00, 0xFD, 0x8F, 0x00, 0x01, 0x77, 0x00,
                           0x00, 0x0D, 0xAC, 0x00, 0x00, 0x00, 0x00, 0x00, 0x21};
    FreedEncoded e = encodeFreed(p);
    EXPECT_FALSE(e.clamped);
    EXPECT_EQ(e.bytes, expected);
}

TEST(Freed, RangeEndsAsTheVintenManualWritesThem) {
    // free-d Installation Manual V1.4.4, Appendix B: −180° = A60000 hex, +180° = 5A0000 hex,
    // −131,072.0 mm = 800000 hex, nearly +131,072.0 mm = 7FFFFF hex.
    FreedPacket p;
    p.panDeg = -180;
    p.rollDeg = 180;
    p.xMm = -131072;
    p.yMm = 131072 - 1.0 / 64;
    FreedBytes b = encodeFreed(p).bytes;
    EXPECT_EQ((std::array{b[2], b[3], b[4]}), (std::array<uint8_t, 3>{0xA6, 0x00, 0x00}));
    EXPECT_EQ((std::array{b[8], b[9], b[10]}), (std::array<uint8_t, 3>{0x5A, 0x00, 0x00}));
    EXPECT_EQ((std::array{b[11], b[12], b[13]}), (std::array<uint8_t, 3>{0x80, 0x00, 0x00}));
    EXPECT_EQ((std::array{b[14], b[15], b[16]}), (std::array<uint8_t, 3>{0x7F, 0xFF, 0xFF}));
    FreedParse back = decodeFreed(b, std::nullopt);
    ASSERT_TRUE(back.ok());
    EXPECT_EQ(back.packet.panDeg, -180.0);
    EXPECT_EQ(back.packet.xMm, -131072.0);
    EXPECT_EQ(back.packet.yMm, 131072 - 1.0 / 64);
}

TEST(Freed, ChecksumExamples) {
    FreedBytes b{};
    b[0] = 0xD1;
    EXPECT_EQ(freedChecksum(b), 0x6F);  // 0x40 − 0xD1 mod 256
    b[1] = 0xFF;
    EXPECT_EQ(freedChecksum(b), 0x70);  // 0x40 − 0xD1 − 0xFF mod 256
    for (int i = 0; i < 28; ++i) b[i] = 0xFF;
    EXPECT_EQ(freedChecksum(b), uint8_t(0x40 - 28 * 0xFF));
}

TEST(Freed, DefaultGltfCameraLooksAlongUnrealX) {
    // A camera at identity in glTF terms looks along world −Z with +Y up: OpenCV axes
    // diag(1, −1, −1). Unreal must see it looking along +X, level: all angles zero.
    cv::Matx44d w = pose(cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1), {1, 2, 3});
    RawD1 d = readD1(encodeFreed(w, lens35(), 7).bytes);
    EXPECT_EQ(d.type, 0xD1);
    EXPECT_EQ(d.camera, 7);
    EXPECT_EQ(d.pan, 0);
    EXPECT_EQ(d.tilt, 0);
    EXPECT_EQ(d.roll, 0);
    EXPECT_EQ(d.x, 1000 * 64);       // FreeD X = world x
    EXPECT_EQ(d.y, -3000 * 64);      // FreeD Y = −world z
    EXPECT_EQ(d.height, 2000 * 64);  // height = world y
    EXPECT_EQ(d.zoom, 3500u);        // 35 mm in 1/100 mm
    EXPECT_EQ(d.focus, 0u);          // unknown
    EXPECT_EQ(d.spare, 0);
}

TEST(Freed, PanIsClockwiseFromAbove) {
    // Looking along world +X (to the right of the default view): Unreal yaw +90 (towards +Y).
    cv::Matx44d w = pose(cv::Matx33d(0, 0, 1, 0, -1, 0, 1, 0, 0), {0, 0, 0});
    RawD1 d = readD1(encodeFreed(w, lens35(), 1).bytes);
    EXPECT_EQ(d.pan, 90 * 32768);
    EXPECT_EQ(d.tilt, 0);
    EXPECT_EQ(d.roll, 0);
    // Looking straight up: tilt +90.
    cv::Matx44d up = pose(cv::Matx33d(1, 0, 0, 0, 0, 1, 0, -1, 0), {0, 0, 0});
    EXPECT_EQ(readD1(encodeFreed(up, lens35(), 1).bytes).tilt, 90 * 32768);
}

TEST(Freed, RandomPosesRoundTripWithinQuantisation) {
    std::mt19937_64 rng(20261205);
    std::uniform_real_distribution<double> position(-131.0, 131.0);
    for (int i = 0; i < 2000; ++i) {
        cv::Matx44d w = pose(randomRotation(rng), {position(rng), position(rng), position(rng)});
        FreedEncoded e = encodeFreed(w, lens35(), 3);
        ASSERT_FALSE(e.clamped);
        expectRecovered(w, e.bytes);
    }
}

TEST(Freed, HardAnglesRoundTrip) {
    // Pan across ±180° (the wrap), tilt at and near ±90° (gimbal lock: pan and roll share an
    // axis; the rotation must still come back), roll across ±180°, and the 24-bit extremes.
    const double pans[] = {-180, -179.99999, 179.99999, 180, 0.00001, -0.00001};
    const double tilts[] = {-90, -89.99999, -89.9, 0, 89.9, 89.99999, 90};
    const double rolls[] = {-180, -179.99999, 0, 179.99999, 180, 45};
    const cv::Vec3d positions[] = {
        {-131.07, -131.07, -131.07}, {131.07, 131.07, 131.07}, {0, 0, 0}};
    for (double pan : pans) {
        for (double tilt : tilts) {
            for (double roll : rolls) {
                for (const cv::Vec3d& t : positions) {
                    StagePose s{t, pan, tilt, roll};
                    cv::Matx44d w = worldFromStagePose(s);
                    FreedEncoded e = encodeFreed(w, lens35(), 1);
                    ASSERT_FALSE(e.clamped);
                    SCOPED_TRACE(::testing::Message() << pan << " " << tilt << " " << roll);
                    expectRecovered(w, e.bytes);
                }
            }
        }
    }
}

TEST(Freed, PositionBeyondRangeIsClampedAndReported) {
    cv::Matx44d far = pose(cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1), {140, -200, 1});
    FreedEncoded e = encodeFreed(far, lens35(), 1);
    EXPECT_TRUE(e.clamped);
    RawD1 d = readD1(e.bytes);
    EXPECT_EQ(d.x, 0x7FFFFF);        // +131.07 m, not wrapped to a negative
    EXPECT_EQ(d.height, -0x800000);  // −131.07 m
    EXPECT_EQ(d.y, -1000 * 64);      // the axis in range is untouched
    cv::Matx44d farBack = pose(cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1), {-140, 0, 0});
    EXPECT_EQ(readD1(encodeFreed(farBack, lens35(), 1).bytes).x, -0x800000);
    // Still a valid packet.
    EXPECT_TRUE(decodeFreed(e.bytes, 1).ok());
}

TEST(Freed, ZoomAndFocusFromTheLens) {
    LensSample lens = lens35();
    lens.sensorWidthMm = 24.89;  // Super 35
    lens.fxPx = lens.fyPx = 1920 * 50.0 / 24.89;
    lens.focusDistanceM = 2.5;
    cv::Matx44d w = pose(cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1), {0, 0, 0});
    RawD1 d = readD1(encodeFreed(w, lens, 1).bytes);
    EXPECT_EQ(d.zoom, 5000u);   // 50 mm
    EXPECT_EQ(d.focus, 2500u);  // 2.5 m in mm
}

TEST(Freed, RejectsWrongSize) {
    FreedBytes good = encodeFreed(FreedPacket{}).bytes;
    std::vector<uint8_t> shorter(good.begin(), good.end() - 1);
    std::vector<uint8_t> longer(good.begin(), good.end());
    longer.push_back(0);
    EXPECT_EQ(decodeFreed(shorter, std::nullopt).error, FreedError::WrongSize);
    EXPECT_EQ(decodeFreed(longer, std::nullopt).error, FreedError::WrongSize);
    EXPECT_EQ(decodeFreed({}, std::nullopt).error, FreedError::WrongSize);
    EXPECT_STREQ(freedErrorName(FreedError::WrongSize), "wrong_size");
}

TEST(Freed, RejectsWrongType) {
    FreedBytes b = encodeFreed(FreedPacket{}).bytes;
    b[0] = 0xD0;  // a D0 (position request) message, checksum fixed so only the type is wrong
    b[28] = freedChecksum(b);
    EXPECT_EQ(decodeFreed(b, std::nullopt).error, FreedError::WrongType);
}

TEST(Freed, RejectsBadChecksum) {
    FreedPacket p;
    p.panDeg = 12.5;
    FreedBytes b = encodeFreed(p).bytes;
    for (size_t i = 1; i < kFreedPacketSize; ++i) {
        FreedBytes bad = b;
        bad[i] ^= 0x10;
        EXPECT_EQ(decodeFreed(bad, std::nullopt).error, FreedError::BadChecksum) << "byte " << i;
    }
}

TEST(Freed, RejectsOtherCamera) {
    FreedPacket p;
    p.cameraId = 2;
    FreedBytes b = encodeFreed(p).bytes;
    EXPECT_EQ(decodeFreed(b, uint8_t(1)).error, FreedError::OtherCamera);
    EXPECT_TRUE(decodeFreed(b, uint8_t(2)).ok());
    EXPECT_TRUE(decodeFreed(b, std::nullopt).ok());
}

TEST(Freed, GarbageNeverDecodesAsAPose) {
    // Random datagrams: any that passes must have the right size, type and checksum.
    std::mt19937_64 rng(7);
    int accepted = 0;
    for (int i = 0; i < 20000; ++i) {
        std::vector<uint8_t> d(rng() % 40);
        for (auto& x : d) x = uint8_t(rng());
        if (!d.empty() && rng() % 2) d[0] = 0xD1;
        FreedParse parse = decodeFreed(d, std::nullopt);
        if (parse.ok()) {
            ++accepted;
            EXPECT_EQ(d.size(), kFreedPacketSize);
            EXPECT_EQ(d[28], freedChecksum(d));
        }
    }
    EXPECT_LT(accepted, 200);
}

}  // namespace
}  // namespace previs
