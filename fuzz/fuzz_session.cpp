// A session folder (docs/session-format.md) from one input split at "@@@@" lines into
// session.toml, cameras/scene/index.csv, poses.csv, events.csv and one frame file
// (cameras/scene/000000000000.png); then openSession, loadPoses, loadEvents, and every frame
// read back through the recorded camera reader.
#include <filesystem>

#include "capture/recorded_source.h"
#include "fuzz/fuzz_support.h"
#include "io/session.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    using namespace previs;
    std::error_code ec;
    const std::filesystem::path dir = fuzz::scratchDir() / "session";
    std::filesystem::remove_all(dir, ec);
    const std::vector<std::string_view> parts = fuzz::splitParts(fuzz::asText(data, size), 5);
    const char* names[] = {"session.toml", "cameras/scene/index.csv", "poses.csv", "events.csv",
                           "cameras/scene/000000000000.png"};
    for (size_t i = 0; i < parts.size(); ++i)
        fuzz::writeScratch(std::string("session/") + names[i], parts[i]);

    Result<SessionInfo> info = openSession(dir.string());
    (void)loadPoses(dir.string());
    size_t skipped = 0;
    (void)loadEvents(dir.string(), &skipped);
    if (!info.ok()) return 0;
    for (const SessionCamera& camera : info->cameras) {
        auto reader = RecordedReader::create(camera.dir, ReplayTiming::AsFastAsPossible);
        if (!reader.ok() || !(*reader)->start().ok()) continue;
        Frame frame;
        for (int i = 0; i < 64 && !(*reader)->finished(); ++i)
            if (!(*reader)->read(0, frame).ok()) break;
    }
    return 0;
}
