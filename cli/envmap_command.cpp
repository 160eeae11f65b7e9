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
#include "vision/hdr_bracket.h"
#include "vision/inverse_tone_map.h"

namespace previs {

namespace {

struct EnvmapOptions {
    std::vector<std::string> images;  // one frame, or an exposure bracket
    std::vector<double> stops;        // the bracket's exposures, one per image
    std::string camera;
    std::vector<double> mountRotationDeg{-90.0, 0.0, 0.0};
    int width = 1024;
    std::string out;
    ToneCurveOptions curve;  // of an LDR input
    double maxFieldAngleDeg = 95.0;
    bool quiet = false;
};

// One frame: LDR (PNG/JPEG) is display-referred, back to linear radiance as for plates; EXR is
// used as is.
Result<cv::Mat> linearFrame(const EnvmapOptions& o) {
    auto image = readImage(o.images[0]);
    if (!image) return image.error();
    ImageF linear = inverseToneMap(*image, o.curve.inverse());
    cv::Mat frame(int(linear.height), int(linear.width), CV_32FC3);
    for (uint32_t y = 0; y < linear.height; ++y) {
        cv::Vec3f* row = frame.ptr<cv::Vec3f>(int(y));
        for (uint32_t x = 0; x < linear.width; ++x)
            for (int c = 0; c < 3; ++c)
                row[x][c] = linear.at(x, y, linear.channels >= 3 ? uint32_t(c) : 0u);
    }
    return frame;
}

// An 8-bit exposure bracket merged as the box merges one (vision/hdr_bracket.h), the frames'
// exposures checked against their pictures first.
Result<cv::Mat> mergedBracket(const EnvmapOptions& o) {
    if (o.stops.size() != o.images.size())
        return makeError("--stops: {} exposures for {} images; give one per image, in order",
                         o.stops.size(), o.images.size());
    const std::vector<float> stops(o.stops.begin(), o.stops.end());
    if (Status s = checkBracketStops(stops, "--stops"); !s) return s.error();
    std::vector<cv::Mat> frames;
    for (const std::string& path : o.images) {
        auto image = readImage(path);
        if (!image) return image.error();
        if (!image->ldrSrgb)
            return makeError(
                "{}: a bracket is of 8-bit frames (PNG/JPEG); an EXR is already "
                "merged, give it alone",
                path);
        cv::Mat rgb(int(image->height), int(image->width), CV_8UC3);
        for (uint32_t y = 0; y < image->height; ++y)
            for (uint32_t x = 0; x < image->width; ++x)
                for (int c = 0; c < 3; ++c)
                    rgb.at<cv::Vec3b>(int(y), int(x))[c] = cv::saturate_cast<uint8_t>(
                        255.0f * image->at(x, y, image->channels >= 3 ? uint32_t(c) : 0u) + 0.5f);
        if (!frames.empty() && rgb.size() != frames[0].size())
            return makeError("{}: {}x{}, but {} is {}x{}; a bracket's frames share one size", path,
                             rgb.cols, rgb.rows, o.images[0], frames[0].cols, frames[0].rows);
        frames.push_back(std::move(rgb));
    }
    const InverseToneMapSettings radiometry = o.curve.inverse();
    for (size_t i = 1; i < frames.size(); ++i) {
        const std::optional<float> measured =
            measuredStopsBetween(frames[i - 1], frames[i], radiometry, 64);
        if (measured && std::abs(*measured - (stops[i] - stops[i - 1])) > 0.5f)
            return makeError(
                "{} and {} differ by {:.2f} stops in their pictures, not the {:.2f} "
                "--stops says; check their order and exposures",
                o.images[i - 1], o.images[i], *measured, stops[i] - stops[i - 1]);
    }
    Result<MergedBracket> merged = mergeBracket(frames, stops, radiometry);
    if (!merged) return merged.error();
    if (merged->clippedFraction > 0.0 && !o.quiet)
        logWarning(
            "{:.3f} % of the pixels clip even at {} stops: their light is a lower bound; "
            "add a shorter exposure",
            100.0 * merged->clippedFraction, *std::min_element(stops.begin(), stops.end()));
    return std::move(merged->radiance);
}

int run(EnvmapOptions& o) {
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
    if (Status s = o.curve.buildColour(); !s) {
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

    Result<cv::Mat> frame = o.images.size() == 1 ? linearFrame(o) : mergedBracket(o);
    if (!frame) {
        logError("{}", frame.message());
        return 2;
    }
    auto env = resampler->apply(*frame);
    if (!env) {
        logError("{}: {}", o.images[0], env.message());
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
    cmd->add_option("FISHEYE_IMG", o->images,
                    "fisheye frame: PNG/JPEG (sRGB) or OpenEXR (linear); or an exposure bracket "
                    "of PNG/JPEG frames with --stops")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--stops", o->stops,
                    "the bracket's exposures, one per image in stops from the tone curve's "
                    "(e.g. 0,-4,-8): merged to radiance as previsd merges its fisheye's")
        ->delimiter(',');
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
    o->curve.addColourTo(cmd, "", "LDR input");
    cmd->add_option("--max-angle", o->maxFieldAngleDeg,
                    "largest angle from the optical axis taken as seen, degrees (default 95)")
        ->check(CLI::Range(1.0, 180.0));
    cmd->add_flag("--quiet", o->quiet, "no summary on stderr");
    return [o] { return run(*o); };
}

}  // namespace previs
