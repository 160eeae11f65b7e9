#pragma once

#include <string>
#include <utility>
#include <vector>

#include "base/result.h"
#include "scene/scene.h"

namespace previs {

// Choices a caller (the previs.toml scene description) makes about how a glTF file is read.
struct GltfLoadOptions {
    // Roles by node name, for files from tools that cannot write extras (DESIGN.md §4): each
    // rule is an fnmatch(3) glob on the node's name and the role it gives (true = real). A
    // matching rule overrides the node's own extras.previs.role, and children inherit it as they
    // inherit extras roles. Rules are order-independent: a node matched by both a real and a
    // virtual rule is an error (there is no "more specific pattern" to prefer). A rule matching
    // no node of the default scene is a warning (likely a typo).
    std::vector<std::pair<std::string, bool>> roleRules;
    // Where the rules were written, appended to messages about them so the user knows which
    // file to fix (e.g. "[roles] of 'shot/previs.toml'"); empty: not mentioned.
    std::string roleRulesOrigin;
};

// Loads a .gltf (with external or data-URI buffers) or .glb file into world-space geometry,
// materials, textures, KHR_lights_punctual lights and perspective cameras of the default scene
// (DESIGN.md §4 conventions). Any malformed input gives one error naming the file and the problem;
// recoverable oddities (undecodable textures, degenerate triangles, non-triangle primitives) are
// logged as warnings and worked around as documented in the implementation.
Result<Scene> loadGltf(const std::string& path, const GltfLoadOptions& options = {});

}  // namespace previs
