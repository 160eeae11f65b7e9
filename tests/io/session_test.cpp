// The session format v3 (docs/session-format.md): what SessionWriter writes, openSession,
// loadPoses, loadEvents, loadLighting and the camera index reader read back; the crash cases the
// format promises to survive (a cut last line, a stray *.tmp), a future version refused, and a
// take from elsewhere kept inside its folder: hostile files (a FIFO, /dev/zero, a sparse file, a
// link to a file outside) refused at once, naming the file and never echoing its content.

#include "io/session.h"

#include <fcntl.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "capture/recorded_source.h"
#include "tests/support/hang_guard.h"
#include "tests/support/temp_dir.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

fs::path freshDir(const std::string& name) {
    return testing::emptyScratchDir("session_test", name);
}

std::string readText(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
}

void writeText(const fs::path& p, const std::string& text) {
    std::ofstream out(p, std::ios::binary);
    out << text;
}

std::array<double, 16> someMatrix(double t) {
    // A rotation about y by an angle that needs all digits, and a translation.
    const double c = std::cos(t), s = std::sin(t);
    return {c, 0, s, 0.1 * t, 0, 1, 0, 0.3, -s, 0, c, -1.0 / 3.0, 0, 0, 0, 1};
}

const std::vector<uint8_t> kBytes = {1, 2, 3, 4, 5};

TEST(Session, RoundTrip) {
    const fs::path dir = freshDir("round_trip");
    {
        SessionWriterOptions options;
        options.cameraRoles = {{"scene", "scene"}, {"fisheye", "fisheye"}};
        options.configToml = "[cameras.scene]\nsource = \"session\"\n";
        options.configDir = ".";  // inside the session: anything outside is refused
        options.created = "2025-01-02T03:04:05Z";
        auto writer = SessionWriter::create(dir.string(), options);
        ASSERT_TRUE(writer.ok()) << writer.message();
        for (uint64_t i = 0; i < 3; ++i) {
            ASSERT_TRUE(writer->writeFrame("scene", 10 + i, 1000 + 66 * i, kBytes, "jpg", 64, 36));
            PoseRecord truth;
            truth.timestampNs = 1000 + 66 * i;
            truth.frame = 10 + i;
            truth.kind = PoseKind::Truth;
            truth.worldFromCamera = someMatrix(0.1 * double(i) + 0.123456789);
            ASSERT_TRUE(writer->writePose(truth));
        }
        ASSERT_TRUE(writer->writeFrame("fisheye", 0, 1000, kBytes, "png", 32, 24));
        PoseRecord tracked;
        tracked.timestampNs = 1066;
        tracked.frame = 11;
        tracked.kind = PoseKind::Tracked;
        tracked.worldFromCamera = someMatrix(1.0);
        tracked.reprojErrorPx = 0.25;
        tracked.tags = 4;
        ASSERT_TRUE(writer->writePose(tracked));
        PoseRecord lost;
        lost.timestampNs = 1132;
        lost.frame = 12;
        lost.kind = PoseKind::Lost;
        ASSERT_TRUE(writer->writePose(lost));
        ASSERT_TRUE(writer->writeEvent({1100, "mode-button", "short-press"}));
        ASSERT_TRUE(writer->writeEvent({1200, "ctl", "mode=preview"}));
        ASSERT_TRUE(writer->flush());
        // Out of order frames are refused, as the reader would refuse them.
        EXPECT_FALSE(writer->writeFrame("scene", 12, 2000, kBytes, "jpg", 64, 36));
        EXPECT_FALSE(writer->writeFrame("scene", 13, 999, kBytes, "jpg", 64, 36));
        EXPECT_FALSE(writer->writeFrame("../x", 20, 3000, kBytes, "jpg", 64, 36));
    }

    auto info = openSession(dir.string());
    ASSERT_TRUE(info.ok()) << info.message();
    // It names its config's folder (config_dir): a v2 session; a take (no config_dir) is the
    // current version (Session.TakeIsTheCurrentVersion).
    EXPECT_EQ(info->version, 2);
    EXPECT_EQ(info->created, "2025-01-02T03:04:05Z");
    EXPECT_EQ(info->clock, "CLOCK_MONOTONIC");
    EXPECT_FALSE(info->previsVersion.empty());
    EXPECT_EQ(fs::path(info->configPath), dir / "config.toml");
    EXPECT_EQ(readText(info->configPath), "[cameras.scene]\nsource = \"session\"\n");
    EXPECT_EQ(fs::path(info->configDir), dir);
    ASSERT_EQ(info->cameras.size(), 2u);
    EXPECT_EQ(info->cameras[0].name, "fisheye");
    EXPECT_EQ(info->cameras[0].role, "fisheye");
    EXPECT_EQ(info->cameras[0].frames, 1u);
    EXPECT_EQ(info->cameras[1].name, "scene");
    EXPECT_EQ(info->cameras[1].frames, 3u);
    ASSERT_NE(info->cameraWithRole("scene"), nullptr);
    EXPECT_EQ(info->cameraWithRole("scene")->dir, (dir / "cameras" / "scene").string());

    // The camera index stays v1 and is read by the existing camera reader.
    auto frames = loadCameraIndex((dir / "cameras" / "scene").string());
    ASSERT_TRUE(frames.ok()) << frames.message();
    ASSERT_EQ(frames->size(), 3u);
    EXPECT_EQ((*frames)[2].sequence, 12u);
    EXPECT_EQ((*frames)[2].timestampNs, 1132u);
    EXPECT_EQ((*frames)[2].width, 64u);
    EXPECT_EQ(fs::path((*frames)[2].file).filename(), "000000000012.jpg");
    EXPECT_EQ(readText((*frames)[2].file), std::string(kBytes.begin(), kBytes.end()));

    auto poses = loadPoses(dir.string());
    ASSERT_TRUE(poses.ok()) << poses.message();
    ASSERT_EQ(poses->size(), 5u);
    for (int i = 0; i < 3; ++i) {
        const PoseRecord& p = (*poses)[size_t(i)];
        EXPECT_EQ(p.kind, PoseKind::Truth);
        EXPECT_EQ(p.frame, uint64_t(10 + i));
        ASSERT_TRUE(p.worldFromCamera.has_value());
        // Exact: the writer prints the shortest text that reads back as the same double.
        EXPECT_EQ(*p.worldFromCamera, someMatrix(0.1 * double(i) + 0.123456789));
        EXPECT_FALSE(p.reprojErrorPx.has_value());
    }
    EXPECT_EQ((*poses)[3].kind, PoseKind::Tracked);
    EXPECT_EQ((*poses)[3].reprojErrorPx, 0.25);
    EXPECT_EQ((*poses)[3].tags, 4);
    EXPECT_EQ((*poses)[4].kind, PoseKind::Lost);
    EXPECT_FALSE((*poses)[4].worldFromCamera.has_value());
    EXPECT_EQ((*poses)[4].timestampNs, 1132u);

    size_t skipped = 99;
    auto events = loadEvents(dir.string(), &skipped);
    ASSERT_TRUE(events.ok()) << events.message();
    EXPECT_EQ(skipped, 0u);
    ASSERT_EQ(events->size(), 2u);
    EXPECT_EQ((*events)[0].timestampNs, 1100u);
    EXPECT_EQ((*events)[0].source, "mode-button");
    EXPECT_EQ((*events)[0].event, "short-press");
    EXPECT_EQ((*events)[1].source, "ctl");
    EXPECT_EQ((*events)[1].event, "mode=preview");

    // The same folder is never recorded over.
    auto again = SessionWriter::create(dir.string());
    ASSERT_FALSE(again.ok());
    EXPECT_NE(again.message().find("already holds a session"), std::string::npos);
}

TEST(Session, TruncatedLastLineIgnoredAndMalformedLineNamed) {
    const fs::path dir = freshDir("truncated");
    {
        auto writer = SessionWriter::create(dir.string());
        ASSERT_TRUE(writer.ok()) << writer.message();
        ASSERT_TRUE(writer->writeEvent({5, "mode-button", "short-press"}));
        PoseRecord lost;
        lost.frame = 0;
        lost.kind = PoseKind::Lost;
        ASSERT_TRUE(writer->writePose(lost));
    }
    // A crash mid-append: the last line has no '\n'.
    {
        std::ofstream events(dir / "events.csv", std::ios::app | std::ios::binary);
        events << "9,mode-button,long-pr";
        std::ofstream poses(dir / "poses.csv", std::ios::app | std::ios::binary);
        poses << "10,1,tracked,1,0,0";
    }
    auto events = loadEvents(dir.string());
    ASSERT_TRUE(events.ok()) << events.message();
    ASSERT_EQ(events->size(), 1u);
    EXPECT_EQ((*events)[0].timestampNs, 5u);
    auto poses = loadPoses(dir.string());
    ASSERT_TRUE(poses.ok()) << poses.message();
    EXPECT_EQ(poses->size(), 1u);

    // The same bytes completed by '\n' are a malformed line: corruption, named by file:line.
    {
        std::ofstream posesOut(dir / "poses.csv", std::ios::app | std::ios::binary);
        posesOut << "\n";
    }
    auto bad = loadPoses(dir.string());
    ASSERT_FALSE(bad.ok());
    EXPECT_NE(bad.message().find("poses.csv:3:"), std::string::npos) << bad.message();
    {
        std::ofstream eventsOut(dir / "events.csv", std::ios::app | std::ios::binary);
        eventsOut << "ate\nnot-a-number,ctl,mode=refine\n";
    }
    auto badEvents = loadEvents(dir.string());
    ASSERT_FALSE(badEvents.ok());
    EXPECT_NE(badEvents.message().find("events.csv:4:"), std::string::npos) << badEvents.message();
}

TEST(Session, UnknownEventSourcesSkippedWithACount) {
    const fs::path dir = freshDir("unknown_events");
    {
        auto writer = SessionWriter::create(dir.string());
        ASSERT_TRUE(writer.ok()) << writer.message();
        ASSERT_TRUE(writer->writeEvent({1, "foot-pedal", "down"}));
        ASSERT_TRUE(writer->writeEvent({2, "mode-button", "long-press"}));
        ASSERT_TRUE(writer->writeEvent({3, "ctl", "record=start"}));
    }
    size_t skipped = 0;
    auto events = loadEvents(dir.string(), &skipped);
    ASSERT_TRUE(events.ok()) << events.message();
    ASSERT_EQ(events->size(), 1u);
    EXPECT_EQ((*events)[0].event, "long-press");
    EXPECT_EQ(skipped, 2u);
}

TEST(Session, FutureVersionRefused) {
    const fs::path dir = freshDir("future");
    fs::create_directories(dir);
    writeText(dir / "session.toml",
              "format = \"previs-session\"\nversion = 99\ncreated = \"2030-01-01T00:00:00Z\"\n");
    auto info = openSession(dir.string());
    ASSERT_FALSE(info.ok());
    EXPECT_NE(info.message().find("version 99 is newer"), std::string::npos) << info.message();
    EXPECT_NE(info.message().find("session.toml"), std::string::npos);

    writeText(dir / "poses.csv", "# previs-session poses v99: something else\n1,2,3\n");
    auto poses = loadPoses(dir.string());
    ASSERT_FALSE(poses.ok());
    EXPECT_NE(poses.message().find("version 99 is newer"), std::string::npos) << poses.message();

    writeText(dir / "session.toml", "format = \"something\"\nversion = 1\n");
    EXPECT_FALSE(openSession(dir.string()).ok());
    fs::remove(dir / "session.toml");
    auto none = openSession(dir.string());
    ASSERT_FALSE(none.ok());
    EXPECT_NE(none.message().find("not a session folder"), std::string::npos);
}

TEST(Session, ReadsVersion1) {
    // v1: no config_dir, poses without the frame column and without a header.
    const fs::path dir = freshDir("v1");
    fs::create_directories(dir / "cameras" / "scene");
    writeText(dir / "session.toml",
              "format = \"previs-session\"\nversion = 1\ncreated = 2024-06-10T12:00:00Z\n"
              "clock = \"CLOCK_MONOTONIC\"\nprevis = \"0.1\"\n");
    writeText(dir / "config.toml", "\n");
    writeText(dir / "cameras" / "scene" / "index.csv",
              "# previs-session camera index v1: sequence,timestampNs,file,width,height\n"
              "0,100,000000000000.png,4,4\n");
    writeText(dir / "poses.csv",
              "100,tracked,1,0,0,0,0,1,0,0,0,0,1,2,0,0,0,1,0.5,3\n"
              "200,lost,,,,,,,,,,,,,,,,,,0\n");
    writeText(dir / "events.csv", "150,mode-button,press\n");
    auto info = openSession(dir.string());
    ASSERT_TRUE(info.ok()) << info.message();
    EXPECT_EQ(info->version, 1);
    EXPECT_EQ(info->created, "2024-06-10T12:00:00Z");
    EXPECT_EQ(fs::path(info->configDir), dir);  // v1: relative to the session folder
    ASSERT_EQ(info->cameras.size(), 1u);
    EXPECT_EQ(info->cameras[0].role, "");
    auto poses = loadPoses(dir.string());
    ASSERT_TRUE(poses.ok()) << poses.message();
    ASSERT_EQ(poses->size(), 2u);
    EXPECT_FALSE((*poses)[0].frame.has_value());
    EXPECT_EQ((*(*poses)[0].worldFromCamera)[11], 2.0);
    EXPECT_EQ((*poses)[0].tags, 3);
    EXPECT_EQ((*poses)[1].kind, PoseKind::Lost);
    auto events = loadEvents(dir.string());
    ASSERT_TRUE(events.ok()) << events.message();
    ASSERT_EQ(events->size(), 1u);
    EXPECT_EQ((*events)[0].event, "press");
}

TEST(Session, TmpFilesIgnored) {
    // A crash between writing a frame's .tmp and its rename leaves a .tmp and no index line;
    // a crash after the rename but before the line leaves an unindexed file. Neither is a frame.
    const fs::path dir = freshDir("tmp");
    {
        auto writer = SessionWriter::create(dir.string());
        ASSERT_TRUE(writer.ok()) << writer.message();
        ASSERT_TRUE(writer->writeFrame("scene", 0, 100, kBytes, "png", 4, 4));
    }
    writeText(dir / "cameras" / "scene" / "000000000001.png.tmp", "half a frame");
    writeText(dir / "cameras" / "scene" / "index.csv.tmp", "garbage\n");
    writeText(dir / "session.toml.tmp", "garbage");
    // Old leftovers of a killed recorder: a reader is only given the take to read, so it
    // removes nothing (issue 52), however old.
    const auto old = fs::file_time_type::clock::now() - std::chrono::minutes(2);
    for (const fs::path& p :
         {dir / "cameras" / "scene" / "000000000001.png.tmp",
          dir / "cameras" / "scene" / "index.csv.tmp", dir / "session.toml.tmp"})
        fs::last_write_time(p, old);
    auto info = openSession(dir.string());
    ASSERT_TRUE(info.ok()) << info.message();
    ASSERT_EQ(info->cameras.size(), 1u);
    EXPECT_EQ(info->cameras[0].frames, 1u);
    for (const fs::path& p :
         {dir / "cameras" / "scene" / "000000000001.png.tmp",
          dir / "cameras" / "scene" / "index.csv.tmp", dir / "session.toml.tmp"})
        EXPECT_TRUE(fs::exists(p)) << "a reader deleted " << p;
    EXPECT_TRUE(fs::exists(dir / "cameras" / "scene" / "000000000000.png"));
    // Recording goes on after the crash's leftovers: the .tmp is simply overwritten.
    {
        auto writer = SessionWriter::create((dir / "second").string());
        ASSERT_TRUE(writer.ok()) << writer.message();
        writeText(dir / "second" / "cameras", "");  // not a folder: a clear error, no crash
        EXPECT_FALSE(writer->writeFrame("scene", 0, 100, kBytes, "png", 4, 4));
    }
}

// Issue 52: the writer's temporaries are new files of its own. Links planted at the names the
// writer used to take ("<file>.tmp", "lighting/<n>.tmp.exr") are neither followed nor truncated.
TEST(Session, WriterNeverWritesThroughAPlantedTemporary) {
    const fs::path dir = freshDir("planted");
    const fs::path victim = testing::scratchDir("session_test") / "planted_victim";
    writeText(victim, "keep me");
    fs::create_directories(dir / "cameras" / "scene");
    fs::create_directories(dir / "lighting");
    for (const fs::path& link :
         {dir / "session.toml.tmp", dir / "config.toml.tmp",
          dir / "cameras" / "scene" / "000000000000.png.tmp", dir / "lighting" / "000000.tmp.exr"})
        fs::create_symlink(victim, link);
    {
        SessionWriterOptions options;
        options.configToml = "[cameras.scene]\n";
        auto writer = SessionWriter::create(dir.string(), options);
        ASSERT_TRUE(writer.ok()) << writer.message();
        ASSERT_TRUE(writer->writeFrame("scene", 0, 100, kBytes, "png", 4, 4));
        ASSERT_TRUE(writer->writeLighting(
            150,
            [](AtomicFile& file) {
                const std::string bytes = "exr bytes";
                return file.write({reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()});
            },
            ""));
    }
    EXPECT_EQ(readText(victim), "keep me");
    EXPECT_EQ(readText(dir / "cameras" / "scene" / "000000000000.png"),
              std::string(kBytes.begin(), kBytes.end()));
    EXPECT_EQ(readText(dir / "lighting" / "000000.exr"), "exr bytes");
    EXPECT_EQ(readText(dir / "config.toml"), "[cameras.scene]\n");
    EXPECT_TRUE(fs::is_symlink(dir / "session.toml.tmp")) << "what was there is left as it was";
}

// Issue 52: what is written just before a quiet spell is made durable within flushInterval
// when its owner asks while idle (the recorder's writer thread does; takes_test checks the
// file itself), not at the next write.
TEST(Session, WriterSaysWhenAnIdleFlushIsDue) {
    const fs::path dir = freshDir("idle_flush");
    SessionWriterOptions options;
    options.flushInterval = std::chrono::milliseconds(50);
    auto writer = SessionWriter::create(dir.string(), options);
    ASSERT_TRUE(writer.ok()) << writer.message();
    EXPECT_FALSE(writer->flushDue().has_value()) << "nothing written yet";
    ASSERT_TRUE(writer->writeEvent({100, "ctl", "mode=refine"}));
    const std::optional<std::chrono::steady_clock::time_point> due = writer->flushDue();
    ASSERT_TRUE(due.has_value()) << "a line waits to be made durable";
    EXPECT_LE(*due - std::chrono::steady_clock::now(), options.flushInterval);
    std::this_thread::sleep_until(*due);
    ASSERT_TRUE(writer->flushIfDue());
    EXPECT_FALSE(writer->flushDue().has_value()) << "flushed while idle";
    EXPECT_TRUE(writer->flushIfDue()) << "nothing to do is no error";
}

TEST(Session, TakeIsTheCurrentVersion) {
    const fs::path dir = freshDir("take_version");
    ASSERT_TRUE(SessionWriter::create(dir.string()).ok());
    auto info = openSession(dir.string());
    ASSERT_TRUE(info.ok()) << info.message();
    EXPECT_EQ(info->version, kSessionFormatVersion);
}

TEST(Session, FrameStampsAndLightingRoundTrip) {
    const fs::path dir = freshDir("stamps");
    {
        auto writer = SessionWriter::create(dir.string());
        ASSERT_TRUE(writer.ok()) << writer.message();
        ASSERT_TRUE(writer->writeFrame("scene", 0, 100, kBytes, "jpg", 4, 4,
                                       {1796391907500000001ull, "13:45:07:15", -5.0f, "30"}));
        ASSERT_TRUE(writer->writeFrame("scene", 1, 200, kBytes, "jpg", 4, 4));
        EXPECT_FALSE(writer->writeFrame("scene", 2, 300, kBytes, "jpg", 4, 4, {1, "a,b", {}, ""}))
            << "a comma would shift the columns";
        const std::string lights = R"({"lights":[{"direction":[0,1,0]}]})";
        for (uint64_t t : {150u, 250u})
            ASSERT_TRUE(writer->writeLighting(
                t,
                [](AtomicFile& file) {
                    const std::string bytes = "exr bytes";
                    return file.write(
                        {reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size()});
                },
                lights));
        EXPECT_FALSE(writer->writeLighting(
            300, [](AtomicFile&) { return Status(makeError("disk full")); }, lights));
        EXPECT_FALSE(writer->writeLighting(
            300, [](AtomicFile&) { return Status{}; }, "two\nlines"));
    }
    auto frames = loadCameraIndex((dir / "cameras" / "scene").string());
    ASSERT_TRUE(frames.ok()) << frames.message();
    ASSERT_EQ(frames->size(), 2u);
    EXPECT_EQ((*frames)[0].wallClockNs, 1796391907500000001ull);
    EXPECT_EQ((*frames)[0].timecode, "13:45:07:15");
    EXPECT_EQ((*frames)[0].exposureStops, -5.0f);  // a bracket frame's exposure (v3)
    EXPECT_EQ((*frames)[0].timecodeRate, "30") << "the rate the label counts at (issue 54)";
    EXPECT_EQ((*frames)[1].timecodeRate, "");
    EXPECT_FALSE((*frames)[1].wallClockNs.has_value());
    EXPECT_FALSE((*frames)[1].exposureStops.has_value());
    auto lighting = loadLighting(dir.string());
    ASSERT_TRUE(lighting.ok()) << lighting.message();
    ASSERT_EQ(lighting->size(), 2u);
    EXPECT_EQ((*lighting)[1].timestampNs, 250u);
    EXPECT_EQ(readText((*lighting)[1].mapFile), "exr bytes");
    EXPECT_EQ((*lighting)[0].lightsJson, R"({"lights":[{"direction":[0,1,0]}]})");
    for (const auto& entry : fs::directory_iterator(dir / "lighting"))
        EXPECT_EQ(entry.path().string().find(".tmp"), std::string::npos)
            << "a failed snapshot leaves nothing: " << entry.path();
}

TEST(Session, ATakeFromElsewhereNamesOnlyFilesInsideIt) {
    const fs::path dir = freshDir("contained");
    fs::create_directories(dir / "config");
    writeText(dir / "config" / "board.toml", "x");
    writeText(dir.parent_path() / "outside.toml", "x");
    fs::create_symlink(dir.parent_path() / "outside.toml", dir / "config" / "link.toml");
    const std::string root = dir.string();
    auto good = containedPath(root, "config/board.toml", "config.toml");
    ASSERT_TRUE(good.ok()) << good.message();
    EXPECT_EQ(fs::path(*good), dir / "config" / "board.toml");
    EXPECT_TRUE(containedPath(root, "config", "config.toml", true).ok());
    for (const char* bad : {"/etc/passwd", "../outside.toml", "config/../../outside.toml",
                            "config/link.toml", "config/missing.toml", "config", ""}) {
        auto refused = containedPath(root, bad, "config.toml");
        ASSERT_FALSE(refused.ok()) << bad;
        EXPECT_NE(refused.message().find("config.toml"), std::string::npos) << refused.message();
    }
    // Frames are plain names in their camera's folder; files are read without following a
    // link, and only when regular (a FIFO would hang a reader).
    fs::create_directories(dir / "cameras" / "scene");
    writeText(dir / "cameras" / "scene" / "index.csv", "0,1,../../outside.toml,4,4\n");
    auto escaping = loadCameraIndex((dir / "cameras" / "scene").string());
    ASSERT_FALSE(escaping.ok());
    EXPECT_NE(escaping.message().find("index.csv:1: malformed"), std::string::npos)
        << escaping.message();
    // A bracket frame's exposure must be a number of stops (a hostile take cannot smuggle NaN
    // or a 2^1000 gain into the merge).
    for (const char* stops : {"nan", "-1e9", "x", "inf"}) {
        writeText(dir / "cameras" / "scene" / "index.csv",
                  fmt::format("0,1,a.jpg,4,4,,,{}\n", stops));
        auto bad = loadCameraIndex((dir / "cameras" / "scene").string());
        ASSERT_FALSE(bad.ok()) << stops;
        EXPECT_NE(bad.message().find("exposureStops"), std::string::npos) << bad.message();
    }
    EXPECT_FALSE(readSessionFile((dir / "config" / "link.toml").string()).ok());
    ASSERT_EQ(::mkfifo((dir / "fifo").c_str(), 0600), 0);
    auto fifo = readSessionFile((dir / "fifo").string());
    ASSERT_FALSE(fifo.ok());
    EXPECT_NE(fifo.message().find("not a regular file"), std::string::npos) << fifo.message();
    auto file = readSessionFile((dir / "config" / "board.toml").string());
    ASSERT_TRUE(file.ok()) << file.message();
    EXPECT_EQ(file->size(), 1u);
}

// A take with one camera frame, written as the recorder writes it.
fs::path smallTake(const std::string& name) {
    const fs::path dir = freshDir(name);
    auto writer = SessionWriter::create(dir.string());
    EXPECT_TRUE(writer.ok()) << writer.message();
    EXPECT_TRUE(writer->writeFrame("scene", 0, 100, kBytes, "png", 4, 4));
    EXPECT_TRUE(writer->writeEvent({5, "mode-button", "short-press"}));
    return dir;
}

void makeFifo(const fs::path& p) {
    fs::remove(p);
    ASSERT_EQ(::mkfifo(p.c_str(), 0600), 0) << p;
}

// Issue 52: a FIFO for any file of a take hung replay, render-session and export-track forever.
TEST(Session, AFifoInATakeIsRefusedAtOnce) {
    const fs::path dir = smallTake("fifo_take");
    testing::HangGuard guard("a reader given a FIFO", std::chrono::seconds(60));
    makeFifo(dir / "events.csv");
    auto events = loadEvents(dir.string());
    ASSERT_FALSE(events.ok());
    EXPECT_NE(events.message().find("events.csv"), std::string::npos) << events.message();
    EXPECT_NE(events.message().find("a FIFO"), std::string::npos) << events.message();

    makeFifo(dir / "poses.csv");
    EXPECT_FALSE(loadPoses(dir.string()).ok());
    fs::create_directories(dir / "lighting");
    makeFifo(dir / "lighting" / "index.csv");
    auto lighting = loadLighting(dir.string());
    ASSERT_FALSE(lighting.ok());
    EXPECT_NE(lighting.message().find("lighting/index.csv"), std::string::npos)
        << lighting.message();
    // An indexed map that is a FIFO, and a camera index that is one.
    writeText(dir / "lighting" / "index.csv.new", "1,000000.exr,{\"lights\":[]}\n");
    fs::rename(dir / "lighting" / "index.csv.new", dir / "lighting" / "index.csv");
    makeFifo(dir / "lighting" / "000000.exr");
    EXPECT_FALSE(loadLighting(dir.string()).ok());
    makeFifo(dir / "cameras" / "scene" / "index.csv");
    auto camera = openSession(dir.string());
    ASSERT_FALSE(camera.ok());
    EXPECT_NE(camera.message().find("index.csv"), std::string::npos) << camera.message();
    makeFifo(dir / "session.toml");
    EXPECT_FALSE(openSession(dir.string()).ok());
}

// A link to /dev/zero, or a sparse 3 GiB index, grew memory without bound: refused before a
// byte is read.
TEST(Session, EndlessOrHugeIndexFilesAreRefusedUnread) {
    const fs::path dir = smallTake("huge_take");
    testing::HangGuard guard("a reader given /dev/zero or a sparse file", std::chrono::seconds(60));
    fs::remove(dir / "events.csv");
    fs::create_symlink("/dev/zero", dir / "events.csv");
    auto zero = loadEvents(dir.string());
    ASSERT_FALSE(zero.ok());
    EXPECT_NE(zero.message().find("symbolic link"), std::string::npos) << zero.message();

    // Sparse files: 3 GiB long, no block on disk.
    auto sparse = [](const fs::path& p) {
        const int fd = ::open(p.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        ASSERT_GE(fd, 0);
        EXPECT_EQ(::ftruncate(fd, off_t(3) << 30), 0);
        ::close(fd);
    };
    sparse(dir / "poses.csv");
    auto huge = loadPoses(dir.string());
    ASSERT_FALSE(huge.ok());
    EXPECT_NE(huge.message().find("more than such a file may hold"), std::string::npos)
        << huge.message();
    sparse(dir / "cameras" / "scene" / "index.csv");
    EXPECT_FALSE(openSession(dir.string()).ok());
}

// An index linked to any readable file printed its lines in warnings, which a farm sends back
// to whoever submitted the take: a link is refused, and a malformed line is named by file and
// number only.
TEST(Session, ARejectedFileIsNamedNeverEchoed) {
    const fs::path dir = smallTake("echo_take");
    const fs::path secret = dir.parent_path() / "echo_secret.txt";
    writeText(secret, "root:SECRET-HASH:19000:0:99999:7:::\n");
    const fs::path index = dir / "cameras" / "scene" / "index.csv";
    fs::remove(index);
    fs::create_symlink(secret, index);
    auto linked = loadCameraIndex(index.parent_path().string());
    ASSERT_FALSE(linked.ok());
    EXPECT_EQ(linked.message().find("SECRET"), std::string::npos) << linked.message();
    EXPECT_NE(linked.message().find("symbolic link"), std::string::npos) << linked.message();

    // The same line in the take's own files: named by its number, never printed.
    fs::remove(index);
    fs::copy_file(secret, index);
    std::vector<std::string> skipped;
    auto lenient = loadCameraIndex(index.parent_path().string(), &skipped);
    ASSERT_TRUE(lenient.ok()) << lenient.message();
    ASSERT_EQ(skipped.size(), 1u);
    EXPECT_NE(skipped[0].find("index.csv:1:"), std::string::npos) << skipped[0];
    fs::copy_file(secret, dir / "events.csv", fs::copy_options::overwrite_existing);
    fs::copy_file(secret, dir / "poses.csv", fs::copy_options::overwrite_existing);
    fs::create_directories(dir / "lighting");
    fs::copy_file(secret, dir / "lighting" / "index.csv");
    for (const std::string& message :
         {skipped[0], loadEvents(dir.string()).error().message,
          loadPoses(dir.string()).error().message, loadLighting(dir.string()).error().message})
        EXPECT_EQ(message.find("SECRET"), std::string::npos) << message;
}

// The writer never makes a session its own readers would refuse: no config_dir outside it.
TEST(Session, WriterRefusesAConfigDirOutsideTheSession) {
    for (const std::string configDir : {"..", "/etc", "config/../.."}) {
        const fs::path dir = fs::path(::testing::TempDir()) / "previs_config_dir_out";
        fs::remove_all(dir);
        SessionWriterOptions options;
        options.configToml = "scene = \"scene.gltf\"\n";
        options.configDir = configDir;
        auto writer = SessionWriter::create(dir.string(), options);
        ASSERT_FALSE(writer.ok()) << configDir;
        EXPECT_NE(writer.message().find("leaves the session"), std::string::npos)
            << writer.message();
        EXPECT_FALSE(fs::exists(dir / "session.toml"));
    }
}

// A take is untrusted whatever version it declares (issue 52): a v2 label does not let its
// config's folder (config_dir) or its camera folders lie outside it.
TEST(Session, AnyVersionKeepsItsFoldersInside) {
    const fs::path dir = smallTake("v2_take");
    const fs::path outside = dir.parent_path() / "v2_outside";
    fs::remove_all(outside);
    fs::create_directories(outside);
    writeText(dir / "config.toml", "scene = \"scene.gltf\"\n");
    for (const std::string& configDir :
         std::vector<std::string>{"..", outside.string(), "missing"}) {
        writeText(dir / "session.toml",
                  fmt::format("format = \"previs-session\"\nversion = 2\nconfig_dir = \"{}\"\n",
                              configDir));
        auto info = openSession(dir.string());
        ASSERT_FALSE(info.ok()) << configDir;
        EXPECT_NE(info.message().find("config_dir"), std::string::npos) << info.message();
    }
    writeText(dir / "session.toml", "format = \"previs-session\"\nversion = 2\n");
    ASSERT_TRUE(openSession(dir.string()).ok());
    // A camera folder linked to frames elsewhere.
    fs::rename(dir / "cameras" / "scene", outside / "scene");
    fs::create_directory_symlink(outside / "scene", dir / "cameras" / "scene");
    auto linked = openSession(dir.string());
    ASSERT_FALSE(linked.ok());
    EXPECT_NE(linked.message().find("symbolic link"), std::string::npos) << linked.message();
    fs::remove(dir / "cameras" / "scene");
    fs::remove(dir / "cameras");
    fs::create_directory_symlink(outside, dir / "cameras");
    EXPECT_FALSE(openSession(dir.string()).ok());
}

}  // namespace
}  // namespace previs
