// loadServiceConfig on a previsd.toml. The folder holds the demo's calibrations and board
// (copied from examples/demo at start) and empty recorded camera folders, so inputs naming them
// get past the file checks. Devices are only named in a config, never opened by the loader.
#include <filesystem>

#include "base/data_paths.h"
#include "config/service_config.h"
#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace previs;
    static const bool fixtures = [] {
        const std::filesystem::path demo =
            projectDataDir().value_or(std::filesystem::path(".")) / "examples/demo";
        for (const char* name :
             {"scene_camera.yaml", "fisheye.yaml", "board.toml", "previs.toml"}) {
            std::error_code ec;
            std::filesystem::copy_file(demo / name, fuzz::scratchDir() / name,
                                       std::filesystem::copy_options::overwrite_existing, ec);
        }
        for (const char* camera : {"scene", "fisheye"})
            fuzz::writeScratch(std::string("session/cameras/") + camera + "/index.csv",
                               "# previs-session camera index v1: sequence,timestampNs,file,"
                               "width,height\n");
        return true;
    }();
    (void)fixtures;
    const std::string path = fuzz::writeScratch("previsd.toml", fuzz::asText(data, size));
    Result<ServiceConfig> config = loadServiceConfig(path);
    (void)config.ok();
    return 0;
}
