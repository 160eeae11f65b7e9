#include "cli/freed_calibrate_command.h"

#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "base/command_line.h"
#include "base/log.h"
#include "base/strings.h"
#include "io/session.h"
#include "net/freed_calibration.h"
#include "take/take_files.h"
#include "take/take_track.h"

namespace previs {

namespace {

namespace fs = std::filesystem;

struct FreedCalibrateOptions {
    std::string takeDir;
    std::string outPath;  // default: TAKE/freed_calibration.toml
    std::optional<int> cameraId;
    bool recordedPoses = false;
};

// The tag tracker's worldFromCamera of the take's frames: tracked again on every frame (as the
// offline tools do), or as the live service wrote them in poses.csv (faster; only the frames it
// kept up with).
Result<std::vector<TimedPose>> cameraPoses(const SessionInfo& session, bool recordedPoses) {
    std::vector<TimedPose> out;
    if (recordedPoses) {
        Result<std::vector<PoseRecord>> poses = loadPoses(session.dir);
        if (!poses) return poses.error();
        for (const PoseRecord& p : *poses) {
            if (p.kind != PoseKind::Tracked || !p.worldFromCamera) continue;
            TimedPose t{int64_t(p.timestampNs), cv::Matx44d(p.worldFromCamera->data())};
            out.push_back(t);
        }
        return out;
    }
    Result<ServiceConfig> config = loadSessionConfig(session);
    if (!config) return config.error();
    Result<TakeTrack> track = trackTake(session, *config);
    if (!track) return track.error();
    for (const std::string& line : track->skippedLines) logWarning("freed-calibrate: {}", line);
    for (const TakeFrame& f : track->frames)
        if (f.tracked) out.push_back({int64_t(f.entry.timestampNs), *f.tracked});
    return out;
}

std::string matrixRows(const cv::Matx44d& m) {
    std::string out;
    for (int r = 0; r < 3; ++r)
        out += fmt::format("    [{:9.6f} {:9.6f} {:9.6f} | {:9.4f}]\n", m(r, 0), m(r, 1), m(r, 2),
                           m(r, 3));
    return out;
}

void printCalibration(const FreedCalibration& c, const FreedDelay& delay) {
    const cv::Vec3d offsetMm(c.bodyFromCamera(0, 3) * 1e3, c.bodyFromCamera(1, 3) * 1e3,
                             c.bodyFromCamera(2, 3) * 1e3);
    fmt::print(
        "delay: {:.2f} ms ± {:.2f} (packets after frames; from the rotation speeds {:.1f} ms, "
        "correlation {:.3f}, fastest turn {:.0f}°/s)\n"
        "mount offset (lens centre in the tracker's axes: x right, y down, z forward): "
        "{:.1f} {:.1f} {:.1f} mm, ±{:.1f} mm / ±{:.2f}° (1σ)\n"
        "body_from_camera:\n{}world_from_stage:\n{}"
        "residuals: {:.2f} mm, {:.3f}° RMS over {} frames ({} left out)\n",
        c.delayMs, c.delaySigmaMs, delay.delayMs, delay.correlation, delay.peakSpeedDegPerS,
        offsetMm[0], offsetMm[1], offsetMm[2], c.mountSigmaMm, c.mountSigmaDeg,
        matrixRows(c.bodyFromCamera), matrixRows(c.worldFromStage), c.rmsPositionMm,
        c.rmsRotationDeg, c.samples, c.rejected);
}

int runFreedCalibrate(const FreedCalibrateOptions& o) {
    const std::string packetsPath = (fs::path(o.takeDir) / "freed.csv").string();
    const std::string outPath =
        o.outPath.empty() ? (fs::path(o.takeDir) / "freed_calibration.toml").string() : o.outPath;
    Result<SessionInfo> session = openSession(o.takeDir);
    if (!session) {
        logError("freed-calibrate: {}", session.message());
        return kExitUsage;
    }
    std::optional<uint8_t> cameraId;
    if (o.cameraId) cameraId = uint8_t(*o.cameraId);
    Result<FreedRecording> recording = loadFreedRecording(packetsPath, cameraId);
    if (!recording) {
        logError("freed-calibrate: {}", recording.message());
        return kExitUsage;
    }
    if (!cameraId && recording->cameraIds.size() > 1) {
        std::vector<std::string> ids;
        for (uint8_t id : recording->cameraIds) ids.push_back(std::to_string(id));
        logError("freed-calibrate: '{}' holds packets of cameras {}: choose one with --camera-id",
                 packetsPath, joined(ids));
        return kExitUsage;
    }
    if (recording->stageFromBody.empty() && !recording->cameraIds.empty()) {
        std::vector<std::string> ids;
        for (uint8_t id : recording->cameraIds) ids.push_back(std::to_string(id));
        logError("freed-calibrate: '{}' has no packets of camera {} (it has {}): check --camera-id",
                 packetsPath, *o.cameraId, joined(ids));
        return kExitUsage;
    }
    if (recording->rejected > 0)
        logWarning(
            "freed-calibrate: '{}': {} datagram(s) were not valid FreeD D1 and are left "
            "out",
            packetsPath, recording->rejected);
    Result<std::vector<TimedPose>> camera = cameraPoses(*session, o.recordedPoses);
    if (!camera) {
        logError("freed-calibrate: {}", camera.message());
        return kExitUsage;
    }
    if (camera->empty() && o.recordedPoses) {
        logError(
            "freed-calibrate: '{}' has no tracked poses: leave out --recorded-poses to track "
            "every frame of the take",
            (fs::path(o.takeDir) / "poses.csv").string());
        return kExitUsage;
    }
    Result<FreedDelay> delay = estimateFreedDelay(*camera, recording->stageFromBody);
    if (!delay) {
        logError("freed-calibrate: '{}': {}", o.takeDir, delay.message());
        return kExitUsage;
    }
    Result<FreedCalibration> calibration =
        solveFreedCalibration(*camera, recording->stageFromBody, *delay);
    if (!calibration) {
        logError("freed-calibrate: '{}' (delay {:.1f} ms): {}", o.takeDir, delay->delayMs,
                 calibration.message());
        return kExitUsage;
    }
    printCalibration(*calibration, *delay);
    std::fflush(stdout);  // the result before the log line that says where it went
    if (Status s = writeFreedCalibration(outPath, *calibration); !s) {
        logError("freed-calibrate: {}", s.message());
        return kExitFailure;
    }
    logInfo("freed-calibrate: written to {}", outPath);
    return kExitOk;
}

}  // namespace

std::function<int()> addFreedCalibrateCommand(CLI::App& app) {
    auto o = std::make_shared<FreedCalibrateOptions>();
    CLI::App* cmd = app.add_subcommand(
        "freed-calibrate",
        "measure a FreeD tracker's delay and mount offset from a take (docs/freed.md)");
    cmd->add_option("TAKE", o->takeDir,
                    "a take with the board in view and the tracker's packets (freed.csv)")
        ->required()
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--out", o->outPath,
                    "where to write it (default: TAKE/freed_calibration.toml)");
    cmd->add_option("--camera-id", o->cameraId,
                    "use only the packets of this FreeD camera id (needed when several)")
        ->check(CLI::Range(0, 255));
    cmd->add_flag("--recorded-poses", o->recordedPoses,
                  "use the tracked poses in poses.csv instead of tracking every frame again");
    return [o] { return runFreedCalibrate(*o); };
}

}  // namespace previs
