// Writes OpenTrackIO samples from the encoder, one JSON object a line, for the schema test
// (validate_opentrackio.py): poses, timecodes and lenses of every kind the encoder handles.

#include <cstdio>
#include <random>

#include "net/opentrackio.h"

namespace {

previs::LensSample lensVariant(int i) {
    previs::LensSample lens;
    lens.widthPx = 1920;
    lens.heightPx = 1080;
    lens.fxPx = 1400 + 10 * i;
    lens.fyPx = 1400 + 10 * i + (i % 3);
    lens.cxPx = 955 + i % 11;
    lens.cyPx = 545 - i % 7;
    switch (i % 5) {
        case 0:
            break;  // no distortion
        case 1:
            lens.distortion = {-0.12, 0.03, 0.0005, -0.0007};
            break;
        case 2:
            lens.distortion = {-0.12, 0.03, 0.0005, -0.0007, 0.001};
            lens.sensorWidthMm = 24.89;
            lens.focusDistanceM = 3.2;
            break;
        case 3:
            lens.distortion = {-0.1, 0.02, 0, 0, 0.001, 0.05, 0.01, 0.002};  // rational
            break;
        default:
            lens.fisheye = true;
            lens.distortion = {0.01, -0.002, 0.0003, 0};
            break;
    }
    return lens;
}

}  // namespace

int main() {
    auto encoder = previs::OpenTrackIOEncoder::create({.sourceNumber = 7,
                                                       .sourceId = "",
                                                       .make = "previs",
                                                       .model = "previsd",
                                                       .serialNumber = "test-0001",
                                                       .firmwareVersion = "0.0"});
    if (!encoder) {
        std::fprintf(stderr, "%s\n", encoder.message().c_str());
        return 1;
    }
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> angle(-180, 180), tilt(-90, 90), t(-130, 130);
    for (int i = 0; i < 60; ++i) {
        previs::OpenTrackIOFrame frame;
        frame.worldFromCamera = previs::worldFromStagePose(
            {{t(rng), t(rng), t(rng)}, angle(rng), i % 10 == 0 ? 90.0 : tilt(rng), angle(rng)});
        frame.timestampNs = 1'765'000'000'000'000'000ull + uint64_t(i) * 41'708'333ull;
        if (i % 4 != 0) {
            bool drop = i % 2 == 1;
            frame.timecode = previs::OtrkTimecode{
                23, 59, 59, drop ? 29 : 23, drop ? 30000u : 24u, drop ? 1001u : 1u, drop};
        }
        frame.sampleRateNum = 24000;
        frame.sampleRateDenom = 1001;
        frame.recording = i % 2 == 0;
        if (i % 6 != 5) frame.lens = lensVariant(i);
        std::printf("%s\n", encoder->sampleJson(frame).c_str());
    }
    return 0;
}
