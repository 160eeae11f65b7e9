// previsd: the on-set service (DESIGN.md §3). Exit codes: 0 clean stop, 1 runtime failure,
// 2 bad config or usage.

#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include "base/command_line.h"
#include "base/log.h"
#include "daemon/network_dropin.h"
#include "daemon/pipeline_stages.h"
#include "daemon/service.h"
#include "daemon/service_config.h"
#include "scene/scene_description.h"

using namespace previs;

namespace {

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
    if (!config.network.web.listen.empty()) {
        if (Result<std::string> token = readWebToken(config.network.web, config.path); !token) {
            logError("{}", token.message());
            return 2;
        }
    }
    logInfo("{}: OK (scene {} with {} triangles; output {}; button {})", config.path,
            config.scenePath, scene->geometry.triangles.size(), toString(config.output.kind),
            config.button ? config.button->chip + ":" + config.button->line : "none");
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
    bool userError = false;
    Result<std::unique_ptr<Service>> service = Service::create(*config, &userError);
    if (!service) {
        logError("{}", service.message());
        return userError ? 2 : 1;
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
