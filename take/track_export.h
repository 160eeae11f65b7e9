#pragma once

// `previs export-track` (DESIGN.md §3, docs/takes.md): a take's camera for post-production.
// - Nuke .chan: "frame tx ty tz rx ry rz vfov" a line, in the scene's glTF world (+Y up,
//   metres); the camera looks along its −Z with +Y up; rotation in degrees as Euler angles in
//   Nuke's default order ZXY (R = Ry·Rx·Rz: Z turns first), as Blender's bundled "Import Nuke
//   chan" add-on reads them (rotation order ZXY, "Make Z up" on); vfov in degrees.
// - JSON lines: one object a frame with the timing, the camera transform, the intrinsics and the
//   lens distortion, named as SMPTE RIS OpenTrackIO names them where it has the quantity.
// Frames without a pose (tracking lost, not bridged) are gaps.

#include <string>

#include "base/result.h"
#include "vision/camera_calibration.h"

namespace previs {

struct TrackExportOptions {
    std::string takeDir;
    std::string outPath;    // FILE.chan or FILE.jsonl
    bool smoothed = false;  // the smoothed track (vision/track_smoother.h), not the raw one
};

// OpenCV camera axes (x right, y down, z forward) → Nuke's ZXY Euler angles of the camera
// looking along −Z with +Y up, degrees (rx, ry, rz).
cv::Vec3d chanRotationDegrees(const cv::Matx33d& worldFromOpenCvCamera);

// The calibrated vertical field of view, degrees.
double verticalFovDegrees(const CameraCalibration& calibration);

// Exit code: 0 written; 1 nothing could be written; 2 a bad take or path.
int runTrackExport(const TrackExportOptions& options);

}  // namespace previs
