// OpenTrackIO: the OTrk header read by a decoder written here from the spec's table, Fletcher-16,
// segmentation and reassembly, each bad-input case, and the sample's fields.

#include "net/opentrackio.h"

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <random>
#include <regex>
#include <set>

namespace previs {
namespace {

using Bytes = std::vector<uint8_t>;

// --- The header as the spec's table lays it out (bit offsets, big-endian) -------------------
struct SpecHeader {
    std::string identifier;  // bits 0–31
    int reserved;            // 32–39
    int encoding;            // 40–47
    int sequence;            // 48–63
    uint32_t offset;         // 64–95
    bool last;               // 96
    int length;              // 97–111
    int checksum;            // 112–127
};

SpecHeader readHeader(const Bytes& d) {
    SpecHeader h;
    h.identifier.assign(d.begin(), d.begin() + 4);
    h.reserved = d[4];
    h.encoding = d[5];
    h.sequence = d[6] * 256 + d[7];
    h.offset = uint32_t(d[8]) << 24 | uint32_t(d[9]) << 16 | uint32_t(d[10]) << 8 | d[11];
    h.last = (d[12] & 0x80) != 0;
    h.length = (d[12] & 0x7F) * 256 + d[13];
    h.checksum = d[14] * 256 + d[15];
    return h;
}

// The spec's reference code: uint8_t sums, so modulus 256.
int specFletcher(const Bytes& bytes) {
    int a = 0, b = 0;
    for (uint8_t x : bytes) {
        a = (a + x) % 256;
        b = (b + a) % 256;
    }
    return b * 256 + a;
}

int checksumOf(const Bytes& datagram) {
    Bytes covered(datagram.begin(), datagram.begin() + 14);
    covered.insert(covered.end(), datagram.begin() + 16, datagram.end());
    return specFletcher(covered);
}

Bytes randomBytes(size_t n, uint64_t seed) {
    std::mt19937_64 rng(seed);
    Bytes b(n);
    for (auto& x : b) x = uint8_t(rng());
    return b;
}

TEST(OpenTrackIO, Fletcher16IsModulo256) {
    const std::string abcde = "abcde";
    Bytes b(abcde.begin(), abcde.end());
    EXPECT_EQ(otrkFletcher16(b),
              0xC3EF);  // worked by hand: sum1 = 495 mod 256, sum2 = 1475 mod 256
    EXPECT_EQ(otrkFletcher16(b), specFletcher(b));
    Bytes big = randomBytes(5000, 1);
    EXPECT_EQ(otrkFletcher16(big), specFletcher(big));
    EXPECT_EQ(otrkFletcher16({}), 0);
}

TEST(OpenTrackIO, MulticastGroupAndPort) {
    EXPECT_EQ(openTrackIOMulticastGroup(14), "239.135.1.14");  // the spec's own example
    EXPECT_EQ(kOpenTrackIOPort, 55555);
}

TEST(OpenTrackIO, SingleSegmentHeader) {
    Bytes payload = {'{', '}'};
    uint16_t sequence = 65535;
    auto datagrams = frameOtrk(payload, OtrkEncoding::Json, sequence);
    ASSERT_EQ(datagrams.size(), 1u);
    EXPECT_EQ(sequence, 0);  // wrapped
    const Bytes& d = datagrams[0];
    ASSERT_EQ(d.size(), 18u);
    SpecHeader h = readHeader(d);
    EXPECT_EQ(h.identifier, "OTrk");
    EXPECT_EQ(h.reserved, 0);
    EXPECT_EQ(h.encoding, 0x01);  // JSON
    EXPECT_EQ(h.sequence, 65535);
    EXPECT_EQ(h.offset, 0u);
    EXPECT_TRUE(h.last);
    EXPECT_EQ(h.length, 2);
    EXPECT_EQ(h.checksum, checksumOf(d));
}

TEST(OpenTrackIO, SegmentationRoundTrip) {
    Bytes payload = randomBytes(5000, 2);
    uint16_t sequence = 100;
    auto datagrams = frameOtrk(payload, OtrkEncoding::Json, sequence, 1200);
    ASSERT_EQ(datagrams.size(), 5u);  // 4 × 1200 + 200
    Bytes rebuilt;
    for (size_t i = 0; i < datagrams.size(); ++i) {
        SpecHeader h = readHeader(datagrams[i]);
        EXPECT_EQ(h.sequence, 100 + int(i));  // one per datagram, as the reference sender
        EXPECT_EQ(h.offset, rebuilt.size());
        EXPECT_EQ(h.last, i + 1 == datagrams.size());
        EXPECT_EQ(h.length, int(datagrams[i].size() - 16));
        EXPECT_EQ(h.checksum, checksumOf(datagrams[i]));
        rebuilt.insert(rebuilt.end(), datagrams[i].begin() + 16, datagrams[i].end());
    }
    EXPECT_EQ(rebuilt, payload);

    OtrkReassembler reassembler;
    for (size_t i = 0; i + 1 < datagrams.size(); ++i) {
        EXPECT_EQ(reassembler.push(datagrams[i]), OtrkReassembler::Status::Incomplete);
    }
    ASSERT_EQ(reassembler.push(datagrams.back()), OtrkReassembler::Status::Complete);
    EXPECT_EQ(reassembler.payload(), payload);
    EXPECT_EQ(reassembler.encoding(), 0x01);
}

TEST(OpenTrackIO, DefaultSegmentsFitOneEthernetFrame) {
    Bytes payload = randomBytes(4000, 3);
    uint16_t sequence = 0;
    for (const Bytes& d : frameOtrk(payload, OtrkEncoding::Json, sequence)) {
        EXPECT_LE(d.size(), 1500u);
    }
}

TEST(OpenTrackIO, SegmentOutOfOrderIsRejected) {
    Bytes payload = randomBytes(3000, 4);
    uint16_t sequence = 0;
    auto d = frameOtrk(payload, OtrkEncoding::Json, sequence, 1000);
    ASSERT_EQ(d.size(), 3u);
    OtrkReassembler r;
    EXPECT_EQ(r.push(d[0]), OtrkReassembler::Status::Incomplete);
    EXPECT_EQ(r.push(d[2]), OtrkReassembler::Status::Rejected);
    EXPECT_EQ(r.error(), OtrkError::OutOfOrder);
    EXPECT_STREQ(otrkErrorName(r.error()), "out_of_order");
    // The late segment cannot complete anything: the partial payload was dropped whole.
    EXPECT_EQ(r.push(d[1]), OtrkReassembler::Status::Rejected);
    // The next payload assembles cleanly.
    auto next = frameOtrk(payload, OtrkEncoding::Json, sequence, 1000);
    for (size_t i = 0; i + 1 < next.size(); ++i) r.push(next[i]);
    EXPECT_EQ(r.push(next.back()), OtrkReassembler::Status::Complete);
    EXPECT_EQ(r.payload(), payload);
}

TEST(OpenTrackIO, LostLastSegmentDropsThePayload) {
    Bytes a = randomBytes(2500, 5), b = randomBytes(100, 6);
    uint16_t sequence = 0;
    auto da = frameOtrk(a, OtrkEncoding::Json, sequence, 1000);
    auto db = frameOtrk(b, OtrkEncoding::Json, sequence, 1000);
    OtrkReassembler r;
    r.push(da[0]);
    r.push(da[1]);  // da[2], the last, is lost
    ASSERT_EQ(r.push(db[0]), OtrkReassembler::Status::Complete);
    EXPECT_EQ(r.payload(), b);
}

TEST(OpenTrackIO, BadChecksumIsRejected) {
    Bytes payload = {'{', '"', 'a', '"', ':', '1', '}'};
    uint16_t sequence = 0;
    Bytes d = frameOtrk(payload, OtrkEncoding::Json, sequence)[0];
    for (size_t i = 4; i < d.size(); ++i) {
        if (i == 12 || i == 13) continue;  // the length: its own error (below)
        Bytes bad = d;
        bad[i] ^= 0x01;
        OtrkReassembler r;
        EXPECT_EQ(r.push(bad), OtrkReassembler::Status::Rejected) << "byte " << i;
        EXPECT_EQ(r.error(), OtrkError::BadChecksum) << "byte " << i;
    }
}

TEST(OpenTrackIO, TruncatedOrWrongLengthIsRejected) {
    Bytes payload = randomBytes(300, 7);
    uint16_t sequence = 0;
    Bytes d = frameOtrk(payload, OtrkEncoding::Json, sequence)[0];
    for (size_t n : {0, 1, 10, 15}) {
        EXPECT_EQ(parseOtrkSegment(std::span(d).first(n)).error, OtrkError::Truncated) << n;
    }
    EXPECT_EQ(parseOtrkSegment(std::span(d).first(200)).error, OtrkError::Truncated);
    Bytes longer = d;
    longer.push_back(0);
    EXPECT_EQ(parseOtrkSegment(longer).error, OtrkError::WrongLength);
    Bytes notOtrk = d;
    notOtrk[0] = 'X';
    EXPECT_EQ(parseOtrkSegment(notOtrk).error, OtrkError::BadIdentifier);
}

TEST(OpenTrackIO, DuplicateDatagramIsProcessedOnce) {
    Bytes payload = {'{', '}'};
    uint16_t sequence = 0;
    Bytes d = frameOtrk(payload, OtrkEncoding::Json, sequence)[0];
    OtrkReassembler r;
    EXPECT_EQ(r.push(d), OtrkReassembler::Status::Complete);
    EXPECT_EQ(r.push(d), OtrkReassembler::Status::Rejected);
    EXPECT_EQ(r.error(), OtrkError::Duplicate);
}

TEST(OpenTrackIO, OversizedPayloadIsRejected) {
    Bytes payload = randomBytes(3000, 8);
    uint16_t sequence = 0;
    auto d = frameOtrk(payload, OtrkEncoding::Json, sequence, 1000);
    OtrkReassembler r(2000);
    r.push(d[0]);
    r.push(d[1]);
    EXPECT_EQ(r.push(d[2]), OtrkReassembler::Status::Rejected);
    EXPECT_EQ(r.error(), OtrkError::TooLarge);
}

TEST(OpenTrackIO, GarbageNeverCrashes) {
    std::mt19937_64 rng(9);
    OtrkReassembler r;
    for (int i = 0; i < 20000; ++i) {
        Bytes d(rng() % 64);
        for (auto& x : d) x = uint8_t(rng());
        if (d.size() >= 4 && rng() % 2) std::copy_n("OTrk", 4, d.begin());
        r.push(d);  // any outcome but a crash; ASan runs this too
    }
}

OpenTrackIOSource sourceNumbered(int number) {
    OpenTrackIOSource source;
    source.sourceNumber = uint8_t(number);
    return source;
}

cv::Matx44d pose(double panDeg, double tiltDeg, double rollDeg, cv::Vec3d stageM) {
    return worldFromStagePose(StagePose{stageM, panDeg, tiltDeg, rollDeg});
}

LensSample pinholeLens() {
    LensSample lens;
    lens.widthPx = 1920;
    lens.heightPx = 1080;
    lens.fxPx = lens.fyPx = 1600;
    lens.cxPx = 970;
    lens.cyPx = 530;
    lens.sensorWidthMm = 24.0;
    lens.distortion = {-0.1, 0.02, 0.001, -0.002, 0.003};
    return lens;
}

TEST(OpenTrackIO, SampleCarriesPoseTimingAndLens) {
    auto encoder = OpenTrackIOEncoder::create(sourceNumbered(3));
    ASSERT_TRUE(encoder.ok()) << encoder.message();
    OpenTrackIOFrame frame;
    frame.worldFromCamera = pose(30, -10, 5, {1.5, -2.25, 1.8});
    frame.timestampNs = 1'765'000'000'123'456'789ull;
    frame.timecode = OtrkTimecode{10, 20, 30, 12, 30000, 1001, true};
    frame.sampleRateNum = 30000;
    frame.sampleRateDenom = 1001;
    frame.lens = pinholeLens();
    nlohmann::json a = nlohmann::json::parse(encoder->sampleJson(frame));
    nlohmann::json b = nlohmann::json::parse(encoder->sampleJson(frame));

    EXPECT_EQ(a["protocol"]["name"], "OpenTrackIO");
    EXPECT_EQ(a["sourceNumber"], 3);
    EXPECT_EQ(a["sourceId"], b["sourceId"]);
    EXPECT_NE(a["sampleId"], b["sampleId"]);
    std::regex urn(
        "^urn:uuid:[0-9a-f]{8}-[0-9a-f]{4}-4[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}$");
    EXPECT_TRUE(std::regex_match(a["sampleId"].get<std::string>(), urn));
    EXPECT_EQ(b["timing"]["sequenceNumber"].get<int>(),
              a["timing"]["sequenceNumber"].get<int>() + 1);

    const auto& t = a["transforms"][0];
    EXPECT_NEAR(t["translation"]["x"].get<double>(), 1.5, 1e-12);
    EXPECT_NEAR(t["translation"]["y"].get<double>(), -2.25, 1e-12);
    EXPECT_NEAR(t["translation"]["z"].get<double>(), 1.8, 1e-12);
    EXPECT_NEAR(t["rotation"]["pan"].get<double>(), 30, 1e-9);
    EXPECT_NEAR(t["rotation"]["tilt"].get<double>(), -10, 1e-9);
    EXPECT_NEAR(t["rotation"]["roll"].get<double>(), 5, 1e-9);

    const auto& timing = a["timing"];
    EXPECT_EQ(timing["sampleTimestamp"]["seconds"], 1'765'000'000ull);
    EXPECT_EQ(timing["sampleTimestamp"]["nanoseconds"], 123'456'789);
    EXPECT_EQ(timing["timecode"]["frames"], 12);
    EXPECT_EQ(timing["timecode"]["frameRate"]["num"], 30000);
    EXPECT_EQ(timing["timecode"]["dropFrame"], true);
    EXPECT_EQ(timing["sampleRate"]["denom"], 1001);

    const auto& lens = a["lens"];
    EXPECT_NEAR(lens["pinholeFocalLength"].get<double>(), 1600 * 24.0 / 1920, 1e-9);  // 20 mm
    EXPECT_NEAR(lens["projectionOffset"]["x"].get<double>(), 10 * 24.0 / 1920, 1e-12);
    EXPECT_NEAR(lens["projectionOffset"]["y"].get<double>(), -10 * 24.0 / 1920, 1e-12);
    EXPECT_EQ(lens["distortion"][0]["model"], "Brown-Conrady U-D");
    double f = 20.0;
    const auto& radial = lens["distortion"][0]["radial"];
    ASSERT_EQ(radial.size(), 5u);  // l1..l5; l6 (k6) is zero and left off
    EXPECT_NEAR(radial[0].get<double>(), -0.1 / (f * f), 1e-15);
    EXPECT_EQ(radial[1].get<double>(), 0.0);
    EXPECT_NEAR(radial[2].get<double>(), 0.02 / (f * f * f * f), 1e-15);
    EXPECT_NEAR(radial[4].get<double>(), 0.003 / std::pow(f, 6), 1e-18);
    EXPECT_NEAR(lens["distortion"][0]["tangential"][1].get<double>(), -0.002 / (f * f), 1e-15);
    EXPECT_FALSE(lens.contains("focusDistance"));  // unknown: left out, not 0
    EXPECT_EQ(a["static"]["camera"]["activeSensorResolution"]["width"], 1920);
}

TEST(OpenTrackIO, SamplePoseRoundTrips) {
    auto encoder = OpenTrackIOEncoder::create({});
    ASSERT_TRUE(encoder.ok());
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> a(-180, 180), tilt(-90, 90), t(-100, 100);
    for (int i = 0; i < 200; ++i) {
        OpenTrackIOFrame frame;
        frame.worldFromCamera = pose(a(rng), tilt(rng), a(rng), {t(rng), t(rng), t(rng)});
        auto back = worldFromOpenTrackIOSample(encoder->sampleJson(frame));
        ASSERT_TRUE(back.ok()) << back.message();
        EXPECT_LT(cv::norm(*back - frame.worldFromCamera), 1e-9);
    }
    EXPECT_FALSE(worldFromOpenTrackIOSample("{}").ok());
    EXPECT_FALSE(worldFromOpenTrackIOSample("not json").ok());
}

TEST(OpenTrackIO, EncodeFramesTheSampleAndCountsDatagrams) {
    auto encoder = OpenTrackIOEncoder::create({});
    ASSERT_TRUE(encoder.ok());
    OpenTrackIOFrame frame;
    frame.lens = pinholeLens();
    auto datagrams = encoder->encode(frame, 200);  // small segments: several datagrams
    ASSERT_GT(datagrams.size(), 1u);
    OtrkReassembler r;
    OtrkReassembler::Status status = OtrkReassembler::Status::Incomplete;
    for (const auto& d : datagrams) status = r.push(d);
    ASSERT_EQ(status, OtrkReassembler::Status::Complete);
    std::string text(r.payload().begin(), r.payload().end());
    EXPECT_TRUE(worldFromOpenTrackIOSample(text).ok());
    // The next frame's datagrams continue the header sequence.
    auto next = encoder->encode(frame, 200);
    EXPECT_EQ(readHeader(next[0]).sequence, readHeader(datagrams.back()).sequence + 1);
}

TEST(OpenTrackIO, BadSourceIsRefused) {
    EXPECT_FALSE(OpenTrackIOEncoder::create(sourceNumbered(0)).ok());
    EXPECT_FALSE(OpenTrackIOEncoder::create(sourceNumbered(201)).ok());
    OpenTrackIOSource badId;
    badId.sourceId = "urn:uuid:NOT-A-UUID";
    EXPECT_FALSE(OpenTrackIOEncoder::create(badId).ok());
}

}  // namespace
}  // namespace previs
