#pragma once

// The tracked pose in the axes the set's protocols share (docs/freed.md, docs/opentrackio.md).
//
// Our world is glTF's: right-handed, +Y up, metres; our camera frame is OpenCV's (x right, y down,
// z forward). OpenTrackIO's stage is right-handed, +Z up, +Y the forward direction of a camera at
// pan = tilt = roll = 0, +X camera-right; rotations intrinsic Z-X-Y (pan about Z, tilt about X,
// roll about Y), each positive by the right-hand rule. FreeD's X/Y/height are the same stage axes
// (Unreal's Live Link FreeD swaps X and Y into its left-handed X-forward frame); only FreeD's pan
// has the opposite sign (clockwise seen from above, as Unreal's yaw).
//
// World → stage: stage X = world x, stage Y = −world z, stage Z = world y, so a camera with the
// glTF default orientation (looking along world −Z, up +Y) has pan = tilt = roll = 0.

#include <opencv2/core.hpp>

namespace previs {

struct StagePose {
    cv::Vec3d translationM;  // stage X, Y, Z of the camera's optical centre, metres
    double panDeg = 0;       // about stage Z, positive turns the view from +Y towards −X (left)
    double tiltDeg = 0;      // about the camera's X after pan, positive looks up; in [−90, 90]
    double rollDeg = 0;      // about the camera's Y (the view axis) after tilt
};

// The stage rotation of a camera whose OpenCV-axes pose in the world is `worldFromCamera` (a
// rigid transform). Pan and roll come out in (−180, 180]. At tilt ±90° (gimbal lock) pan and roll
// turn about the same axis: roll is set to 0 and pan carries the whole turn.
StagePose stagePoseFromWorld(const cv::Matx44d& worldFromCamera);

// The inverse: the worldFromCamera (OpenCV camera axes) of a stage pose.
cv::Matx44d worldFromStagePose(const StagePose& pose);

// The worldFromCamera (OpenCV camera axes) of a camera body with stage rotation `stageFromBody`
// (columns: right, forward, up) at `translationM` in stage axes.
cv::Matx44d worldFromStage(const cv::Matx33d& stageFromBody, const cv::Vec3d& translationM);

// Rz(pan)·Rx(tilt)·Ry(roll), degrees: the stage rotation of the camera body (columns: camera
// right, forward, up in stage axes).
cv::Matx33d stageRotation(double panDeg, double tiltDeg, double rollDeg);

}  // namespace previs
