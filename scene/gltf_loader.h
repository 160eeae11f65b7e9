#pragma once

#include <cstdint>
#include <map>
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
    // Per material name, whether a transmissive material is a thin wall (true) or the surface of
    // a refracting solid (false), whatever its KHR_materials_volume says (previs.toml
    // [materials]). Without one glTF's rule holds: a volume with thicknessFactor > 0 is a solid,
    // anything else a thin wall, and a thin one on a closed mesh is warned about once per
    // material (Blender's exporter writes its default glass so). A name matching no material is
    // a warning.
    std::map<std::string, bool> thinWalledByMaterial{};
    std::string materialsOrigin{};  // as roleRulesOrigin, for thinWalledByMaterial
    // What one scene may hold in memory as it loads: the bytes of the glTF, its buffers and its
    // encoded images, plus every image's decoded RGBA pixels (checked against the size its header
    // declares, before it is decoded). 2 GiB holds eight 8K textures; a scene needing more is
    // refused with one line, where it would otherwise take the box's memory (MemoryMax=4G).
    uint64_t maxDataBytes = uint64_t(2) << 30;
};

// Loads a .gltf (with external or data-URI buffers) or .glb file into world-space geometry,
// materials, textures, KHR_lights_punctual lights and perspective cameras of the default scene
// (DESIGN.md §4 conventions). Buffers and images are data: URIs or files inside the glTF's folder
// (after resolving `..` and symbolic links): an absolute path, another scheme (http:, file:) or a
// path out of the folder is refused, as is a scene over options.maxDataBytes. Any malformed input
// gives one error naming the file and the problem; recoverable oddities (undecodable textures,
// degenerate triangles, non-triangle primitives) are logged as warnings and worked around as
// documented in the implementation.
Result<Scene> loadGltf(const std::string& path, const GltfLoadOptions& options = {});

}  // namespace previs
