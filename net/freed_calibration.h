#pragma once

// FreeD in: the two calibrations that turn a tracker's or PTZ head's packets into our camera pose
// (docs/freed.md, "FreeD in: calibration").
//
// A packet gives stageFromBody (worldFromFreed(packet): the tracker's stage taken as our world,
// its body as the camera). The camera's pose in the tag board's world is
//     worldFromCamera = worldFromStage · stageFromBody · bodyFromCamera
// at the camera frame time t, with the packet series read at t + delay. worldFromStage (where the
// tracker's origin and axes lie in the board's world), bodyFromCamera (the mount offset: tracker
// head to the lens's optical centre) and the delay are measured once, from a take in which the
// board is visible while the operator pans, tilts and stops the camera a few times.
//
// Per frame ([tracking] source = "freed"), with the packets received so far as TimedPoses of
// worldFromFreed(packet) at their receipt time:
//     std::optional<cv::Matx44d> pose = freedWorldFromCamera(calibration, packets, frameNs);
//     if (!pose) the frame has no pose (lost): no packets around frameNs + delay yet, or a gap.

#include <cstdint>
#include <opencv2/core.hpp>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

// A pose at a CLOCK_MONOTONIC time: a camera frame's capture time, a packet's receipt time.
struct TimedPose {
    int64_t timestampNs = 0;
    cv::Matx44d pose = cv::Matx44d::eye();
};

struct FreedCalibration {
    cv::Matx44d worldFromStage = cv::Matx44d::eye();
    cv::Matx44d bodyFromCamera = cv::Matx44d::eye();
    // Receipt time of a packet minus the capture time of the frame showing the same instant: the
    // pose of the frame captured at t is the packet series read at t + delayMs.
    double delayMs = 0;
    // Its 1σ from the fit of the poses (0 when the fit could not refine the correlation's).
    double delaySigmaMs = 0;
    // The normalised cross-correlation of the two rotation speeds at the delay (1 = identical).
    double delayCorrelation = 0;
    // RMS over the samples kept of (calibrated FreeD pose vs the tag-tracked pose).
    double rmsPositionMm = 0;
    double rmsRotationDeg = 0;
    // 1σ uncertainty of bodyFromCamera in its worst direction, from the fit's covariance: what
    // the take can tell about the mount offset (large when the camera turned about one axis).
    double mountSigmaMm = 0;
    double mountSigmaDeg = 0;
    int samples = 0;      // frame/packet pairs the solution uses
    int rejected = 0;     // pairs left out as outliers
    std::string created;  // RFC 3339 UTC; empty until written
};

// worldFromCamera of a packet's stageFromBody (worldFromFreed(packet)).
cv::Matx44d applyFreedCalibration(const FreedCalibration& calibration,
                                  const cv::Matx44d& stageFromBody);

// A longer gap between two packets is a lost stretch, not bridged: 2.5 packet intervals at
// 25 Hz, the slowest rate trackers and PTZ heads commonly send.
inline constexpr int64_t kFreedMaxGapNs = 100'000'000;

// The pose at `timestampNs` from a time-sorted series: rotation slerped, translation lerped
// between the two samples around it. Nothing when the time is outside the series or the two
// samples are more than `maxGapNs` apart (a lost stretch is not bridged).
std::optional<cv::Matx44d> interpolatePose(std::span<const TimedPose> series, int64_t timestampNs,
                                           int64_t maxGapNs);

// The camera's worldFromCamera for the frame captured at `frameNs`: the packets (stageFromBody
// at receipt time, sorted) read at frameNs + delay, then applyFreedCalibration. Nothing when the
// packets do not reach that time yet or have a gap there.
std::optional<cv::Matx44d> freedWorldFromCamera(const FreedCalibration& calibration,
                                                std::span<const TimedPose> stageFromBody,
                                                int64_t frameNs, int64_t maxGapNs = kFreedMaxGapNs);

struct FreedDelay {
    double delayMs = 0;
    double correlation = 0;       // normalised cross-correlation at the peak
    double peakSpeedDegPerS = 0;  // the camera's fastest turn seen, for the report
};

struct FreedDelayOptions {
    double searchMs = 500;  // the delay is searched in [−searchMs, searchMs]
    double stepMs = 1;      // grid of the search before the parabolic refinement
    // Below this the camera did not turn enough to time anything (a held camera).
    double minPeakSpeedDegPerS = 5;
    // Below this the two motions do not match (wrong take, wrong camera id, a lost stretch).
    double minCorrelation = 0.8;
    // Another local maximum this close to the peak, with a valley this deep between them, makes
    // the delay ambiguous.
    double minPeakMargin = 0.05;
};

// The delay between the packets (stageFromBody at receipt time) and the camera frames
// (tag-tracked worldFromCamera at capture time), from the rotation speed of each: the angle
// turned between consecutive frames is the same in both series whatever worldFromStage and
// bodyFromCamera are. Fails, saying why, on too little motion or an indistinct peak.
Result<FreedDelay> estimateFreedDelay(std::span<const TimedPose> worldFromCamera,
                                      std::span<const TimedPose> stageFromBody,
                                      const FreedDelayOptions& options = {});

struct FreedSolveOptions {
    // Pairs farther than this from the solution (and than 3.5 robust sigmas) are left out.
    double outlierFloorMm = 5;
    double outlierFloorDeg = 0.5;
    // The rotations must turn about a second axis at least this far from the first (RMS angle of
    // the turn axes about their main direction), else bodyFromCamera's offset along the
    // turn axis cannot be told from worldFromStage's.
    double minAxisSpreadDeg = 5;
    size_t maxSamples = 600;  // evenly thinned beyond this: the solve grows as N²
    // A mount offset less certain than this (1σ) is refused, naming the motion to add: an
    // overlay off by a centimetre at the lens slides visibly against the set.
    double maxMountSigmaMm = 5;
    double maxMountSigmaDeg = 0.5;
};

// worldFromStage and bodyFromCamera (OpenCV's calibrateRobotWorldHandEye, then refined together)
// from the frames of `worldFromCamera`, each paired with the packet series read at its time +
// delay; the delay itself is refined to the one the poses fit best, near delay.delayMs.
Result<FreedCalibration> solveFreedCalibration(std::span<const TimedPose> worldFromCamera,
                                               std::span<const TimedPose> stageFromBody,
                                               const FreedDelay& delay,
                                               const FreedSolveOptions& options = {});

// freed_calibration.toml (docs/freed.md). `created` is written as given (now when empty).
Status writeFreedCalibration(const std::string& path, const FreedCalibration& calibration);
Result<FreedCalibration> loadFreedCalibration(const std::string& path);

// A take's freed.csv: the header, then one line per datagram received: CLOCK_MONOTONIC ns at
// receipt, the datagram's bytes as lowercase hex.
inline constexpr const char* kFreedRecordingHeader = "receivedNs,packet";
std::string freedRecordingLine(int64_t receivedNs, std::span<const uint8_t> datagram);

struct FreedRecording {
    std::vector<TimedPose> stageFromBody;  // worldFromFreed of each valid packet, by time
    size_t rejected = 0;                   // datagrams decodeFreed refused (size, checksum...)
    std::vector<uint8_t> cameraIds;        // the camera ids seen, ascending
};
// The largest freed.csv read (checked before reading): about 4 h of a tracker at 60 Hz.
inline constexpr uint64_t kMaxFreedRecordingBytes = uint64_t(256) << 20;
// Reads freed.csv (a regular file, no link followed); packets of other cameras are skipped when
// `cameraId` is set. A malformed line is an error naming the file and the line.
Result<FreedRecording> loadFreedRecording(const std::string& path, std::optional<uint8_t> cameraId);

}  // namespace previs
