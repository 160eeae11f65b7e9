#pragma once

// A camera of the service config as a running CameraSource (DESIGN.md §1: every source has a
// live and a recorded implementation): V4L2 with the config's controls applied on every open,
// libcamera with its typed controls, or a recorded session camera looping like a demo reel.

#include <memory>

#include "capture/camera_source.h"
#include "config/service_config.h"

namespace previs {

// `loop`: a recorded camera starts over at its end (timestamps keep increasing), as previsd
// plays a demo session; otherwise it finishes. `onFrame`: CaptureOptions::onFrame (the take
// recorder's tap); `keepCaptured`: while set, live frames carry their bytes as captured;
// `stage`: CaptureOptions::stage (the service's watch over the capture thread).
std::unique_ptr<CameraSource> makeCameraSource(
    const CameraConfig& camera, bool loop,
    std::function<void(const std::shared_ptr<const Frame>&)> onFrame = {},
    const std::atomic<bool>* keepCaptured = nullptr, Stage* stage = nullptr);

}  // namespace previs
