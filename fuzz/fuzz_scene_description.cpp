// loadSceneDescription on a previs.toml. The folder holds a tiny valid glTF (scene.gltf) and
// environment map (env.hdr) so inputs naming them get past the file checks.
#include "fuzz/fuzz_support.h"
#include "scene/scene_description.h"

namespace {

// One triangle, one camera; buffer as a data URI (3 positions + 3 indices, 42 bytes).
constexpr std::string_view kGltf = R"({"asset":{"version":"2.0"},"scene":0,
"scenes":[{"nodes":[0,1]}],
"nodes":[{"mesh":0,"name":"floor"},{"camera":0,"name":"cam","translation":[0,0,3]}],
"cameras":[{"type":"perspective","perspective":{"yfov":0.8,"znear":0.01}}],
"meshes":[{"primitives":[{"attributes":{"POSITION":0},"indices":1}]}],
"buffers":[{"byteLength":42,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIA"}],
"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":6}],
"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},
{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}]})";

// An 8x1 Radiance map, stored flat.
const std::string kHdr =
    std::string("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 8\n") + std::string(32, '\x80');

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace previs;
    static const bool fixtures = [] {
        fuzz::writeScratch("scene.gltf", kGltf);
        fuzz::writeScratch("env.hdr", kHdr);
        return true;
    }();
    (void)fixtures;
    const std::string path = fuzz::writeScratch("previs.toml", fuzz::asText(data, size));
    Result<Scene> scene = loadSceneDescription(path);
    (void)scene.ok();
    return 0;
}
