#pragma once

// The previs.toml scene description (DESIGN.md §3, §4; the format is in docs/scene-format.md):
// a glTF file plus what the tool that wrote it could not say — roles by node name, the
// environment map and its orientation, which transmissive materials are thin walls or solids,
// the camera to use and its lens.

#include <string>

#include "base/result.h"
#include "scene/scene.h"

namespace previs {

// Reads the description at `path`, loads the glTF it names (with its role patterns) and its
// environment map, and applies the camera choice (Scene::cameraName) and lens overrides. Paths
// inside are relative to the description's folder. Any user error — TOML syntax, an unknown
// key, a wrong type or range, a missing file, an unsupported version — gives one message naming
// the file, the line and the key, and what to change.
Result<Scene> loadSceneDescription(const std::string& path);

// What `previs render SCENE` and the service call: .gltf/.glb (any case) go to loadGltf, .toml
// to loadSceneDescription; anything else is an error naming the file and the accepted types.
Result<Scene> loadScene(const std::string& path);

}  // namespace previs
