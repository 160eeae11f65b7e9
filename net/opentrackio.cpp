#include "net/opentrackio.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>

#include "base/log.h"

namespace previs {

namespace {

using nlohmann::json;

constexpr uint8_t kIdentifier[4] = {'O', 'T', 'r', 'k'};
constexpr uint16_t kLastSegmentBit = 0x8000;

void putU16(uint8_t* p, uint16_t v) {
    p[0] = uint8_t(v >> 8);
    p[1] = uint8_t(v);
}
void putU32(uint8_t* p, uint32_t v) {
    putU16(p, uint16_t(v >> 16));
    putU16(p + 2, uint16_t(v));
}
uint16_t getU16(const uint8_t* p) { return uint16_t(p[0] << 8 | p[1]); }
uint32_t getU32(const uint8_t* p) { return uint32_t(getU16(p)) << 16 | getU16(p + 2); }

// The checksum covers the header's first 14 bytes and then the payload.
uint16_t segmentChecksum(std::span<const uint8_t> header14, std::span<const uint8_t> payload) {
    uint8_t sum1 = 0, sum2 = 0;
    for (auto part : {header14, payload}) {
        for (uint8_t b : part) {
            sum1 = uint8_t(sum1 + b);
            sum2 = uint8_t(sum2 + sum1);
        }
    }
    return uint16_t(sum2 << 8 | sum1);
}

json rational(uint32_t num, uint32_t denom) { return {{"num", num}, {"denom", denom}}; }

json transformJson(const StagePose& pose) {
    return {
        {"id", "Camera"},
        {"translation",
         {{"x", pose.translationM[0]}, {"y", pose.translationM[1]}, {"z", pose.translationM[2]}}},
        {"rotation", {{"pan", pose.panDeg}, {"tilt", pose.tiltDeg}, {"roll", pose.rollDeg}}}};
}

json timingJson(const OpenTrackIOFrame& frame, uint32_t sequence) {
    json timing = {// UDP has no timing of its own: the sample carries its timestamp ("internal").
                   {"mode", "internal"},
                   {"sampleTimestamp",
                    {{"seconds", frame.timestampNs / 1'000'000'000u},
                     {"nanoseconds", frame.timestampNs % 1'000'000'000u}}},
                   {"sequenceNumber", sequence}};
    if (frame.sampleRateNum > 0)
        timing["sampleRate"] = rational(frame.sampleRateNum, std::max(frame.sampleRateDenom, 1u));
    if (frame.timecode) {
        const OtrkTimecode& tc = *frame.timecode;
        timing["timecode"] = {
            {"hours", tc.hours},
            {"minutes", tc.minutes},
            {"seconds", tc.seconds},
            {"frames", tc.frames},
            {"frameRate", rational(std::max(tc.rateNum, 1u), std::max(tc.rateDenom, 1u))},
            {"dropFrame", tc.dropFrame}};
    }
    return timing;
}

// OpenCV radial-tangential (undistorted → distorted, normalised coordinates) to OpenTrackIO's
// Brown-Conrady U-D on millimetre coordinates, by SMPTE's note "Conversion of OpenCV to
// OpenTrackIO (OpenLensIO) lens calibration parameters" (camdkit, 2025-09-02): radial
// l1..l6 = k1/F², k4/F², k2/F⁴, k5/F⁴, k3/F⁶, k6/F⁶ (odd l in the numerator, even in the
// denominator), tangential q1, q2 = p1/F², p2/F², F the focal length in mm.
json distortionJson(const LensSample& lens, double focalMm) {
    const std::vector<double>& d = lens.distortion;
    auto k = [&](size_t i) { return i < d.size() ? d[i] : 0.0; };
    double f2 = focalMm * focalMm, f4 = f2 * f2, f6 = f4 * f2;
    std::vector<double> radial = {k(0) / f2, k(5) / f2, k(1) / f4, k(6) / f4, k(4) / f6, k(7) / f6};
    while (radial.size() > 1 && radial.back() == 0.0) radial.pop_back();
    return json::array({{{"model", "Brown-Conrady U-D"},
                         {"radial", radial},
                         {"tangential", {k(2) / f2, k(3) / f2}}}});
}

json lensJson(const LensSample& lens) {
    double focalMm = lens.focalLengthMm();
    double pixelHeightMm = focalMm / lens.fyPx;  // fx·pw = fy·ph = F
    json out = {{"pinholeFocalLength", focalMm},
                {"projectionOffset",
                 {{"x", (lens.cxPx - lens.widthPx / 2.0) * lens.mmPerPx()},
                  {"y", (lens.cyPx - lens.heightPx / 2.0) * pixelHeightMm}}}};
    if (!lens.fisheye && !lens.distortion.empty())
        out["distortion"] = distortionJson(lens, focalMm);
    if (lens.focusDistanceM > 0) out["focusDistance"] = lens.focusDistanceM;
    return out;
}

json staticJson(const OpenTrackIOSource& source, const std::optional<LensSample>& lens) {
    json tracker = json::object();
    auto put = [&](const char* key, const std::string& value) {
        if (!value.empty()) tracker[key] = value;  // the schema wants non-blank strings
    };
    put("make", source.make);
    put("model", source.model);
    put("serialNumber", source.serialNumber);
    put("firmwareVersion", source.firmwareVersion);
    json out = {{"tracker", tracker}};
    if (lens && lens->valid()) {
        out["camera"] = {
            {"activeSensorPhysicalDimensions",
             {{"width", lens->sensorWidthMm},
              {"height", lens->heightPx * lens->focalLengthMm() / lens->fyPx}}},
            {"activeSensorResolution", {{"width", lens->widthPx}, {"height", lens->heightPx}}}};
    }
    return out;
}

bool validUrnUuid(const std::string& id) {
    static constexpr std::string_view kPrefix = "urn:uuid:";
    if (id.size() != kPrefix.size() + 36 || id.compare(0, kPrefix.size(), kPrefix) != 0) {
        return false;
    }
    for (size_t i = 0; i < 36; ++i) {
        char c = id[kPrefix.size() + i];
        bool dash = i == 8 || i == 13 || i == 18 || i == 23;
        if (dash ? c != '-' : !((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
    }
    return true;
}

}  // namespace

std::string openTrackIOMulticastGroup(uint8_t sourceNumber) {
    return fmt::format("239.135.1.{}", sourceNumber);
}

uint16_t otrkFletcher16(std::span<const uint8_t> data) { return segmentChecksum({}, data); }

Result<OpenTrackIOEncoder> OpenTrackIOEncoder::create(OpenTrackIOSource source) {
    if (source.sourceNumber < 1 || source.sourceNumber > 200) {
        return makeError(
            "[opentrackio] source number {}: must be 1 to 200 (the spec reserves the "
            "rest)",
            source.sourceNumber);
    }
    if (!source.sourceId.empty() && !validUrnUuid(source.sourceId)) {
        return makeError("[opentrackio] source id '{}': must be urn:uuid: and a lower-case UUID",
                         source.sourceId);
    }
    OpenTrackIOEncoder encoder(std::move(source));
    if (encoder.source_.sourceId.empty()) encoder.source_.sourceId = encoder.randomUrnUuid();
    return encoder;
}

OpenTrackIOEncoder::OpenTrackIOEncoder(OpenTrackIOSource source)
    : source_(std::move(source)), random_(std::random_device{}()) {}

// A version-4 (random) UUID, RFC 9562.
std::string OpenTrackIOEncoder::randomUrnUuid() {
    uint64_t hi = random_(), lo = random_();
    hi = (hi & ~0xF000ull) | 0x4000ull;                  // version 4
    lo = (lo & ~(0xC000ull << 48)) | (0x8000ull << 48);  // variant 10
    return fmt::format("urn:uuid:{:08x}-{:04x}-{:04x}-{:04x}-{:012x}", hi >> 32,
                       (hi >> 16) & 0xFFFF, hi & 0xFFFF, lo >> 48, lo & 0xFFFFFFFFFFFFull);
}

std::string OpenTrackIOEncoder::sampleJson(const OpenTrackIOFrame& frame) {
    // A tracked pose is finite; NaN would be written as null and fail the schema.
    PV_DCHECK(cv::checkRange(frame.worldFromCamera));
    StagePose pose = stagePoseFromWorld(frame.worldFromCamera);
    json sample = {{"protocol", {{"name", "OpenTrackIO"}, {"version", {1, 0, 1}}}},
                   {"sampleId", randomUrnUuid()},
                   {"sourceId", source_.sourceId},
                   {"sourceNumber", source_.sourceNumber},
                   {"timing", timingJson(frame, sampleSequence_++)},
                   {"transforms", json::array({transformJson(pose)})},
                   {"static", staticJson(source_, frame.lens)}};
    json tracker = {{"recording", frame.recording}};
    if (!frame.trackerStatus.empty()) tracker["status"] = frame.trackerStatus;
    sample["tracker"] = tracker;
    if (frame.lens && frame.lens->valid()) sample["lens"] = lensJson(*frame.lens);
    return sample.dump();
}

std::vector<std::vector<uint8_t>> OpenTrackIOEncoder::encode(const OpenTrackIOFrame& frame,
                                                             size_t maxSegmentPayload) {
    std::string text = sampleJson(frame);
    auto bytes = std::span(reinterpret_cast<const uint8_t*>(text.data()), text.size());
    return frameOtrk(bytes, OtrkEncoding::Json, packetSequence_, maxSegmentPayload);
}

std::vector<std::vector<uint8_t>> frameOtrk(std::span<const uint8_t> payload, OtrkEncoding encoding,
                                            uint16_t& sequence, size_t maxSegmentPayload) {
    size_t step = std::clamp<size_t>(maxSegmentPayload, 1, kOtrkMaxPayloadField);
    std::vector<std::vector<uint8_t>> datagrams;
    size_t offset = 0;
    do {
        size_t length = std::min(step, payload.size() - offset);
        bool last = offset + length >= payload.size();
        std::vector<uint8_t> d(kOtrkHeaderSize + length);
        std::copy(std::begin(kIdentifier), std::end(kIdentifier), d.begin());
        d[4] = 0;  // reserved
        d[5] = uint8_t(encoding);
        putU16(&d[6], sequence++);
        putU32(&d[8], uint32_t(offset));
        putU16(&d[12], uint16_t((last ? kLastSegmentBit : 0) | length));
        std::copy_n(payload.begin() + offset, length, d.begin() + kOtrkHeaderSize);
        putU16(&d[14], segmentChecksum(std::span(d).first(14), payload.subspan(offset, length)));
        datagrams.push_back(std::move(d));
        offset += length;
    } while (offset < payload.size());
    return datagrams;
}

const char* otrkErrorName(OtrkError error) {
    switch (error) {
        case OtrkError::None:
            return "none";
        case OtrkError::Truncated:
            return "truncated";
        case OtrkError::BadIdentifier:
            return "bad_identifier";
        case OtrkError::WrongLength:
            return "wrong_length";
        case OtrkError::BadChecksum:
            return "bad_checksum";
        case OtrkError::OutOfOrder:
            return "out_of_order";
        case OtrkError::Duplicate:
            return "duplicate";
        case OtrkError::TooLarge:
            return "too_large";
    }
    return "unknown";
}

OtrkSegment parseOtrkSegment(std::span<const uint8_t> datagram) {
    OtrkSegment s;
    if (datagram.size() < kOtrkHeaderSize) {
        s.error = OtrkError::Truncated;
        return s;
    }
    const uint8_t* d = datagram.data();
    if (!std::equal(std::begin(kIdentifier), std::end(kIdentifier), d)) {
        s.error = OtrkError::BadIdentifier;
        return s;
    }
    OtrkHeader& h = s.header;
    h.encoding = d[5];
    h.sequence = getU16(d + 6);
    h.segmentOffset = getU32(d + 8);
    uint16_t flagAndLength = getU16(d + 12);
    h.lastSegment = (flagAndLength & kLastSegmentBit) != 0;
    h.payloadLength = flagAndLength & uint16_t(~kLastSegmentBit);
    h.checksum = getU16(d + 14);
    size_t available = datagram.size() - kOtrkHeaderSize;
    if (available < h.payloadLength) {
        s.error = OtrkError::Truncated;
    } else if (available > h.payloadLength) {
        s.error = OtrkError::WrongLength;
    } else if (segmentChecksum(datagram.first(14), datagram.subspan(kOtrkHeaderSize)) !=
               h.checksum) {
        s.error = OtrkError::BadChecksum;
    } else {
        s.payload = datagram.subspan(kOtrkHeaderSize);
    }
    return s;
}

OtrkReassembler::Status OtrkReassembler::reject(OtrkError error) {
    error_ = error;
    buffer_.clear();
    assembling_ = false;
    return Status::Rejected;
}

OtrkReassembler::Status OtrkReassembler::push(std::span<const uint8_t> datagram) {
    OtrkSegment s = parseOtrkSegment(datagram);
    // A damaged datagram leaves a payload in progress alone: its own segment may follow intact
    // only if the sender repeats it, which it does not, but the next payload starts clean.
    if (s.error != OtrkError::None) return reject(s.error);
    if (haveLast_ && s.header.sequence == lastSequence_) {
        error_ = OtrkError::Duplicate;
        return Status::Rejected;
    }
    haveLast_ = true;
    lastSequence_ = s.header.sequence;
    if (s.header.segmentOffset == 0) {
        buffer_.clear();  // a new payload; an unfinished one before it lost its tail
        assembling_ = true;
        encoding_ = s.header.encoding;
    } else if (!assembling_ || s.header.segmentOffset != buffer_.size() ||
               s.header.encoding != encoding_) {
        return reject(OtrkError::OutOfOrder);
    }
    if (buffer_.size() + s.payload.size() > maxPayload_) return reject(OtrkError::TooLarge);
    buffer_.insert(buffer_.end(), s.payload.begin(), s.payload.end());
    error_ = OtrkError::None;
    if (!s.header.lastSegment) return Status::Incomplete;
    payload_.swap(buffer_);
    buffer_.clear();
    assembling_ = false;
    return Status::Complete;
}

Result<cv::Matx44d> worldFromOpenTrackIOSample(std::string_view text) {
    json sample = json::parse(text, nullptr, false);
    if (sample.is_discarded() || !sample.is_object()) {
        return makeError("OpenTrackIO sample: not a JSON object");
    }
    auto transforms = sample.find("transforms");
    if (transforms == sample.end() || !transforms->is_array() || transforms->empty()) {
        return makeError("OpenTrackIO sample: no transforms");
    }
    // Stage-from-camera-body as a 4×4, composed parent first.
    cv::Matx44d stageFromBody = cv::Matx44d::eye();
    for (const json& t : *transforms) {
        auto num = [&](const char* object, const char* key) -> std::optional<double> {
            auto o = t.find(object);
            if (o == t.end() || !o->is_object()) return std::nullopt;
            auto v = o->find(key);
            if (v == o->end() || !v->is_number()) return std::nullopt;
            return v->get<double>();
        };
        auto x = num("translation", "x"), y = num("translation", "y"), z = num("translation", "z");
        auto pan = num("rotation", "pan"), tilt = num("rotation", "tilt");
        auto roll = num("rotation", "roll");
        if (!x || !y || !z || !pan || !tilt || !roll) {
            return makeError(
                "OpenTrackIO sample: a transform lacks translation x/y/z or rotation "
                "pan/tilt/roll");
        }
        cv::Matx33d r = stageRotation(*pan, *tilt, *roll);
        cv::Matx44d m(r(0, 0), r(0, 1), r(0, 2), *x, r(1, 0), r(1, 1), r(1, 2), *y, r(2, 0),
                      r(2, 1), r(2, 2), *z, 0, 0, 0, 1);
        stageFromBody = stageFromBody * m;
    }
    cv::Matx33d r(stageFromBody(0, 0), stageFromBody(0, 1), stageFromBody(0, 2),
                  stageFromBody(1, 0), stageFromBody(1, 1), stageFromBody(1, 2),
                  stageFromBody(2, 0), stageFromBody(2, 1), stageFromBody(2, 2));
    return worldFromStage(r,
                          cv::Vec3d(stageFromBody(0, 3), stageFromBody(1, 3), stageFromBody(2, 3)));
}

}  // namespace previs
