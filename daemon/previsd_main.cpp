// previsd: the on-set service (DESIGN.md §3). Exit codes: 0 clean stop, 1 runtime failure,
// 2 bad config or usage.

#include <sys/statvfs.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>

#include "base/command_line.h"
#include "base/log.h"
#include "config/service_config.h"
#include "daemon/network_dropin.h"
#include "daemon/service.h"
#include "scene/scene_description.h"
#include "shot/pipeline_stages.h"

using namespace previs;

namespace {

// Whether a take could start now (as TakeRecorder::openTake would find the folder): it exists or
// can be made, this user can write there, and the disk has [record] min_free_mb free. Nothing is
// created.
Status checkTakesFolder(const RecordConfig& record) {
    namespace fs = std::filesystem;
    const fs::path root = takesFolder(record);
    fs::path existing = root;
    std::error_code ec;
    while (!fs::exists(existing, ec) && existing.has_parent_path() &&
           existing != existing.parent_path())
        existing = existing.parent_path();
    if (!fs::is_directory(existing, ec))
        return makeError("takes folder {}: {} is not a folder; set [record] dir to a folder",
                         root.string(), existing.string());
    if (::access(existing.c_str(), W_OK | X_OK) != 0)
        return makeError(
            "takes folder {}: {} is not writable by this user ({}); set [record] dir "
            "to a folder previsd can write",
            root.string(), existing.string(), std::strerror(errno));
    struct statvfs st {};
    if (::statvfs(existing.c_str(), &st) != 0)
        return makeError("takes folder {}: cannot read the free space of {}: {}", root.string(),
                         existing.string(), std::strerror(errno));
    const uint64_t freeMb = (uint64_t(st.f_bavail) * uint64_t(st.f_frsize)) >> 20;
    if (freeMb < record.minFreeMb)
        return makeError(
            "takes folder {}: {} MiB free, under [record] min_free_mb = {}; a take "
            "would not start (free space, or set [record] dir to a larger disk)",
            root.string(), freeMb, record.minFreeMb);
    return {};
}

// --check: everything the config names, loaded and validated, without opening devices that may
// legitimately be absent at check time (cameras, display, button).
int check(const ServiceConfig& config) {
    Result<Scene> scene = loadScene(config.scenePath);
    if (!scene) {
        logError("{}", scene.message());
        return 2;
    }
    if (Result<TrackingStage> t = TrackingStage::create(config); !t) {
        logError("{}", t.message());
        return 2;
    }
    if (config.fisheyeCamera) {
        if (Result<LightingStage> l = LightingStage::create(config); !l) {
            logError("{}", l.message());
            return 2;
        }
    }
    std::string web = "off";
    if (!config.network.web.listen.empty()) {
        Result<std::string> token = readWebToken(config.network.web, config.path);
        if (!token) {
            logError("{}", token.message());
            return 2;
        }
        web = token->empty() ? "view only (no token)" : "with control (token)";
    }
    if (Status takes = checkTakesFolder(config.record); !takes) {
        logError("{}: {}", config.path, takes.message());
        return 2;
    }
    const std::string colour = cameraColourSummary(config);
    logInfo(
        "{}: OK (scene {} with {} triangles; output {}; button {}; web monitor {}; takes in {}{})",
        config.path, config.scenePath, scene->geometry.triangles.size(),
        toString(config.output.kind),
        config.button ? config.button->chip + ":" + config.button->line : "none", web,
        takesFolder(config.record), colour.empty() ? "" : "; colour: " + colour);
    return 0;
}

// --network-units DIR: the socket units and the service's drop-in for the config's network
// features (daemon/network_dropin.h), written into DIR (/etc/systemd/system on the box).
int writeNetworkUnits(const ServiceConfig& config, const std::string& dir) {
    NetworkUnitOptions options;
    options.freedInListen = config.tracking.freedListen;
    options.webTokenSource =
        (std::filesystem::absolute(config.path).parent_path() / "web-token").string();
    // The token the unit will load as its credential, checked now rather than at start.
    std::error_code statFailed;
    if (!config.network.web.listen.empty() && config.network.web.tokenFile.empty() &&
        std::filesystem::is_regular_file(options.webTokenSource, statFailed)) {
        if (Result<std::string> token =
                readWebTokenFile(options.webTokenSource, config.path, kWebTokenCredentialKey);
            !token) {
            logError("{}", token.message());
            return 2;
        }
    }
    Result<std::map<std::string, std::string>> units = networkUnits(config.network, options);
    if (!units) {
        logError("{}: {}", config.path, units.message());
        return 2;
    }
    for (const auto& [name, text] : *units) {
        const std::filesystem::path path = std::filesystem::path(dir) / name;
        std::error_code ec;
        std::filesystem::create_directories(path.parent_path(), ec);
        std::ofstream out(path);
        out << text;
        if (!out.flush()) {
            logError("cannot write {} (is {} writable?)", path.string(), dir);
            return 2;
        }
        std::printf("%s\n", path.c_str());
    }
    return 0;
}

int run(const std::string& configPath, bool checkOnly, const std::string& unitsDir) {
    Result<ServiceConfig> config = loadServiceConfig(configPath);
    if (!config) {
        logError("{}", config.message());
        return 2;
    }
    if (checkOnly) return check(*config);
    if (!unitsDir.empty()) return writeNetworkUnits(*config, unitsDir);

    // Before any thread starts, so that only run()'s signalfd sees these.
    blockServiceSignals();
    raiseOpenFileLimit();
    // The control socket and the web port first: a second previsd is refused before the slow
    // start, which run() does while both answer "starting".
    Result<std::unique_ptr<Service>> service = Service::open(*config);
    if (!service) {
        logError("{}", service.message());
        return exitCodeOf(service.error());
    }
    return (*service)->run();
}

}  // namespace

int main(int argc, char** argv) {
    setLogProgramName("previsd");
    CLI::App app{"previsd: the previs on-set service", "previsd"};
    app.set_version_flag("--version", "previsd " PREVIS_VERSION);
    useOneLineUsageErrors(app);
    std::string configPath;
    bool checkOnly = false;
    app.add_option("--config", configPath, "the service config (docs/config-format.md)")
        ->required();
    app.add_flag("--check", checkOnly, "validate the config and everything it names, then exit");
    std::string unitsDir;
    app.add_option("--network-units", unitsDir,
                   "write the systemd socket units and drop-in that give the unit the sockets the "
                   "config's [freed], [opentrackio] and [web] need into DIR "
                   "(/etc/systemd/system; docs/systemd.md), then exit")
        ->type_name("DIR");
    if (auto exitCode = parseCommandLine(app, argc, argv)) return *exitCode;
    return runReportingExceptions("previsd", [&] { return run(configPath, checkOnly, unitsDir); });
}
