#pragma once

// SMPTE RIS OpenTrackIO (https://www.opentrackio.org, v1.0.1): one JSON sample per tracked frame,
// framed in UDP datagrams by the 16-byte "OTrk" header as the SMPTE reference sender
// (github.com/SMPTE/ris-osvp-metadata-camdkit, src/test/python/parser/opentrackio_sender.py)
// does. Fields, axes, units and framing: docs/opentrackio.md.
//
// Sending (per tracked frame, on the tracking thread):
//     auto encoder = OpenTrackIOEncoder::create(source);          // once
//     auto socket = UdpSocket::multicastSender(openTrackIOMulticastGroup(n), kOpenTrackIOPort);
//         // or, for out = "HOST:PORT": UdpSocket::sender("HOST:PORT")
//     for (auto& datagram : encoder->encode(frame)) socket->send(datagram);
// A lost pose sends nothing: do not call encode() with a stale pose.
//
// Receiving (tests, a monitor): OtrkReassembler::push() each datagram; on Complete, payload()
// holds one sample; Rejected says why in error() (count it, drop it).

#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "base/result.h"
#include "net/lens_sample.h"
#include "net/stage_pose.h"

namespace previs {

inline constexpr uint16_t kOpenTrackIOPort = 55555;
inline constexpr size_t kOtrkHeaderSize = 16;
// The reference sender's segment size: one Ethernet MTU (1500) less the header, so a segment is
// never IP-fragmented (a lost fragment loses the whole datagram).
inline constexpr size_t kOtrkMaxSegmentPayload = 1500 - kOtrkHeaderSize;
// The 15-bit payload length field's maximum.
inline constexpr size_t kOtrkMaxPayloadField = 0x7FFF;

enum class OtrkEncoding : uint8_t { Json = 0x01, Cbor = 0x02 };

// "239.135.1.N", the group the spec allots to source number N (1–200).
std::string openTrackIOMulticastGroup(uint8_t sourceNumber);

// Fletcher-16 with modulus 256, as the spec's reference code (not the usual 255).
uint16_t otrkFletcher16(std::span<const uint8_t> data);

struct OtrkTimecode {
    int hours = 0, minutes = 0, seconds = 0, frames = 0;
    uint32_t rateNum = 24, rateDenom = 1;  // e.g. 30000/1001 for "29.97"
    bool dropFrame = false;
};

// What one tracked frame sends.
struct OpenTrackIOFrame {
    cv::Matx44d worldFromCamera = cv::Matx44d::eye();  // OpenCV camera axes, our Y-up world
    uint64_t timestampNs = 0;  // capture instant, ns since the PTP/Unix epoch (CLOCK_REALTIME)
    std::optional<OtrkTimecode> timecode;
    // The rate samples are sent at, e.g. 24000/1001; num 0: not known yet, sampleRate left out.
    uint32_t sampleRateNum = 24, sampleRateDenom = 1;
    std::string trackerStatus = "Optical Good";  // free text, non-blank
    bool recording = false;
    std::optional<LensSample> lens;
};

// Who sends: fixed for a run.
struct OpenTrackIOSource {
    uint8_t sourceNumber = 1;  // 1–200
    std::string sourceId;      // "urn:uuid:…"; empty: a random one for this encoder
    std::string make = "previs", model = "previsd", serialNumber, firmwareVersion;
};

class OpenTrackIOEncoder {
public:
    static Result<OpenTrackIOEncoder> create(OpenTrackIOSource source);

    // The JSON sample for a frame (advances the sample sequence number). The pose must be
    // finite (a tracked pose always is).
    std::string sampleJson(const OpenTrackIOFrame& frame);
    // sampleJson() framed into datagrams of at most `maxSegmentPayload` payload bytes each.
    std::vector<std::vector<uint8_t>> encode(const OpenTrackIOFrame& frame,
                                             size_t maxSegmentPayload = kOtrkMaxSegmentPayload);

    const std::string& sourceId() const { return source_.sourceId; }

private:
    explicit OpenTrackIOEncoder(OpenTrackIOSource source);
    std::string randomUrnUuid();

    OpenTrackIOSource source_;
    std::mt19937_64 random_;
    uint32_t sampleSequence_ = 0;  // timing.sequenceNumber, one per sample
    uint16_t packetSequence_ = 0;  // header sequence number, one per datagram (reference sender)
};

// Frames one payload: segments of at most `maxSegmentPayload` (≤ 0x7FFF) bytes, each with its
// header, the last flagged; each datagram takes the next `sequence` number (wrapping at 2^16).
std::vector<std::vector<uint8_t>> frameOtrk(std::span<const uint8_t> payload, OtrkEncoding encoding,
                                            uint16_t& sequence,
                                            size_t maxSegmentPayload = kOtrkMaxSegmentPayload);

struct OtrkHeader {
    uint8_t encoding = 0;  // OtrkEncoding, or ≥ 0x80 vendor-specific
    uint16_t sequence = 0;
    uint32_t segmentOffset = 0;
    bool lastSegment = false;
    uint16_t payloadLength = 0;
    uint16_t checksum = 0;
};

enum class OtrkError {
    None,
    Truncated,      // shorter than the header or than the payload length it declares
    BadIdentifier,  // not "OTrk"
    WrongLength,    // more bytes than the header's payload length
    BadChecksum,
    OutOfOrder,  // a segment whose offset does not continue the payload being assembled
    Duplicate,   // the sequence number of the datagram just before it
    TooLarge,    // a segmented payload beyond the reassembler's limit
};
const char* otrkErrorName(OtrkError error);

struct OtrkSegment {
    OtrkError error = OtrkError::None;
    OtrkHeader header;
    std::span<const uint8_t> payload;  // into the datagram; valid only when error is None
};
OtrkSegment parseOtrkSegment(std::span<const uint8_t> datagram);

// Rebuilds payloads from datagrams in arrival order. A segment must continue the payload at the
// byte offset assembled so far; anything else drops the partial payload (the spec: a payload
// with a lost segment is discarded whole) and is rejected as OutOfOrder.
class OtrkReassembler {
public:
    enum class Status { Incomplete, Complete, Rejected };

    explicit OtrkReassembler(size_t maxPayload = 1 << 20) : maxPayload_(maxPayload) {}

    Status push(std::span<const uint8_t> datagram);
    OtrkError error() const { return error_; }
    // The complete payload after push() returned Complete.
    const std::vector<uint8_t>& payload() const { return payload_; }
    uint8_t encoding() const { return encoding_; }

private:
    Status reject(OtrkError error);

    size_t maxPayload_;
    std::vector<uint8_t> buffer_, payload_;
    bool assembling_ = false;
    bool haveLast_ = false;
    uint16_t lastSequence_ = 0;
    uint8_t encoding_ = 0;
    OtrkError error_ = OtrkError::None;
};

// The camera pose a JSON sample carries: its transforms composed in order (each translation,
// then pan/tilt/roll; scale ignored), mapped back to our world. An error names what is missing.
Result<cv::Matx44d> worldFromOpenTrackIOSample(std::string_view json);

}  // namespace previs
