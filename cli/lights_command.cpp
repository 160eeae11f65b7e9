#include "cli/lights_command.h"

#include <cstdio>
#include <nlohmann/json.hpp>

#include "base/log.h"
#include "scene/environment_map.h"
#include "shot/pipeline_stages.h"
#include "vision/light_estimator.h"

namespace previs {

namespace {

struct LightsOptions {
    std::string env;
    bool json = false;
    LightEstimatorSettings settings;
};

nlohmann::ordered_json jsonVec3(const cv::Vec3d& v) { return {v[0], v[1], v[2]}; }

int run(const LightsOptions& o) {
    auto map = loadEnvironmentMap(o.env);
    if (!map) {
        logError("{}", map.message());
        return 2;
    }
    auto snap = LightEstimator(o.settings).estimate(environmentMapToMat(*map));
    if (!snap) {
        logError("{}: {}", o.env, snap.message());
        return 1;
    }
    if (o.json) {
        // The lights as a take records them (one owner of their JSON), then the powers.
        nlohmann::ordered_json out =
            nlohmann::ordered_json::parse(estimatedLightsJson(snap->lights));
        out["residualPower"] = jsonVec3(snap->residualPower);
        out["totalPower"] = jsonVec3(snap->totalPower);
        std::printf("%s\n", out.dump().c_str());
        return 0;
    }
    std::printf("%s: %zu light(s), threshold luminance %.4g\n", o.env.c_str(), snap->lights.size(),
                snap->thresholdLuminance);
    for (const EstimatedLight& l : snap->lights)
        std::printf(
            "  direction (%.4f, %.4f, %.4f)  solid angle %.4g sr  radiance (%.4g, %.4g, "
            "%.4g)  %d texels\n",
            l.direction[0], l.direction[1], l.direction[2], l.solidAngleSr, l.radiance[0],
            l.radiance[1], l.radiance[2], l.texels);
    std::printf("  residual power (%.6g, %.6g, %.6g)\n  total power    (%.6g, %.6g, %.6g)\n",
                snap->residualPower[0], snap->residualPower[1], snap->residualPower[2],
                snap->totalPower[0], snap->totalPower[1], snap->totalPower[2]);
    return 0;
}

}  // namespace

std::function<int()> addLightsCommand(CLI::App& app) {
    auto o = std::make_shared<LightsOptions>();
    CLI::App* cmd = app.add_subcommand(
        "lights", "estimate light sources on an HDR environment map (energy-preserving)");
    cmd->add_option("ENV", o->env, "equirectangular HDR map (.exr or .hdr)")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_flag("--json", o->json, "print one JSON object on stdout");
    cmd->add_option("--mean-factor", o->settings.meanFactor,
                    "threshold: luminance > max(F × mean, M × max); F (default 8)")
        ->check(CLI::PositiveNumber);
    cmd->add_option("--max-fraction", o->settings.maxFraction, "threshold: M (default 0.02)")
        ->check(CLI::Range(0.0, 1.0));
    cmd->add_option("--max-lights", o->settings.maxLights, "at most this many lights (default 16)")
        ->check(CLI::Range(0, 1024));
    return [o] { return run(*o); };
}

}  // namespace previs
