#include "take/track_export.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "base/atomic_file.h"
#include "base/log.h"
#include "take/take_files.h"
#include "take/take_track.h"
#include "timecode/timecode.h"

namespace previs {

namespace fs = std::filesystem;

namespace {

constexpr double kDegrees = 180.0 / CV_PI;

std::string chanLine(size_t frame, const cv::Matx44d& m, double vfov) {
    const cv::Vec3d r = chanRotationDegrees(m.get_minor<3, 3>(0, 0));
    return fmt::format("{} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f} {:.9f}\n", frame, m(0, 3),
                       m(1, 3), m(2, 3), r[0], r[1], r[2], vfov);
}

nlohmann::ordered_json jsonLine(size_t frame, const TakeFrame& f, const cv::Matx44d& m,
                                const CameraCalibration& calibration, const LabelRateRule& boxRule,
                                bool smoothed) {
    nlohmann::ordered_json j;
    j["frame"] = frame;
    nlohmann::ordered_json timing;
    timing["sequenceNumber"] = frame;
    timing["monotonicNs"] = f.entry.timestampNs;
    if (f.entry.wallClockNs)
        timing["sampleTimestamp"] = {{"seconds", *f.entry.wallClockNs / 1'000'000'000ull},
                                     {"nanoseconds", *f.entry.wallClockNs % 1'000'000'000ull}};
    // The label the take holds, at the rate it was labelled at (timecode/timecode.h labelRate;
    // the box's rule for takes from before the rate column).
    const TimecodeRate rate = labelRate(f.entry.timecode, f.entry.timecodeRate, boxRule);
    Result<Timecode> tc = Timecode::parse(f.entry.timecode, rate);
    if (tc)
        timing["timecode"] = {{"hours", tc->hours()},
                              {"minutes", tc->minutes()},
                              {"seconds", tc->seconds()},
                              {"frames", tc->frames()},
                              {"frameRate", {{"num", rate.num()}, {"denom", rate.den()}}},
                              {"dropFrame", rate.dropFrame()}};
    j["timing"] = timing;
    nlohmann::ordered_json matrix = nlohmann::ordered_json::array();
    for (int i = 0; i < 16; ++i) matrix.push_back(m(i / 4, i % 4));
    j["worldFromCamera"] = matrix;
    const cv::Vec3d r = chanRotationDegrees(m.get_minor<3, 3>(0, 0));
    // The same camera as the .chan line, for tools that read OpenTrackIO's transform names:
    // here pan, tilt and roll are the ZXY angles about +Y, +X and +Z of the glTF world.
    j["transforms"] = {{{"id", "Camera"},
                        {"translation", {{"x", m(0, 3)}, {"y", m(1, 3)}, {"z", m(2, 3)}}},
                        {"rotation", {{"pan", r[1]}, {"tilt", r[0]}, {"roll", r[2]}}}}};
    j["intrinsics"] = {{"fx", calibration.fx()},
                       {"fy", calibration.fy()},
                       {"cx", calibration.cx()},
                       {"cy", calibration.cy()},
                       {"width", calibration.imageSize().width},
                       {"height", calibration.imageSize().height}};
    const std::vector<double>& d = calibration.distortion();
    nlohmann::ordered_json distortion;
    if (calibration.model() == DistortionModel::Fisheye) {
        distortion["model"] = "OpenCV fisheye (Kannala-Brandt) U-D";
        distortion["radial"] = d;
    } else {
        // OpenCV's k1 k2 p1 p2 [k3 ...]: radial then tangential.
        distortion["model"] = "Brown-Conrady U-D";
        std::vector<double> radial, tangential;
        for (size_t i = 0; i < d.size(); ++i)
            (i == 2 || i == 3 ? tangential : radial).push_back(d[i]);
        distortion["radial"] = radial;
        distortion["tangential"] = tangential;
    }
    distortion["direction"] =
        "undistorted to distorted: maps ideal normalised pinhole coordinates to the image's";
    j["lens"] = {{"distortion", nlohmann::ordered_json::array({distortion})}};
    j["tracker"] = {{"status", f.tracked ? "tracked" : "bridged"},
                    {"smoothed", smoothed},
                    {"tags", f.tags},
                    {"reprojErrorPx", f.reprojErrorPx}};
    return j;
}

}  // namespace

cv::Vec3d chanRotationDegrees(const cv::Matx33d& worldFromOpenCvCamera) {
    // OpenCV's camera (y down, z forward) → the camera looking along −Z with +Y up.
    const cv::Matx33d r = worldFromOpenCvCamera * cv::Matx33d(1, 0, 0, 0, -1, 0, 0, 0, -1);
    // R = Ry(b)·Rx(a)·Rz(c): r12 = −sin a, r02 = sin b cos a, r22 = cos b cos a,
    // r10 = cos a sin c, r11 = cos a cos c.
    const double a = std::asin(std::clamp(-r(1, 2), -1.0, 1.0));
    double b, c;
    if (std::abs(r(1, 2)) < 1.0 - 1e-12) {
        b = std::atan2(r(0, 2), r(2, 2));
        c = std::atan2(r(1, 0), r(1, 1));
    } else {
        // Looking straight up or down: only b ± c is defined; c = 0.
        b = std::atan2(-r(2, 0), r(0, 0));
        c = 0.0;
    }
    return {a * kDegrees, b * kDegrees, c * kDegrees};
}

double verticalFovDegrees(const CameraCalibration& calibration) {
    return 2.0 * std::atan(0.5 * double(calibration.imageSize().height) / calibration.fy()) *
           kDegrees;
}

int runTrackExport(const TrackExportOptions& o) {
    const std::string ext = fs::path(o.outPath).extension().string();
    if (ext != ".chan" && ext != ".jsonl") {
        logError("export-track: '{}': the file must end in .chan (Nuke) or .jsonl", o.outPath);
        return 2;
    }
    Result<SessionInfo> session = openSession(o.takeDir);
    if (!session) {
        logError("export-track: {}", session.message());
        return 2;
    }
    Result<ServiceConfig> config = loadSessionConfig(*session);
    if (!config) {
        logError("export-track: {}", config.message());
        return 2;
    }
    Result<TakeTrack> track = trackTake(*session, *config);
    if (!track) {
        logError("export-track: {}", track.message());
        return 2;
    }
    for (const std::string& line : track->skippedLines) logWarning("export-track: {}", line);
    const CameraCalibration& calibration = *config->sceneCamera.calibration;
    const double vfov = verticalFovDegrees(calibration);
    Result<LabelRateRule> boxRule = labelRateRule(*config, config->sceneCamera);
    if (!boxRule) {
        logError("export-track: {}", boxRule.message());
        return 2;
    }
    std::string text;
    size_t written = 0, gaps = 0;
    for (size_t i = 0; i < track->frames.size(); ++i) {
        const TakeFrame& f = track->frames[i];
        const std::optional<cv::Matx44d>& pose = o.smoothed ? f.smoothed : f.tracked;
        if (!pose) {
            ++gaps;
            continue;
        }
        if (ext == ".chan")
            text += chanLine(i, *pose, vfov);
        else
            text += jsonLine(i, f, *pose, calibration, *boxRule, o.smoothed).dump() + "\n";
        ++written;
    }
    // Whole or not at all, beside the target (base/atomic_file.h); not synced, as before.
    if (Status s =
            writeFileAtomic(o.outPath, {reinterpret_cast<const uint8_t*>(text.data()), text.size()},
                            {.durable = false});
        !s) {
        logError("export-track: cannot write {}: {}", o.outPath, s.message());
        return 1;
    }
    logInfo("export-track: {} frame(s) of {} written to {}{}", written, track->frames.size(),
            o.outPath, gaps ? fmt::format(" ({} without a pose are gaps)", gaps) : "");
    return written > 0 ? 0 : 1;
}

}  // namespace previs
