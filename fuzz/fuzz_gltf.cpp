// loadGltf on .gltf (JSON, data-URI buffers) and .glb input, chosen by the GLB magic.
#include "fuzz/fuzz_support.h"
#include "scene/gltf_loader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace previs;
    const std::string_view text = fuzz::asText(data, size);
    const std::string path =
        fuzz::writeScratch(text.starts_with("glTF") ? "model.glb" : "model.gltf", text);
    Result<Scene> scene = loadGltf(path);
    (void)scene.ok();
    return 0;
}
