#include "cli/envmap_command.h"

#include <cmath>
#include <opencv2/core/utils/logger.hpp>

#include "base/log.h"
#include "base/output_path.h"
#include "base/strings.h"
#include "cli/tone_curve_options.h"
#include "image/image.h"
#include "vision/camera_calibration.h"
#include "vision/fisheye_to_equirect.h"
#include "vision/inverse_tone_map.h"

namespace previs {

namespace {

struct EnvmapOptions {
    std::string image;
    std::string camera;
    std::vector<double> mountRotationDeg{-90.0, 0.0, 0.0};
    int width = 1024;
    std::string out;
    ToneCurveOptions curve;  // of an LDR input
    double maxFieldAngleDeg = 95.0;
    bool quiet = false;
};

int run(const EnvmapOptions& o) {
    cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
    if (!endsWith(o.out, ".exr")) {
        logError("--out {}: the environment map is written as linear HDR OpenEXR; use a .exr name",
                 o.out);
        return 2;
    }
    if (Status s = checkOutputFile("--out", o.out); !s) {
        logError("{}", s.message());
        return 2;
    }
    auto calib = CameraCalibration::load(o.camera);
    if (!calib) {
        logError("--camera: {}", calib.message());
        return 2;
    }
    if (calib->model() != DistortionModel::Fisheye)
        logWarning(
            "--camera {}: not a fisheye calibration (no distortion_model: fisheye); only "
            "directions within 90° of its axis can be seen",
            o.camera);
    FisheyeToEquirectSettings settings;
    settings.mountRotationDeg =
        cv::Vec3d(o.mountRotationDeg[0], o.mountRotationDeg[1], o.mountRotationDeg[2]);
    settings.width = o.width;
    settings.maxFieldAngleDeg = o.maxFieldAngleDeg;
    auto resampler = FisheyeToEquirect::create(*calib, settings);
    if (!resampler) {
        logError("{}: {}", o.camera, resampler.message());
        return 2;
    }

    auto image = readImage(o.image);
    if (!image) {
        logError("{}", image.message());
        return 2;
    }
    // LDR (PNG/JPEG) is display-referred: back to linear radiance as for plates. EXR is used as is.
    ImageF linear = inverseToneMap(*image, o.curve.inverse());

    cv::Mat frame(int(linear.height), int(linear.width), CV_32FC3);
    for (uint32_t y = 0; y < linear.height; ++y) {
        cv::Vec3f* row = frame.ptr<cv::Vec3f>(int(y));
        for (uint32_t x = 0; x < linear.width; ++x)
            for (int c = 0; c < 3; ++c)
                row[x][c] = linear.at(x, y, linear.channels >= 3 ? uint32_t(c) : 0u);
    }
    auto env = resampler->apply(frame);
    if (!env) {
        logError("{}: {}", o.image, env.message());
        return 1;
    }

    ImageF out;
    out.width = uint32_t(env->cols);
    out.height = uint32_t(env->rows);
    out.channels = 3;
    out.pixels.assign(env->ptr<float>(0), env->ptr<float>(0) + size_t(env->total()) * 3);
    if (Status s = writeExr(o.out, out); !s) {
        logError("{}", s.message());
        return 1;
    }
    if (!o.quiet)
        logInfo(
            "wrote {} ({}x{}); the lens sees {:.1f}% of the sphere, the rest is the mean of "
            "its outermost 5° ring",
            o.out, out.width, out.height, 100.0 * resampler->seenFraction());
    return 0;
}

}  // namespace

std::function<int()> addEnvmapCommand(CLI::App& app) {
    auto o = std::make_shared<EnvmapOptions>();
    CLI::App* cmd = app.add_subcommand(
        "envmap", "fisheye frame → equirectangular HDR environment map (DESIGN.md §4)");
    cmd->add_option("FISHEYE_IMG", o->image, "fisheye frame: PNG/JPEG (sRGB) or OpenEXR (linear)")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--camera", o->camera,
                    "OpenCV calibration YAML of the fisheye (distortion_model: fisheye)")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--mount-rotation", o->mountRotationDeg,
                    "RX,RY,RZ degrees: worldFromFisheye = Rz·Ry·Rx (default -90,0,0: zenith up, "
                    "image bottom toward world -Z)")
        ->delimiter(',')
        ->expected(3);
    cmd->add_option("--width", o->width, "map width in pixels, height = width/2 (default 1024)")
        ->check(CLI::Range(8, 16384));
    cmd->add_option("--out", o->out, "output ENV.exr (linear float RGB)")->required();
    o->curve.addTo(cmd, "", "LDR input", true);
    cmd->add_option("--max-angle", o->maxFieldAngleDeg,
                    "largest angle from the optical axis taken as seen, degrees (default 95)")
        ->check(CLI::Range(1.0, 180.0));
    cmd->add_flag("--quiet", o->quiet, "no summary on stderr");
    return [o] { return run(*o); };
}

}  // namespace previs
