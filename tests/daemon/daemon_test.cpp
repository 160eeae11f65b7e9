// Host tests of the service's pieces that need no GPU: the mode machine, the control socket,
// the status JSON contract (DESIGN.md §3) and the camera-convention conversions.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <thread>

#include "config/service_config.h"
#include "daemon/control_server.h"
#include "daemon/memory_budget.h"
#include "daemon/network_dropin.h"
#include "daemon/service.h"
#include "io/session.h"
#include "scene/scene.h"
#include "shot/mode_machine.h"
#include "shot/pipeline_stages.h"
#include "take/recorded_events.h"
#include "take/take_recorder.h"
#include "tests/daemon/recorder_fixtures.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"
#include "vision/lens_grid.h"

namespace previs {
namespace {

namespace fs = std::filesystem;
using testing::HangGuard;
using testing::recorderConfig;

std::string socketPath(const std::string& name) {
    return (testing::scratchDir("previs_daemon_test") / name).string();
}

TEST(ModeMachine, ToggleAndSetCountEveryChange) {
    ModeMachine m;
    EXPECT_EQ(m.mode(), Mode::Preview);
    EXPECT_EQ(m.toggle("test"), Mode::Refine);
    EXPECT_EQ(m.toggle("test"), Mode::Preview);
    EXPECT_EQ(m.version(), 2u);
    EXPECT_EQ(m.set(Mode::Preview, "test"), Mode::Preview);
    EXPECT_EQ(m.version(), 2u) << "setting the current mode is not a change";
    EXPECT_EQ(m.set(Mode::Refine, "test"), Mode::Refine);
    EXPECT_EQ(m.version(), 3u);
    EXPECT_EQ(parseMode("refine"), Mode::Refine);
    EXPECT_EQ(parseMode("Refine"), std::nullopt);
}

TEST(ModeMachine, ConcurrentTogglesAreNeverLost) {
    // The button thread and the socket thread drive the same machine.
    ModeMachine m;
    std::vector<std::thread> threads;
    for (int t = 0; t < 4; ++t)
        threads.emplace_back([&] {
            for (int i = 0; i < 1001; ++i) m.toggle("test");
        });
    for (auto& t : threads) t.join();
    EXPECT_EQ(m.version(), 4004u);
    EXPECT_EQ(m.mode(), Mode::Preview);  // an even number of toggles
}

TEST(ControlServer, AnswersOneLinePerConnection) {
    const std::string path = socketPath("answers.sock");
    std::atomic<int> calls{0};
    auto server = ControlServer::create(path, [&](const std::string& command) {
        ++calls;
        return nlohmann::json{{"echo", command}}.dump();
    });
    ASSERT_TRUE(server) << server.message();
    for (const char* command : {"status", "mode refine", "toggle"}) {
        Result<std::string> reply = controlRequest(path, command);
        ASSERT_TRUE(reply) << reply.message();
        EXPECT_EQ(nlohmann::json::parse(*reply)["echo"], command);
    }
    EXPECT_EQ(calls.load(), 3);
    // Owner and group only: the socket changes the box's mode.
    EXPECT_EQ(fs::status(path).permissions() & fs::perms::others_all, fs::perms::none);
}

TEST(ControlServer, SilentClientDoesNotBlockOthers) {
    const std::string path = socketPath("silent.sock");
    auto server = ControlServer::create(path, [](const std::string&) { return std::string("{}"); });
    ASSERT_TRUE(server) << server.message();
    // A client that connects and says nothing.
    int silent = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
    ASSERT_EQ(::connect(silent, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    // The next client is served by another of the socket's threads (or, were they all held by
    // silent clients, once one times out after 1 s), well within 10 s.
    Result<std::string> reply = controlRequest(path, "status", 10000);
    EXPECT_TRUE(reply) << reply.message();
    ::close(silent);
}

// `record stop` waits while the take drains; the socket answers status meanwhile (issue 52).
TEST(ControlServer, AnswersStatusWhileARecordStopDrains) {
    HangGuard guard("the control socket test", std::chrono::seconds(60));
    const std::string path = socketPath("draining.sock");
    std::mutex mutex;
    std::condition_variable changed;
    bool stopEntered = false, drained = false;
    auto server = ControlServer::create(path, [&](const std::string& command) -> std::string {
        if (command != "record stop") return "{\"status\": true}";
        std::unique_lock lock(mutex);
        stopEntered = true;
        changed.notify_all();
        changed.wait(lock, [&] { return drained; });
        return "{\"ok\": true, \"path\": \"take\"}";
    });
    ASSERT_TRUE(server) << server.message();
    Result<std::string> stopReply = makeError("no reply");
    std::thread stopper([&] { stopReply = controlRequest(path, "record stop", 30000); });
    {
        std::unique_lock lock(mutex);
        changed.wait(lock, [&] { return stopEntered; });
    }
    Result<std::string> status = controlRequest(path, "status", 3000);
    EXPECT_TRUE(status) << status.message();
    {
        std::lock_guard lock(mutex);
        drained = true;
    }
    changed.notify_all();
    stopper.join();
    ASSERT_TRUE(stopReply) << stopReply.message();
    EXPECT_EQ(nlohmann::json::parse(*stopReply)["path"], "take");
}

// A double tap (the page, the control socket, the button at once): one take starts, the other
// starts are answered "already recording"; stops at once end it once and answer its folder.
TEST(TakeRecorder, SimultaneousStartsStartOneTakeAndSimultaneousStopsShareItsEnd) {
    HangGuard guard("simultaneous starts and stops", std::chrono::seconds(60));
    TakeRecorder recorder(recorderConfig("double_tap"));
    constexpr int kCallers = 8;
    std::vector<Result<std::string>> starts(kCallers, makeError("not run"));
    std::vector<std::thread> callers;
    for (int i = 0; i < kCallers; ++i)
        callers.emplace_back([&, i] { starts[size_t(i)] = recorder.start(""); });
    for (std::thread& t : callers) t.join();
    callers.clear();
    std::string take;
    for (const Result<std::string>& r : starts) {
        if (r) {
            EXPECT_TRUE(take.empty()) << "two takes started: " << take << " and " << *r;
            take = *r;
        } else {
            EXPECT_NE(r.message().find("already recording"), std::string::npos) << r.message();
        }
    }
    ASSERT_FALSE(take.empty());
    for (int n = 0; n < 200; ++n) recorder.addEvent({0, "test", "event=" + std::to_string(n)});
    std::vector<Result<std::string>> stops(kCallers, makeError("not run"));
    for (int i = 0; i < kCallers; ++i)
        callers.emplace_back([&, i] { stops[size_t(i)] = recorder.stop(); });
    for (std::thread& t : callers) t.join();
    int ended = 0;
    for (const Result<std::string>& r : stops) {
        if (!r) {
            // A stop that came after the take ended (not during its drain).
            EXPECT_EQ(r.message(), "not recording");
            continue;
        }
        EXPECT_EQ(*r, take);
        ++ended;
    }
    EXPECT_GE(ended, 1);
    EXPECT_FALSE(recorder.recording());
    Result<SessionInfo> session = openSession(take);
    EXPECT_TRUE(session) << session.message();
}

// Threads hammering start and stop as the page's and the socket's callers do: never a crash,
// a hang or a second writer; every take that started ends as a session that opens.
TEST(TakeRecorder, HammeredStartAndStopNeverCrashHangOrLoseATake) {
    HangGuard guard("start/stop hammering", std::chrono::seconds(90));
    const ServiceConfig config = recorderConfig("hammer");
    std::set<std::string> started;
    {
        TakeRecorder recorder(config);
        std::mutex startedMutex;
        std::atomic<bool> producing{true};
        std::thread producer([&] {
            while (producing.load()) {
                recorder.addEvent({0, "test", "event"});
                std::this_thread::sleep_for(std::chrono::milliseconds(1));
            }
        });
        std::vector<std::thread> callers;
        for (int i = 0; i < 6; ++i)
            callers.emplace_back([&, i] {
                for (int n = 0; n < 8; ++n) {
                    if ((n + i) % 2 == 0) {
                        Result<std::string> r = recorder.start("");
                        if (r) {
                            std::lock_guard lock(startedMutex);
                            EXPECT_TRUE(started.insert(*r).second) << *r << " started twice";
                        }
                    } else {
                        (void)recorder.stop();
                    }
                }
            });
        for (std::thread& t : callers) t.join();
        (void)recorder.stop();
        EXPECT_FALSE(recorder.recording());
        producing.store(false);
        producer.join();
    }
    EXPECT_FALSE(started.empty());
    for (const std::string& take : started) {
        Result<SessionInfo> session = openSession(take);
        EXPECT_TRUE(session) << take << ": " << session.message();
    }
}

// A shell's soft limit of 1024 is raised to the hard one at start (issue 52, High 2).
TEST(Descriptors, TheSoftLimitIsRaisedToTheHardOne) {
    rlimit before{};
    ASSERT_EQ(::getrlimit(RLIMIT_NOFILE, &before), 0);
    if (before.rlim_max < 512) GTEST_SKIP() << "hard limit " << before.rlim_max;
    const rlimit low{256, before.rlim_max};
    ASSERT_EQ(::setrlimit(RLIMIT_NOFILE, &low), 0);
    EXPECT_EQ(raiseOpenFileLimit(), uint64_t(before.rlim_max));
    rlimit after{};
    ASSERT_EQ(::getrlimit(RLIMIT_NOFILE, &after), 0);
    EXPECT_EQ(after.rlim_cur, before.rlim_max);
    ::setrlimit(RLIMIT_NOFILE, &before);
}

// With the process a few descriptors short of its limit (the network took the rest), a take
// still starts, records its frames and ends as a session that opens: what the unit's
// LimitNOFILE= and the web's connection bound keep for it.
TEST(TakeRecorder, ATakeRecordsWithTheProcessNearItsDescriptorLimit) {
    TakeRecorder recorder(recorderConfig("near_fd_limit"));
    rlimit before{};
    ASSERT_EQ(::getrlimit(RLIMIT_NOFILE, &before), 0);
    size_t open = 0;
    for ([[maybe_unused]] const auto& entry : fs::directory_iterator("/proc/self/fd")) ++open;
    const rlimit tight{rlim_t(open + 256), before.rlim_max};
    ASSERT_EQ(::setrlimit(RLIMIT_NOFILE, &tight), 0);
    // Everything but kLeft descriptors taken, as idle connections would.
    constexpr int kLeft = 16;
    std::vector<int> taken;
    for (int fd; (fd = ::open("/dev/null", O_RDONLY | O_CLOEXEC)) >= 0;) taken.push_back(fd);
    for (int i = 0; i < kLeft && !taken.empty(); ++i) {
        ::close(taken.back());
        taken.pop_back();
    }
    Result<std::string> take = recorder.start("near_limit");
    constexpr int kFrames = 20;
    for (int n = 0; take && n < kFrames; ++n) {
        auto frame = std::make_shared<Frame>();
        frame->width = 8;
        frame->height = 8;
        frame->rgb.assign(8 * 8 * 3, uint8_t(n));
        frame->timestampNs = uint64_t(n + 1) * 33'000'000;
        frame->sequence = uint64_t(n);
        frame->wallClockNs = 1'700'000'000'000'000'000ull + frame->timestampNs;
        recorder.addFrame("scene", frame);
    }
    Result<std::string> stopped = take ? recorder.stop() : take;
    const RecordStatus status = recorder.status();
    for (int fd : taken) ::close(fd);
    ::setrlimit(RLIMIT_NOFILE, &before);
    ASSERT_TRUE(take) << take.message();
    ASSERT_TRUE(stopped) << stopped.message();
    EXPECT_TRUE(status.stoppedBecause.empty()) << status.stoppedBecause;
    EXPECT_EQ(status.frames, uint64_t(kFrames));
    Result<SessionInfo> session = openSession(*take);
    ASSERT_TRUE(session) << session.message();
}

TEST(ControlServer, ReplacesAStaleSocketButNotALiveOne) {
    const std::string path = socketPath("stale.sock");
    {
        auto first = ControlServer::create(path, [](const std::string&) { return "{}"; });
        ASSERT_TRUE(first) << first.message();
        auto second = ControlServer::create(path, [](const std::string&) { return "{}"; });
        ASSERT_FALSE(second);
        EXPECT_NE(second.message().find("another previsd is running"), std::string::npos)
            << second.message();
    }
    EXPECT_FALSE(fs::exists(path)) << "a stopped server removes its socket";
    // A socket file left by a crash (bound, nobody listening).
    int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    std::strncpy(addr.sun_path, path.c_str(), sizeof(addr.sun_path) - 1);
    ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0);
    ::close(fd);
    ASSERT_TRUE(fs::exists(path));
    auto third = ControlServer::create(path, [](const std::string&) { return "{\"ok\":true}"; });
    ASSERT_TRUE(third) << third.message();
    EXPECT_TRUE(controlRequest(path, "status"));
}

TEST(ControlServer, ClientNamesTheSocketWhenNoServerRuns) {
    Result<std::string> reply = controlRequest(socketPath("nobody.sock"), "status", 500);
    ASSERT_FALSE(reply);
    EXPECT_NE(reply.message().find("nobody.sock"), std::string::npos) << reply.message();
    EXPECT_NE(reply.message().find("is previsd running"), std::string::npos);
}

// A control character in any value written into a generated unit is refused, naming where it
// came from (issue 52): the config refuses it first, this keeps a newline from ever adding a
// setting to a unit systemd runs as root.
TEST(NetworkUnits, AValueWithANewlineIsRefusedNotWrittenIntoAUnit) {
    NetworkConfig network;
    network.web.listen = "127.0.0.1:8080\nExecStartPre=/bin/sh -c id";
    Result<std::map<std::string, std::string>> units = networkUnits(network);
    ASSERT_FALSE(units);
    EXPECT_NE(units.message().find("[web] listen holds a control character"), std::string::npos)
        << units.message();
    network.web.listen = "127.0.0.1:8080";
    NetworkUnitOptions options;
    options.webTokenSource = "/etc/pre\nvis/web-token";
    units = networkUnits(network, options);
    ASSERT_FALSE(units);
    EXPECT_NE(units.message().find("the config's folder"), std::string::npos) << units.message();
    options.webTokenSource = "/etc/previs/web-token";
    units = networkUnits(network, options);
    ASSERT_TRUE(units) << units.message();
}

// Each socket unit lives only while previsd does (BindsTo=: a packet never starts a previsd an
// operator stopped or that exited 2) and binds an address that is not up yet (FreeBind=).
// tests/systemd/socket_units_vm.sh checks both under systemd.
TEST(NetworkUnits, SocketsAreBoundToTheServiceAndBindAnAddressNotUpYet) {
    NetworkConfig network;
    network.web.listen = "192.0.2.77:8080";
    network.freed.out = "127.0.0.1:40000";
    NetworkUnitOptions options;
    options.freedInListen = "0.0.0.0:40001";
    Result<std::map<std::string, std::string>> units = networkUnits(network, options);
    ASSERT_TRUE(units) << units.message();
    int sockets = 0;
    for (const auto& [name, text] : *units) {
        if (!name.ends_with(".socket")) continue;
        ++sockets;
        EXPECT_NE(text.find("\nBindsTo=previsd.service\n"), std::string::npos) << name << text;
        EXPECT_NE(text.find("\nFreeBind=yes\n"), std::string::npos) << name << text;
    }
    EXPECT_EQ(sockets, 3);
}

TEST(StatusJson, HasTheDesignFields) {
    ServiceStatus s;
    s.mode = Mode::Refine;
    s.framesShown = 12;
    s.framesDropped = 3;
    s.samples = 256;
    s.fps = 3.14159;
    s.display = "kms";
    s.worldFromCamera = cv::Matx44d::eye();
    s.worldFromCamera->operator()(0, 3) = 1.5;
    s.tags = 4;
    s.uptimeSeconds = 61.25;
    const nlohmann::json j = nlohmann::json::parse(statusJson(s));
    EXPECT_EQ(j["mode"], "refine");
    EXPECT_EQ(j["framesShown"], 12);
    EXPECT_EQ(j["framesDropped"], 3);
    EXPECT_EQ(j["samples"], 256);
    EXPECT_TRUE(j["noiseEstimate"].is_null());
    EXPECT_TRUE(j["etaSeconds"].is_null());
    EXPECT_NEAR(j["fps"].get<double>(), 3.14, 1e-9);
    EXPECT_EQ(j["recording"], false);
    EXPECT_EQ(j["display"], "kms");
    ASSERT_EQ(j["pose"]["worldFromCamera"].size(), 16u);
    EXPECT_EQ(j["pose"]["worldFromCamera"][3], 1.5);  // row-major: m03
    EXPECT_EQ(j["pose"]["tags"], 4);
    EXPECT_GT(j["uptimeSeconds"].get<double>(), 61.0);
    // Frames without a trusted pose, counted by why; the button and LED not configured.
    EXPECT_EQ(j["trackingLost"], nlohmann::json({{"noTags", 0},
                                                 {"noBoardTag", 0},
                                                 {"tooFewTags", 0},
                                                 {"reprojection", 0},
                                                 {"illConditioned", 0},
                                                 {"frameSize", 0},
                                                 {"noTrackerData", 0}}));
    EXPECT_EQ(j["button"], "none");
    EXPECT_EQ(j["led"], "none");
    s.trackingLostFrames[size_t(LostReason::IllConditioned)] = 7;
    EXPECT_EQ(nlohmann::json::parse(statusJson(s))["trackingLost"]["illConditioned"], 7);
    s.worldFromCamera.reset();
    EXPECT_TRUE(nlohmann::json::parse(statusJson(s))["pose"].is_null());
    EXPECT_EQ(statusLine(s).rfind("REFINE 256 spp", 0), 0u) << statusLine(s);
    EXPECT_TRUE(nlohmann::json::parse(statusJson(s))["photons"].is_null());
    // Refinement with the meter's estimate: the JSON has numbers, the overlay the line.
    s.noiseEstimate = 0.0183;
    s.etaSeconds = 12.34;
    s.fps = 2.0;
    s.trackingLost = false;
    const nlohmann::json m = nlohmann::json::parse(statusJson(s));
    EXPECT_NEAR(m["noiseEstimate"].get<double>(), 0.0183, 1e-9);
    EXPECT_NEAR(m["etaSeconds"].get<double>(), 12.3, 1e-9);
    EXPECT_EQ(statusLine(s), "REFINE 256 spp noise 1.8% ETA 12 s 2.0 fps");
    s.etaSeconds = 0.0;
    EXPECT_EQ(statusLine(s), "REFINE 256 spp noise 1.8% ETA 0 s 2.0 fps");
    s.etaSeconds = 754.0;
    EXPECT_NE(statusLine(s).find("ETA 12.6 min"), std::string::npos) << statusLine(s);
    s.etaSeconds = 9000.0;
    EXPECT_NE(statusLine(s).find("ETA 2.5 h"), std::string::npos) << statusLine(s);
    // In preview the overlay has neither (a stale estimate would mislead).
    s.mode = Mode::Preview;
    EXPECT_EQ(statusLine(s), "PREVIEW 256 spp 2.0 fps");
    s.mode = Mode::Refine;
    s.noiseEstimate.reset();
    s.etaSeconds.reset();
    s.trackingLost = true;
    // With a photon pass: its budget and radius, in the JSON and on the overlay.
    s.photonsPerIteration = 65536;
    s.photonRadiusM = 0.0042f;
    const nlohmann::json p = nlohmann::json::parse(statusJson(s));
    EXPECT_EQ(p["photons"]["perIteration"], 65536);
    EXPECT_NEAR(p["photons"]["radiusM"].get<double>(), 0.0042, 1e-6);
    EXPECT_NE(statusLine(s).find("64K photons r 4.2 mm"), std::string::npos) << statusLine(s);
}

// The plate-consistency meter's reading (DESIGN.md §4): null before the first, then the object
// docs/previsd.md describes; outside [0.8, 1.25] a warning on the overlay.
// A camera's problem line carries what the driver or a file name held, in any bytes: the status
// stays valid JSON (invalid UTF-8 as U+FFFD) instead of failing (issue 52).
TEST(StatusJson, IsValidWhateverBytesACameraNameHolds) {
    ServiceStatus s;
    s.sceneCameraProblem = "cannot open /dev/video\xff\xfe: No such device";
    std::string text;
    ASSERT_NO_THROW(text = statusJson(s));
    const nlohmann::json j = nlohmann::json::parse(text);
    EXPECT_NE(text.find("\xef\xbf\xbd"), std::string::npos) << text;  // U+FFFD
    EXPECT_TRUE(j.is_object());
}

TEST(StatusJson, ThePlateConsistencyReadingAndItsWarning) {
    ServiceStatus s;
    s.trackingLost = false;
    EXPECT_TRUE(nlohmann::json::parse(statusJson(s))["plateConsistency"].is_null());
    PlateConsistencyReading r;
    r.value.ratio = {0.0812, 0.0834, 0.0967};
    r.value.spread = {0.12, 0.11, 0.13};
    r.value.pixels = 412;
    r.value.gridWidth = 40;
    r.value.gridHeight = 23;
    r.value.ok = false;
    r.frame = 17;
    s.plateConsistency = r;
    const nlohmann::json j = nlohmann::json::parse(statusJson(s))["plateConsistency"];
    EXPECT_EQ(j["ratio"], nlohmann::json({0.0812, 0.0834, 0.0967}));
    EXPECT_EQ(j["spread"], nlohmann::json({0.12, 0.11, 0.13}));
    EXPECT_EQ(j["pixels"], 412);
    EXPECT_EQ(j["resolution"], nlohmann::json({40, 23}));
    EXPECT_EQ(j["ok"], false);
    EXPECT_EQ(j["range"], nlohmann::json({0.8, 1.25}));
    EXPECT_EQ(j["frame"], 17);
    EXPECT_NE(statusLine(s).find("LIGHTING OFF x0.08 0.08 0.10"), std::string::npos)
        << statusLine(s);
    s.plateConsistency->value.ratio = {0.97, 1.0, 1.02};
    s.plateConsistency->value.ok = true;
    EXPECT_EQ(statusLine(s).find("LIGHTING OFF"), std::string::npos) << statusLine(s);
}

TEST(RecordedEvents, FireWithTheirFrameOnEveryPass) {
    // The demo take: presses recorded just before frames 22 and 42 (examples/demo/README.md).
    auto loaded = RecordedEvents::load(testing::sourcePath("examples/demo/session/cameras/scene"));
    ASSERT_TRUE(loaded) << loaded.message();
    ASSERT_TRUE(*loaded);
    RecordedEvents events = std::move(**loaded);
    ASSERT_EQ(events.size(), 2u);
    std::vector<uint32_t> firedAt;
    for (uint32_t pass = 0; pass < 2; ++pass)
        for (uint32_t frame = 0; frame < 60; frame += (frame % 7 == 3 ? 2 : 1))  // some dropped
            for (const SessionEvent& e : events.due(frame)) {
                EXPECT_EQ(e.source, "mode-button");
                EXPECT_EQ(e.event, "short-press");
                firedAt.push_back(frame);
            }
    ASSERT_EQ(firedAt.size(), 4u) << "both presses, on both passes, even across dropped frames";
    events.due(59);
    EXPECT_FALSE(events.restarted());
    events.due(0);
    EXPECT_TRUE(events.restarted()) << "the service puts the mode back to preview here";
    EXPECT_EQ(firedAt[0], firedAt[2]);
    EXPECT_EQ(firedAt[1], firedAt[3]);
    EXPECT_LT(firedAt[0], firedAt[1]);
    // A session without events.csv has none.
    const fs::path bare = testing::scratchDir("previs_daemon_test") / "bare/cameras/scene";
    fs::create_directories(bare);
    auto none = RecordedEvents::load(bare.string());
    ASSERT_TRUE(none) << none.message();
    EXPECT_FALSE(*none);
}

TEST(CameraConventions, OpenCvToRendererFlipsYAndZ) {
    // A camera at (1, 2, 3) looking along world −Z with +Y up in the renderer's convention is,
    // in OpenCV's axes (y down, z forward), the rotation diag(1, −1, −1).
    cv::Matx44d cv = cv::Matx44d::eye();
    cv(1, 1) = -1;
    cv(2, 2) = -1;
    cv(0, 3) = 1;
    cv(1, 3) = 2;
    cv(2, 3) = 3;
    const glm::mat4 m = renderWorldFromOpenCvCamera(cv);
    for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) EXPECT_FLOAT_EQ(m[c][r], r == c ? 1.0f : 0.0f);
    EXPECT_FLOAT_EQ(m[3][0], 1.0f);
    EXPECT_FLOAT_EQ(m[3][1], 2.0f);
    EXPECT_FLOAT_EQ(m[3][2], 3.0f);
}

TEST(CameraConventions, PoseDeltaMeasuresTranslationAndAngle) {
    cv::Matx44d a = cv::Matx44d::eye(), b = cv::Matx44d::eye();
    const double angle = 10.0 * M_PI / 180.0;
    b(0, 0) = std::cos(angle);
    b(0, 1) = -std::sin(angle);
    b(1, 0) = std::sin(angle);
    b(1, 1) = std::cos(angle);
    b(2, 3) = 0.25;
    const PoseDelta d = poseDelta(a, b);
    EXPECT_NEAR(d.translationM, 0.25, 1e-12);
    EXPECT_NEAR(d.rotationDeg, 10.0, 1e-9);
    EXPECT_NEAR(poseDelta(b, b).rotationDeg, 0.0, 1e-6);
}

}  // namespace
}  // namespace previs

namespace previs {
namespace {

// The memory check against the service's cgroup (daemon/memory_budget.h), on cgroup files laid
// out as the kernel lays them out.
TEST(MemoryBudget, ReadsTheCgroupsLimitAndRefusesWhatWouldCrossIt) {
    const std::filesystem::path root = testing::scratchDir("previs_memory_budget");
    std::filesystem::create_directories(root / "proc/self");
    std::filesystem::create_directories(root / "sys/fs/cgroup/system.slice/previsd.service");
    std::ofstream(root / "proc/self/cgroup") << "0::/system.slice/previsd.service\n";
    const auto limitFile = root / "sys/fs/cgroup/system.slice/previsd.service/memory.max";
    std::ofstream(limitFile) << "max\n";
    EXPECT_EQ(cgroupMemoryLimit(root.string()), std::nullopt) << "max: unlimited";
    std::ofstream(limitFile) << "4294967296\n";
    EXPECT_EQ(cgroupMemoryLimit(root.string()), uint64_t(4) << 30);
    EXPECT_EQ(cgroupMemoryLimit((root / "nothing").string()), std::nullopt);

    Scene scene;
    scene.path = "set.glb";
    ServiceConfig config;
    config.path = "/etc/previs/previsd.toml";
    config.render.width = 1920;
    config.render.height = 1080;
    const uint64_t hd = estimatedServiceBytes(scene, config);
    // The measured peak at 1080p (1.94 GiB on the demo scene) fits under the shipped 4 GiB.
    EXPECT_GT(hd, uint64_t(1900) << 20);
    EXPECT_LT(hd, uint64_t(4) << 30);
    EXPECT_TRUE(checkMemoryBudget(scene, config, uint64_t(4) << 30));
    EXPECT_TRUE(checkMemoryBudget(scene, config, std::nullopt));
    // A scene of 20 million triangles does not.
    scene.geometry.triangles.resize(20'000'000);
    scene.geometry.positions.resize(10'000'000);
    const Status refused = checkMemoryBudget(scene, config, uint64_t(4) << 30);
    ASSERT_FALSE(refused);
    EXPECT_NE(refused.message().find("set.glb at 1920x1080 needs about"), std::string::npos)
        << refused.message();
    EXPECT_NE(refused.message().find("limit of 4096 MiB (MemoryMax=)"), std::string::npos)
        << refused.message();
}

}  // namespace
}  // namespace previs
