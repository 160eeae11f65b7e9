#pragma once

// The stages between the cameras and the renderer (DESIGN.md §1), as plain objects that take a
// frame and give an immutable snapshot. The service runs each on its own thread; `previs replay`
// calls them in lock step on one thread, so both run the very same code.

#include <array>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/atomic_file.h"
#include "base/result.h"
#include "capture/frame.h"
#include "config/service_config.h"
#include "render/lighting_fit.h"
#include "scene/scene.h"
#include "shot/freed_input.h"
#include "timecode/timecode.h"
#include "vision/board_pose.h"
#include "vision/fisheye_to_equirect.h"
#include "vision/hdr_bracket.h"
#include "vision/light_estimator.h"
#include "vision/pose_filter.h"

namespace previs {

// A scene-camera frame with the pose tracked on that very frame: picture and pose travel
// together, so they cannot slip against each other (no delay calibration needed).
struct TrackedFrame {
    std::shared_ptr<const Frame> frame;
    // OpenCV camera axes (x right, y down, z forward), the board's world frame. The pose to
    // composite with: the live pose filter's with [tracking] pose_filter (vision/pose_filter.h),
    // else the tracker's; the last good one while tracking is lost; none before the first.
    std::optional<cv::Matx44d> worldFromCamera;
    // The tracker's own pose on this very frame, unfiltered (none when lost): what a take
    // records as "tracked" and the offline smoother starts from.
    std::optional<cv::Matx44d> trackedWorldFromCamera;
    bool filtered = false;  // worldFromCamera is the filter's
    bool lost = true;
    int tags = 0;
    double reprojErrorPx = 0.0;
    // The pose's one-sigma uncertainty (BoardPose::positionStdM, rotationStdDeg).
    double positionStdM = 0.0;
    double rotationStdDeg = 0.0;
    std::string reason;                          // why this frame gave no trusted pose
    LostReason lostReason = LostReason::NoTags;  // its kind (None: a trusted pose)
    double trackMs = 0.0;
    // When the tracking stage took the frame (steady clock, CLOCK_MONOTONIC), for latency when
    // the frame's own timestamp is not on this machine's clock (a recording).
    int64_t receivedNs = 0;
    // The frame's SMPTE timecode ([timecode], docs/timecode.md); none before a source is set.
    std::optional<Timecode> timecode;
};

// When the frame was captured on this machine's CLOCK_MONOTONIC (`nowNs`'s clock): a live
// camera's own timestamp; a recording's is hours or days old, so there the tracking stage's
// receipt stands in for capture. For latencies.
int64_t captureInstantNs(const TrackedFrame& frame, int64_t nowNs);

// The set's lighting from one fisheye frame: the environment map and, in the "lights" mode,
// the light sources estimated from it (the map then holds the residual).
struct LiveLighting {
    std::shared_ptr<const EnvironmentMap> environment;
    std::vector<EstimatedLight> lights;
    double totalLuminancePower = 0.0;  // ∫ luminance dω of the whole map
    // The map's luminance projected on the real spherical harmonics of bands 0–2 (world frame,
    // coefficient index l² + l + m), before any light is split off: what a diffuse surface sees
    // of the lighting (Ramamoorthi & Hanrahan 2001), and what a refinement restart compares —
    // unlike the total power it moves when the lighting turns (shot/refine_watch.h).
    std::array<double, 9> luminanceSh{};
    uint64_t sequence = 0;  // the fisheye frame's sequence
    uint64_t timestampNs = 0;
    double computeMs = 0.0;
    // The whole map as captured, before any light was split off (what saveLighting keeps).
    std::shared_ptr<const EnvironmentMap> captured;
    // Read back from the box's saved lighting (LightingStage::restore), not captured since the
    // service started: it stands in, and the status still says lighting is pending.
    bool restored = false;
    // Merged from a bracket of this many fisheye frames (0: one frame, not bracketed).
    int bracketFrames = 0;
    // Texels whose light even the bracket's shortest exposure clipped (CV_8U, 255 = clipped; empty
    // when none): their radiance is only a lower bound. Their share of the sphere's solid angle.
    cv::Mat clippedTexels;
    double clippedSolidAngleFraction = 0.0;
};

// Keeps `lighting`'s captured map at `path` (OpenEXR), written to a temporary beside it and
// renamed (base/atomic_file.h), so the file is whole or absent.
Status saveLighting(const LiveLighting& lighting, const std::string& path);
// Writes `lighting`'s captured map into `file` as OpenEXR; the caller commits it.
Status writeLightingMap(const LiveLighting& lighting, AtomicFile& file);

class TrackingStage {
public:
    // With [tracking] source = "freed" the pose comes from `freed` (the service's live input);
    // none given, from the take's own freed.csv when the scene camera is a recording.
    static Result<TrackingStage> create(const ServiceConfig& config,
                                        std::shared_ptr<FreedInput> freed = nullptr);
    TrackedFrame process(std::shared_ptr<const Frame> frame);

private:
    TrackingStage(Tracker tracker, cv::Size calibrated, std::optional<PoseFilter> filter)
        : tracker_(std::move(tracker)), calibrated_(calibrated), filter_(std::move(filter)) {}
    // The pose from the tracker's packets: lost (NoTrackerData) when none lies near the frame.
    void trackFreed(TrackedFrame& out);
    std::shared_ptr<FreedInput> freed_;
    // Live: how long a frame waits for the packet of its instant (the calibrated delay and a
    // packet interval); a recording's are all there.
    std::chrono::milliseconds freedWait_{0};
    std::optional<cv::Matx44d> lastFreed_;
    bool freedLive_ = false;  // packets arriving now, not a take's freed.csv
    Tracker tracker_;
    cv::Size calibrated_;  // frames of another size would give plausible but wrong poses
    bool loggedSize_ = false;
    std::optional<PoseFilter> filter_;
};

class LightingStage {
public:
    // Needs config.fisheyeCamera.
    static Result<LightingStage> create(const ServiceConfig& config);
    // Whether this frame goes to process(): by its timestamp under [lighting] update_hz; with a
    // bracket, every frame of one in progress and the first of one whose time has come.
    bool due(const Frame& fisheyeFrame) const;
    // The snapshot this frame makes, or null when it makes none: a bracket still in progress, or
    // dropped (bracketCounts() and lastBracketDrop() say why).
    Result<std::shared_ptr<const LiveLighting>> process(const Frame& fisheyeFrame);
    // With [cameras.fisheye.bracket]: what became of the brackets so far; null without.
    const BracketCounts* bracketCounts() const;
    std::string lastBracketDrop() const;
    // The snapshot of a map saveLighting wrote (its lights estimated again, as for a frame),
    // marked restored.
    Result<std::shared_ptr<const LiveLighting>> restore(const std::string& path);

private:
    // A snapshot of an equirectangular map (linear radiance, CV_32FC3) named `name`.
    Result<std::shared_ptr<LiveLighting>> fromMap(const cv::Mat& map, const std::string& name);
    LightingStage(FisheyeToEquirect toEquirect, InverseToneMapSettings radiometry,
                  std::optional<BracketAssembler> bracket, LightingMode mode,
                  LightEstimatorSettings lights, double updateHz)
        : toEquirect_(std::move(toEquirect)),
          radiometry_(radiometry),
          bracket_(std::move(bracket)),
          mode_(mode),
          estimator_(lights),
          periodNs_(updateHz > 0.0 ? uint64_t(1e9 / updateHz) : 0) {}
    // The map of one bracket's merged radiance, its clipped texels flagged.
    Result<std::shared_ptr<LiveLighting>> fromBracket(const MergedBracket& merged);
    FisheyeToEquirect toEquirect_;
    InverseToneMapSettings radiometry_;
    std::optional<BracketAssembler> bracket_;
    LightingMode mode_;
    LightEstimator estimator_;
    uint64_t periodNs_;
    std::optional<uint64_t> lastNs_;
};

// `lighting` with a fit to the plate applied (render/lighting_fit.h): its clipped clusters and
// every texel of its maps corrected, its estimated lights scaled by the gain of the cluster in
// their direction and the global gain, its moments computed again. Null `lighting`: null.
std::shared_ptr<const LiveLighting> correctedLighting(
    const std::shared_ptr<const LiveLighting>& lighting, const LightingCorrection& correction);

// The estimated lights as `previs lights --json` prints them, one line:
// {"lights":[{"direction":[x,y,z],"solidAngleSr":s,"radiance":[r,g,b]},...]}.
std::string estimatedLightsJson(const std::vector<EstimatedLight>& lights);

// How far apart two poses are: translation (metres) and rotation angle (degrees).
struct PoseDelta {
    double translationM = 0.0;
    double rotationDeg = 0.0;
};
PoseDelta poseDelta(const cv::Matx44d& a, const cv::Matx44d& b);

// The nine orthonormal real spherical harmonics of bands 0–2 at unit direction d, index
// l² + l + m (Sloan's "Stupid SH tricks" table; any axis order keeps each band's norm).
std::array<double, 9> realShBand2(const cv::Vec3d& d);

}  // namespace previs
