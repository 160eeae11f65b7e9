#include "cli/take_commands.h"

#include <unistd.h>

#include <filesystem>
#include <memory>

#include "base/log.h"
#include "base/output_path.h"
#include "take/take_render.h"
#include "take/track_export.h"

namespace previs {

namespace {

// Before the take is tracked: the file is written beside itself and renamed, so its folder must
// take a new file even where the file itself exists and is writable.
Status checkTrackOut(const std::string& path) {
    if (Status s = checkOutputFile("--out", path); !s) return s;
    const std::filesystem::path folder = std::filesystem::path(path).has_parent_path()
                                             ? std::filesystem::path(path).parent_path()
                                             : std::filesystem::path(".");
    if (::access(folder.c_str(), W_OK | X_OK) != 0)
        return makeError(
            "--out {}: the folder {} is not writable (the file is written there "
            "under a temporary name, then renamed)",
            path, folder.string());
    return {};
}

}  // namespace

std::function<int()> addRenderSessionCommand(CLI::App& app) {
    auto o = std::make_shared<TakeRenderOptions>();
    CLI::App* cmd = app.add_subcommand("render-session",
                                       "render a recorded take at final quality (docs/takes.md)");
    cmd->add_option("TAKE", o->takeDir, "the take's folder (docs/session-format.md)")
        ->required()
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--out", o->outDir, "folder for frame_NNNNNN.exr and .png")->required();
    cmd->add_option("--frames", o->frames,
                    "frames to render: A:B (as a Python slice) or a list like 1-100, 1-100x2, "
                    "1,5,7-9 (default: all)");
    auto* spp = cmd->add_option("--spp", o->spp,
                                "samples per pixel (default: the take config's [refine] "
                                "max_samples)");
    cmd->add_option("--target-noise", o->targetNoise,
                    "stop a frame once the convergence meter's relative RMSE is this low "
                    "(default: [refine] target_noise; 0 = render every sample)")
        ->excludes(spp);
    cmd->add_option("--aov", o->aovs,
                    "layers besides the composite: mixed, real, mask, differential, albedo, "
                    "normal, depth (default: mixed,real,mask,differential)")
        ->delimiter(',');
    cmd->add_option("--width", o->width, "output width (with --height; default: the take's)");
    cmd->add_option("--height", o->height, "output height");
    cmd->add_option("--plan", o->plan,
                    "print the frames cut into N ranges, one a line, and render nothing (a "
                    "render farm's array tasks take one each)");
    cmd->add_flag("--raw-poses", o->rawPoses,
                  "render with the tracker's pose of each frame, not the smoothed track");
    cmd->add_flag("--quiet", o->quiet, "no progress on stderr (stages and frames)");
    return [o] { return runTakeRender(*o); };
}

std::function<int()> addExportTrackCommand(CLI::App& app) {
    auto o = std::make_shared<TrackExportOptions>();
    CLI::App* cmd = app.add_subcommand(
        "export-track", "write a take's camera track for post: Nuke .chan or JSON lines");
    cmd->add_option("TAKE", o->takeDir, "the take's folder")
        ->required()
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--out", o->outPath, "FILE.chan (Nuke, Blender) or FILE.jsonl")->required();
    cmd->add_flag("--smoothed", o->smoothed,
                  "the track smoothed over the whole take (as render-session renders it)");
    return [o] {
        if (Status s = checkTrackOut(o->outPath); !s) {
            logError("export-track: {}", s.message());
            return 2;
        }
        return runTrackExport(*o);
    };
}

}  // namespace previs
