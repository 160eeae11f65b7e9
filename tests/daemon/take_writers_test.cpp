// Issue 52, the take recorder's writing: a FreeD flood on loopback against the real FreeD input
// and recorder is bounded (only the configured tracker's valid packets are recorded, at most
// TakeRecorder::kFreedRecordHz, the rest counted) and `record stop` returns at once; and what the
// writer wrote before a quiet spell is made durable within flush_interval_ms, not at the next
// write. Issue 55: the rate a take's labels count at follows the one rule (LabelRateRule).

#include <arpa/inet.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "base/unique_fd.h"
#include "config/service_config.h"
#include "daemon/service.h"
#include "net/freed.h"
#include "net/freed_calibration.h"
#include "shot/freed_input.h"
#include "take/take_recorder.h"
#include "tests/daemon/recorder_fixtures.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"
#include "timecode/timecode.h"

namespace previs {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using testing::HangGuard;
using testing::recorderConfig;

// A bound loopback UDP socket, as systemd would pass it, and its port.
UniqueFD loopbackReceiver(uint16_t& port) {
    UniqueFD fd(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    socklen_t size = sizeof(addr);
    if (!fd.isValid() || ::bind(fd.get(), reinterpret_cast<sockaddr*>(&addr), size) != 0 ||
        ::getsockname(fd.get(), reinterpret_cast<sockaddr*>(&addr), &size) != 0)
        return {};
    port = ntohs(addr.sin_port);
    return fd;
}

TEST(FreedFlood, OnlyTheTrackersValidPacketsAreRecordedWithinABoundAndDropsAreCounted) {
    HangGuard guard("a FreeD flood and record stop", std::chrono::seconds(120));
    ServiceConfig config = recorderConfig("flood");
    config.record.queueMb = 16;  // the smallest budget allowed
    TakeRecorder recorder(config);
    Result<std::string> take = recorder.start("flood");
    ASSERT_TRUE(take) << take.message();

    uint16_t port = 0;
    UniqueFD passed = loopbackReceiver(port);
    ASSERT_TRUE(passed.isValid()) << std::strerror(errno);
    TrackingConfig tracking = config.tracking;
    tracking.freedCameraId = 2;
    auto input = FreedInput::listen(tracking, std::move(passed),
                                    [&](int64_t receivedNs, std::span<const uint8_t> datagram) {
                                        recorder.addFreedPacket(receivedNs, datagram);
                                    });
    ASSERT_TRUE(input) << input.message();

    // The flood: the tracker's own packets as fast as loopback takes them, mixed with another
    // camera's, broken checksums and short datagrams.
    UniqueFD out(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0));
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    to.sin_port = htons(port);
    ASSERT_EQ(::connect(out.get(), reinterpret_cast<sockaddr*>(&to), sizeof(to)), 0);
    const FreedBytes good = encodeFreed(FreedPacket{.cameraId = 2, .panDeg = 10}).bytes;
    FreedBytes badSum = good;
    badSum[28] ^= 0x5a;
    const FreedBytes otherCamera = encodeFreed(FreedPacket{.cameraId = 3}).bytes;
    const std::vector<const uint8_t*> kinds = {good.data(), badSum.data(), otherCamera.data()};
    const auto floodEnd = std::chrono::steady_clock::now() + 1500ms;
    uint64_t sent = 0;
    while (std::chrono::steady_clock::now() < floodEnd) {
        for (int i = 0; i < 64; ++i, ++sent) {
            // Errors (a full socket buffer) are part of a flood: the next one goes on.
            [[maybe_unused]] ssize_t n =
                sent % 4 == 3 ? ::send(out.get(), good.data(), 20, MSG_DONTWAIT)
                              : ::send(out.get(), kinds[sent % 4], good.size(), MSG_DONTWAIT);
        }
    }
    std::this_thread::sleep_for(100ms);  // what is in the socket's buffer arrives
    // The input first: every packet it accepted went to a rolling take.
    (*input)->stop();
    const FreedInputStats stats = (*input)->stats();
    const auto stopStart = std::chrono::steady_clock::now();
    Result<std::string> stopped = recorder.stop();
    const double stopSeconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - stopStart).count();
    ASSERT_TRUE(stopped) << stopped.message();

    ASSERT_GT(stats.packets, uint64_t(3 * TakeRecorder::kFreedBurst))
        << "the flood reached the input (" << sent << " sent)";
    const fs::path csv = fs::path(*take) / "freed.csv";
    Result<FreedRecording> recorded = loadFreedRecording(csv.string(), 2);
    ASSERT_TRUE(recorded) << recorded.message();
    EXPECT_EQ(recorded->rejected, 0u) << "a refused datagram is never recorded";
    EXPECT_EQ(recorded->cameraIds, std::vector<uint8_t>{2}) << "nor another camera's";
    const std::vector<TimedPose>& poses = recorded->stageFromBody;
    ASSERT_FALSE(poses.empty());
    // The token bucket's own bound, on the packets' receipt times (no wall clock involved).
    const double spanS = double(poses.back().timestampNs - poses.front().timestampNs) * 1e-9;
    EXPECT_LE(double(poses.size()),
              TakeRecorder::kFreedRecordHz * spanS + TakeRecorder::kFreedBurst + 1)
        << poses.size() << " packets recorded over " << spanS << " s";
    EXPECT_LE(fs::file_size(csv), uint64_t(100) * (poses.size() + 1)) << "about 80 bytes a line";
    // Every valid packet is recorded or counted, none left waiting in memory.
    const RecordStatus after = recorder.status();
    EXPECT_GT(after.freedDropped, 0u);
    EXPECT_EQ(poses.size() + after.freedDropped, stats.packets);
    EXPECT_LT(stopSeconds, 30.0) << "a hang guard only: the drain is a few hundred lines";
    EXPECT_EQ(after.dropped, 0u) << "no frame was crowded out";
}

// cachestat(2) (Linux 6.5): the pages of a file not yet written back; its number is the same on
// every architecture (the generic syscall table), and older headers do not name it.
struct CacheStat {
    uint64_t cache, dirty, writeback, evicted, recentlyEvicted;
};
std::optional<uint64_t> unsyncedPages(const fs::path& file) {
    UniqueFD fd(::open(file.c_str(), O_RDONLY | O_CLOEXEC));
    if (!fd.isValid()) return std::nullopt;
    struct {
        uint64_t offset = 0, length = 0;  // the whole file
    } range;
    CacheStat stat{};
    constexpr long kCachestat = 451;
    if (::syscall(kCachestat, fd.get(), &range, &stat, 0) != 0) return std::nullopt;
    return stat.dirty + stat.writeback;
}

TEST(TakeWriter, WhatCameBeforeAQuietSpellIsMadeDurableWithoutAnotherWrite) {
    HangGuard guard("an idle take", std::chrono::seconds(60));
    ServiceConfig config = recorderConfig("idle");
    config.record.flushIntervalMs = 1000;
    TakeRecorder recorder(config);
    Result<std::string> take = recorder.start("idle");
    ASSERT_TRUE(take) << take.message();
    const fs::path events = fs::path(*take) / "events.csv";
    // The first line is synced as it comes (the last sync is older than the interval); the
    // ones right after it wait for the interval to pass.
    for (int i = 0; i < 3; ++i) recorder.addEvent({uint64_t(100 + i), "ctl", "mode=refine"});
    const auto deadline = std::chrono::steady_clock::now() + 5s;
    while (!fs::exists(events) && std::chrono::steady_clock::now() < deadline)
        std::this_thread::sleep_for(10ms);
    ASSERT_TRUE(fs::exists(events));
    if (!unsyncedPages(events)) GTEST_SKIP() << "no cachestat(2) here (Linux 6.5 or later)";
    // Nothing more is written: within the interval (plus a loaded machine's margin) the lines
    // must be on the disk. Without the idle flush they wait for the kernel's writeback (30 s).
    std::optional<uint64_t> pages;
    while ((pages = unsyncedPages(events)).value_or(1) != 0 &&
           std::chrono::steady_clock::now() < deadline + 5s)
        std::this_thread::sleep_for(50ms);
    EXPECT_EQ(pages, std::optional<uint64_t>(0)) << "events.csv still unsynced after ~10 s idle";
    ASSERT_TRUE(recorder.stop());
}

// Issue 54 part 6: the monitor page shows REC with the take's duration, so the status says how
// long the take has rolled (wall time: a sleep is a lower bound however loaded the machine is).
TEST(TakeRecorder, TheStatusSaysHowLongTheTakeHasRolled) {
    HangGuard guard("a take's duration", std::chrono::seconds(60));
    TakeRecorder recorder(recorderConfig("duration"));
    Result<std::string> take = recorder.start("duration");
    ASSERT_TRUE(take) << take.message();
    std::this_thread::sleep_for(300ms);
    ServiceStatus s;
    s.record = recorder.status();
    EXPECT_GE(s.record.seconds, 0.3);
    EXPECT_LT(s.record.seconds, 60.0);
    const nlohmann::json j = nlohmann::json::parse(statusJson(s));
    EXPECT_GE(j["record"]["seconds"].get<double>(), 0.3);
    ASSERT_TRUE(recorder.stop());
}

// `frames` 8x8 scene frames at `fps` (wall clock set) recorded under `config` with no timecode
// source (the recorder labels them itself); the take's scene index.
std::vector<RecordedFrameEntry> recordSceneFrames(const ServiceConfig& config, double fps,
                                                  int frames) {
    TakeRecorder recorder(config);
    Result<std::string> take = recorder.start("");
    EXPECT_TRUE(take) << take.message();
    if (!take) return {};
    for (int n = 0; n < frames; ++n) {
        auto frame = std::make_shared<Frame>();
        frame->width = 8;
        frame->height = 8;
        frame->rgb.assign(8 * 8 * 3, uint8_t(n));
        frame->timestampNs = 1'000'000'000 + uint64_t(std::llround(n * 1e9 / fps));
        frame->sequence = uint64_t(n);
        frame->wallClockNs = 1'796'551'200'000'000'000ull + frame->timestampNs;
        recorder.addFrame("scene", frame);
    }
    EXPECT_TRUE(recorder.stop());
    Result<std::vector<RecordedFrameEntry>> index =
        loadCameraIndex((fs::path(*take) / "cameras" / "scene").string());
    EXPECT_TRUE(index) << index.message();
    return index ? *index : std::vector<RecordedFrameEntry>{};
}

// The rates a take's index holds, one entry per distinct rate.
std::set<std::string> recordedRates(const std::vector<RecordedFrameEntry>& index) {
    std::set<std::string> rates;
    for (const RecordedFrameEntry& e : index) rates.insert(e.timecodeRate);
    return rates;
}

// Issue 55: a take recorded with [timecode] rate set and no LTC source counts its labels at that
// rate (the recorder measured the camera instead), and the export reads that rate back, from the
// column and, for a take without it, from the same rule.
TEST(TakeRecorder, ATakesLabelsCountAtTheConfiguredTimecodeRate) {
    HangGuard guard("a take at [timecode] rate", std::chrono::seconds(60));
    ServiceConfig config = recorderConfig("timecode_rate");
    ASSERT_EQ(config.sceneCamera.fps, 0.0) << "the demo's scene camera names no fps";
    config.network.timecode.rate = "25";
    const std::vector<RecordedFrameEntry> index = recordSceneFrames(config, 30.0, 6);
    ASSERT_EQ(index.size(), 6u);
    EXPECT_EQ(recordedRates(index), std::set<std::string>{"25"});
    Result<LabelRateRule> rule = labelRateRule(config, config.sceneCamera);
    ASSERT_TRUE(rule) << rule.message();
    for (const RecordedFrameEntry& e : index) {
        EXPECT_TRUE(Timecode::parse(e.timecode, TimecodeRate::fps25())) << e.timecode;
        EXPECT_EQ(labelRate(e.timecode, e.timecodeRate, *rule), TimecodeRate::fps25());
        EXPECT_EQ(labelRate(e.timecode, "", *rule), TimecodeRate::fps25())
            << "a reader without the column takes the rate the recorder used";
    }
}

// Without [timecode] rate the recorder keeps its rule: the camera's fps, else its rate measured
// on its first two frames (a 15 fps camera counts at 30), else 30 for a lone frame.
TEST(TakeRecorder, WithoutATimecodeRateLabelsCountAtTheCamerasRate) {
    HangGuard guard("takes at the camera's rate", std::chrono::seconds(60));
    ServiceConfig config = recorderConfig("camera_rate");
    EXPECT_EQ(recordedRates(recordSceneFrames(config, 25.0, 4)), std::set<std::string>{"25"});
    EXPECT_EQ(recordedRates(recordSceneFrames(config, 15.0, 4)), std::set<std::string>{"30"});
    EXPECT_EQ(recordedRates(recordSceneFrames(config, 25.0, 1)), std::set<std::string>{"30"});
    config.sceneCamera.fps = 24.0;
    EXPECT_EQ(recordedRates(recordSceneFrames(config, 30.0, 4)), std::set<std::string>{"24"});
}

}  // namespace
}  // namespace previs
