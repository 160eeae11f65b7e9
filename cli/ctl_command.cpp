#include "cli/ctl_command.h"

#include <cstdio>
#include <memory>
#include <nlohmann/json.hpp>

#include "base/log.h"
#include "config/service_config.h"
#include "daemon/control_server.h"

namespace previs {

namespace {

struct CtlOptions {
    std::string socket;
    bool json = false;
    std::string mode;
    std::string takeName;
};

// The human-readable form of `previs ctl status`.
void printStatus(const nlohmann::json& s) {
    // Before the pipeline runs (DESIGN.md §3 "state"): what the start is doing.
    if (s.contains("starting") && s["starting"].is_string())
        std::printf("starting  %s\n", s["starting"].get<std::string>().c_str());
    std::printf("mode      %s\n", s.value("mode", "?").c_str());
    std::printf("samples   %llu\n", (unsigned long long)s.value("samples", 0ull));
    std::printf("fps       %.2f\n", s.value("fps", 0.0));
    std::printf("frames    %llu shown, %llu dropped\n",
                (unsigned long long)s.value("framesShown", 0ull),
                (unsigned long long)s.value("framesDropped", 0ull));
    std::printf("display   %s\n", s.value("display", "?").c_str());
    if (s.contains("pose") && s["pose"].is_object()) {
        const auto& m = s["pose"]["worldFromCamera"];
        std::printf("camera    at (%.3f, %.3f, %.3f) m, %d tag(s)%s\n", m[3].get<double>(),
                    m[7].get<double>(), m[11].get<double>(), s["pose"].value("tags", 0),
                    s["pose"].value("lost", false) ? ", tracking lost (holding)" : "");
    } else {
        std::printf("camera    not tracked yet\n");
    }
    if (s.value("recording", false) && s["record"].is_object())
        std::printf("recording %s: %llu frames, %.1f MiB, %llu dropped\n",
                    s["record"].value("path", "?").c_str(),
                    (unsigned long long)s["record"].value("frames", 0ull),
                    double(s["record"].value("bytes", 0ull)) / (1 << 20),
                    (unsigned long long)s["record"].value("dropped", 0ull));
    else if (s.contains("record") && s["record"].is_object())
        std::printf("recording stopped: %s\n", s["record"].value("stoppedBecause", "").c_str());
    std::printf("uptime    %.0f s\n", s.value("uptimeSeconds", 0.0));
}

constexpr int kRecordTimeoutMs = 120'000;

int run(const CtlOptions& o, const std::string& command, bool status) {
    ControlConfig control;
    control.socketPath = o.socket;
    const std::string path = controlSocketPath(control);
    // `record stop` answers once the take is on disk (its queue, up to [record] queue_mb, drains
    // first) and `record start` once the config's files are copied into the take: seconds on a
    // slow card, where every other command takes microseconds.
    const int timeoutMs = command.starts_with("record ") ? kRecordTimeoutMs : 5000;
    Result<std::string> reply = controlRequest(path, command, timeoutMs);
    if (!reply) {
        logError("{}", reply.message());
        return 1;
    }
    nlohmann::json j = nlohmann::json::parse(*reply, nullptr, false);
    if (j.is_discarded()) {
        logError("previsd at {} answered something that is not JSON: {}", path, *reply);
        return 1;
    }
    if (j.contains("ok") && !j["ok"].get<bool>()) {
        logError("previsd: {}", j.value("error", "failed"));
        return 2;
    }
    if (status && !o.json)
        printStatus(j);
    else if (status)
        std::printf("%s\n", reply->c_str());
    else if (j.contains("applied"))
        std::printf("%s\n", j.value("applied", "").c_str());  // reload: what took effect
    else if (j.contains("path"))
        std::printf("%s\n", j.value("path", "").c_str());  // record start|stop: the take
    else
        std::printf("%s\n", j.value("mode", "").c_str());
    return 0;
}

}  // namespace

std::function<int()> addCtlCommand(CLI::App& app) {
    auto o = std::make_shared<CtlOptions>();
    CLI::App* cmd = app.add_subcommand("ctl", "talk to a running previsd");
    cmd->add_option("--socket", o->socket,
                    "control socket (default $RUNTIME_DIRECTORY/previsd.sock, else "
                    "/run/previs/previsd.sock)");
    cmd->require_subcommand(1);
    CLI::App* status = cmd->add_subcommand("status", "mode, samples, fps, pose, drops");
    status->add_flag("--json", o->json, "one JSON object (DESIGN.md §3)");
    CLI::App* mode = cmd->add_subcommand("mode", "switch to preview or refinement");
    mode->add_option("MODE", o->mode, "preview or refine")
        ->required()
        ->check(CLI::IsMember({"preview", "refine"}));
    CLI::App* toggle = cmd->add_subcommand("toggle", "switch between preview and refinement");
    CLI::App* record = cmd->add_subcommand(
        "record", "start a take (prints its folder) or stop it (docs/takes.md)");
    auto recordWhat = std::make_shared<std::string>();
    record->add_option("WHAT", *recordWhat, "start or stop")
        ->required()
        ->check(CLI::IsMember({"start", "stop"}));
    record->add_option("--name", o->takeName,
                       "start: the take's name, added to its folder's (letters, digits, - and _)");
    CLI::App* reload = cmd->add_subcommand(
        "reload",
        "reread previsd's config; returns once it is in effect (exit 0) or refused (exit 2, the "
        "running one kept): systemctl reload runs this");
    return [o, status, mode, toggle, record, recordWhat, reload] {
        if (*status) return run(*o, "status", true);
        if (*reload) return run(*o, "reload", false);
        if (*mode) return run(*o, "mode " + o->mode, false);
        if (*toggle) return run(*o, "toggle", false);
        if (*record) {
            std::string command = "record " + *recordWhat;
            if (*recordWhat == "start" && !o->takeName.empty()) command += " " + o->takeName;
            return run(*o, command, false);
        }
        return 2;
    };
}

}  // namespace previs
