#include "bench/bench_network.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <vector>

#include "base/log.h"
#include "bench/bench_progress.h"
#include "bench/bench_stats.h"
#include "net/freed.h"
#include "net/opentrackio.h"
#include "timecode/ltc_bench.h"
#include "timecode/timecode.h"

namespace previs::bench {

namespace {

double threadCpuSeconds() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return double(ts.tv_sec) + double(ts.tv_nsec) * 1e-9;
}

// A camera moving on an arc and turning: every packet encodes a different pose.
cv::Matx44d poseAt(int i) {
    const double a = 0.001 * i;
    const double c = std::cos(a), s = std::sin(a);
    return cv::Matx44d(c, 0, s, 1.5 * s, 0, 1, 0, 1.6, -s, 0, c, 3.0 * c, 0, 0, 0, 1);
}

// The demo's scene camera: 640×360, rad-tan with five coefficients.
LensSample demoLikeLens() {
    LensSample lens;
    lens.fxPx = lens.fyPx = 520.0;
    lens.cxPx = 320.0;
    lens.cyPx = 180.0;
    lens.widthPx = 640;
    lens.heightPx = 360;
    lens.distortion = {-0.12, 0.05, 0.0005, -0.0003, -0.01};
    return lens;
}

}  // namespace

int runLtcBench(bool quick) {
    const double seconds = quick ? 2.0 : 20.0;
    const int repeats = quick ? 1 : 5;
    const struct {
        const char* name;
        TimecodeRate rate;
    } rates[] = {{"24", TimecodeRate::fps24()},
                 {"25", TimecodeRate::fps25()},
                 {"29.97 DF", TimecodeRate::fps29_97Df()},
                 {"30", TimecodeRate::fps30()}};
    std::printf(
        "LTC decode (timecode/ltc_bench.h): libltc's encoder writes %.0f s of LTC at 48 kHz, the "
        "decoder reads it in 10 ms chunks with every check; CPU time of the thread, best of "
        "%d.\n\n",
        seconds, repeats);
    std::printf(
        "| rate | CPU per second of audio | real-time factor | %% of one core | frames "
        "decoded | rejected |\n|---|---|---|---|---|---|\n");
    for (const auto& r : rates) {
        benchProgress("ltc: {} fps", r.name);
        Result<LtcDecodeCost> cost = measureLtcDecodeCost(r.rate, 48000, seconds, repeats);
        if (!cost) {
            logError("bench ltc {}: {}", r.name, cost.message());
            return 1;
        }
        std::printf("| %s | %.0f µs | %.0f× | %.3f %% | %llu | %llu |\n", r.name,
                    cost->usPerAudioSecond, cost->realTimeFactor, cost->usPerAudioSecond * 1e-4,
                    static_cast<unsigned long long>(cost->framesDecoded),
                    static_cast<unsigned long long>(cost->rejected));
        std::fflush(stdout);
    }
    std::printf("\n");
    return 0;
}

int runNetworkEncodeBench(bool quick) {
    const int packets = quick ? 2000 : 50000;
    const int repeats = quick ? 1 : 5;
    const LensSample lens = demoLikeLens();
    std::printf(
        "One tracked frame's packets, encoded (the sockets' send not included): %d packets a run, "
        "CPU time of the thread per packet, median and best of %d runs.\n\n",
        packets, repeats);
    std::printf(
        "| packet | bytes | datagrams | µs per packet (median) | best | packets per "
        "second of one core |\n|---|---|---|---|---|---|\n");

    // FreeD D1: pose and lens to 29 bytes with the checksum.
    {
        benchProgress("network: FreeD");
        std::vector<double> us;
        unsigned sink = 0;
        for (int r = 0; r < repeats; ++r) {
            const double start = threadCpuSeconds();
            for (int i = 0; i < packets; ++i)
                sink += encodeFreed(poseAt(i), lens, 1).bytes[kFreedPacketSize - 1];
            us.push_back((threadCpuSeconds() - start) / packets * 1e6);
        }
        const double med = median(us);
        std::printf("| FreeD D1 (`encodeFreed`) | %zu | 1 | %.3f | %.3f | %.0f |\n",
                    kFreedPacketSize, med, *std::min_element(us.begin(), us.end()), 1e6 / med);
        volatile unsigned keep = sink;  // the loop's result is used
        (void)keep;
    }

    // OpenTrackIO: the JSON sample (pose, timecode, lens with distortion) and its OTrk framing,
    // as daemon/tracking_out.cpp fills it.
    {
        benchProgress("network: OpenTrackIO");
        Result<OpenTrackIOEncoder> encoder = OpenTrackIOEncoder::create({});
        if (!encoder) {
            logError("bench network: {}", encoder.message());
            return 1;
        }
        const TimecodeRate rate = TimecodeRate::fps25();
        OpenTrackIOFrame frame;
        frame.sampleRateNum = 25;
        frame.sampleRateDenom = 1;
        frame.lens = lens;
        frame.timecode = OtrkTimecode{10, 0, 0, 0, 25, 1, false};
        std::vector<double> us;
        size_t bytes = 0, datagrams = 0;
        for (int r = 0; r < repeats; ++r) {
            const double start = threadCpuSeconds();
            for (int i = 0; i < packets; ++i) {
                frame.worldFromCamera = poseAt(i);
                frame.timestampNs = 1'800'000'000'000'000'000ull + uint64_t(i) * 40'000'000ull;
                const Timecode tc = Timecode::fromFrameCount(i, rate);
                frame.timecode->seconds = tc.seconds();
                frame.timecode->frames = tc.frames();
                std::vector<std::vector<uint8_t>> out = encoder->encode(frame);
                datagrams = out.size();
                bytes = 0;
                for (const auto& d : out) bytes += d.size();
            }
            us.push_back((threadCpuSeconds() - start) / packets * 1e6);
        }
        const double med = median(us);
        std::printf(
            "| OpenTrackIO sample, JSON + OTrk header (`OpenTrackIOEncoder::encode`) | %zu | %zu | "
            "%.3f | %.3f | %.0f |\n",
            bytes, datagrams, med, *std::min_element(us.begin(), us.end()), 1e6 / med);
    }
    std::printf("\n");
    return 0;
}

}  // namespace previs::bench
