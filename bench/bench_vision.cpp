#include "bench/bench_vision.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "render/board_render.h"
#include "vision/board_pose.h"
#include "vision/fisheye_to_equirect.h"
#include "vision/inverse_tone_map.h"
#include "vision/light_estimator.h"

namespace previs {

namespace {

template <typename F>
VisionTiming measure(const std::string& name, int runs, F&& body) {
    std::vector<double> ms;
    std::string note;
    body(note);  // warm-up (first-touch allocations, OpenCV's lazy init)
    for (int i = 0; i < runs; ++i) {
        auto t0 = std::chrono::steady_clock::now();
        body(note);
        ms.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count());
    }
    std::sort(ms.begin(), ms.end());
    VisionTiming t;
    t.name = name;
    t.runs = runs;
    t.medianMs = ms[ms.size() / 2];
    t.p90Ms = ms[std::min(ms.size() - 1, ms.size() * 9 / 10)];
    t.note = note;
    return t;
}

}  // namespace

Result<std::vector<VisionTiming>> benchVision(const std::string& dataDir, int runs) {
    runs = std::max(1, runs);
    std::vector<VisionTiming> out;

    // A 1280×720 frame: the 640×480 ViSP board frame scaled 1.5× into the middle of the canvas,
    // with the intrinsics scaled the same way, so detection and pose do real work.
    const std::string seq = dataDir + "/video/visp_rbt_sequence/";
    cv::Mat small = cv::imread(seq + "color_image_0000.png", cv::IMREAD_GRAYSCALE);
    if (small.empty()) return makeError("{}: cannot read the benchmark frame", seq);
    cv::Mat frame(720, 1280, CV_8UC1, cv::Scalar(128));
    cv::resize(small, frame(cv::Rect(160, 0, 960, 720)), cv::Size(960, 720), 0, 0,
               cv::INTER_LINEAR);
    cv::Matx33d k(607.178466796875 * 1.5, 0, 321.39129638671875 * 1.5 + 160, 0,
                  607.2342529296875 * 1.5, 241.91822814941406 * 1.5, 0, 0, 1);
    auto calib = CameraCalibration::create(k, {}, {1280, 720}, DistortionModel::Pinhole, "bench");
    if (!calib) return calib.error();
    const TagBoard board = vispRbtBoard();

    struct Config {
        float decimate;
        int threads;
    };
    // decimate 0: the tracker's default, chosen from the last pose's predicted tag sizes (every
    // run after the warm-up has one).
    for (Config c :
         {Config{2.0f, 1}, Config{2.0f, 2}, Config{1.0f, 1}, Config{1.0f, 2}, Config{0.0f, 1}}) {
        TagDetectorSettings s;
        s.decimate = c.decimate;
        s.threads = c.threads;
        // Timed as for a camera whose radiometry is configured: the edge refit's cost included.
        TrackerSettings configured;
        configured.linearFromCode = linearFromCodeTable(InverseToneMapSettings{});
        auto tracker = Tracker::create(s, board, *calib, configured);
        if (!tracker) return tracker.error();
        out.push_back(measure(
            fmt::format("track 1280x720 (decimate {}, {} thread(s))",
                        c.decimate > 0.0f ? fmt::format("{}", c.decimate) : std::string("auto"),
                        c.threads),
            runs, [&](std::string& note) {
                const TrackingState& st = tracker->track(frame);
                note = st.lost ? "lost: " + st.reason
                               : fmt::format("{} tags, reprojection {:.2f} px, decimated {}",
                                             st.pose->tagIds.size(), st.pose->reprojErrorPx,
                                             tracker->searchStats().decimate);
            }));
    }

    // Fisheye → environment → lights, on the Ricoh Theta front lens frame (960×1080).
    const std::string fisheyePath = dataDir + "/fisheye/theta_dual_fisheye/front_table.jpg";
    cv::Mat bgr = cv::imread(fisheyePath, cv::IMREAD_COLOR);
    if (bgr.empty()) return makeError("{}: cannot read the fisheye frame", fisheyePath);
    cv::Mat rgb8;
    cv::cvtColor(bgr, rgb8, cv::COLOR_BGR2RGB);
    auto fisheyeCalib = CameraCalibration::create(
        cv::Matx33d(285.4445582214784, 0, 479.54163801123735, 0, 285.79052232080954,
                    479.1500510939406, 0, 0, 1),
        {-0.027030288484165232, 0.022343725236597712, -0.009221629906294137, 0.0005504661082009},
        {960, 1080}, DistortionModel::Fisheye, "bench fisheye");
    if (!fisheyeCalib) return fisheyeCalib.error();
    FisheyeToEquirectSettings fs;
    fs.width = 1024;
    auto built = std::chrono::steady_clock::now();
    auto resampler = FisheyeToEquirect::create(*fisheyeCalib, fs);
    if (!resampler) return resampler.error();
    const double buildMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - built).count();
    LightEstimator estimator;
    cv::Mat env;
    out.push_back(measure("inverse tone map 960x1080 (8-bit sRGB)", runs,
                          [&](std::string&) { (void)inverseToneMapRgb8(rgb8, {}); }));
    cv::Mat linear = inverseToneMapRgb8(rgb8, {});
    out.push_back(measure("fisheye 960x1080 -> env 1024x512", runs, [&](std::string& note) {
        env = *resampler->apply(linear);
        note = fmt::format("lookup built once in {:.0f} ms", buildMs);
    }));
    out.push_back(measure("lights on env 1024x512 (fisheye)", runs, [&](std::string& note) {
        note = fmt::format("{} light(s)", estimator.estimate(env)->lights.size());
    }));
    out.push_back(measure("fisheye frame -> env -> lights (total)", runs, [&](std::string& note) {
        cv::Mat l = inverseToneMapRgb8(rgb8, {});
        note = fmt::format("{} light(s)", estimator.estimate(*resampler->apply(l))->lights.size());
    }));
    cv::Mat city =
        cv::imread(dataDir + "/envmaps/polyhaven_1k_hdr/rooitou_park_1k.hdr", cv::IMREAD_UNCHANGED);
    if (!city.empty()) {
        cv::cvtColor(city, city, cv::COLOR_BGR2RGB);
        out.push_back(measure("lights on rooitou_park_1k.hdr (sun)", runs, [&](std::string& note) {
            note = fmt::format("{} light(s)", estimator.estimate(city)->lights.size());
        }));
    }
    return out;
}

}  // namespace previs
