#pragma once

#include <string>

#include "base/result.h"
#include "scene/scene.h"

namespace previs {

// Loads a .gltf (with external or data-URI buffers) or .glb file into world-space geometry,
// materials, textures, KHR_lights_punctual lights and perspective cameras of the default scene
// (DESIGN.md §4 conventions). Any malformed input gives one error naming the file and the problem;
// recoverable oddities (undecodable textures, degenerate triangles, non-triangle primitives) are
// logged as warnings and worked around as documented in the implementation.
Result<Scene> loadGltf(const std::string& path);

}  // namespace previs
