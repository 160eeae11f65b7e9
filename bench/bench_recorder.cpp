#include "bench/bench_recorder.h"

#include <linux/videodev2.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "base/log.h"
#include "take/take_recorder.h"

namespace previs::bench {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

constexpr int kWidth = 1280, kHeight = 720;
constexpr double kCameraFps = 30.0;

// A 1280×720 RGB frame: the photograph scaled to fill, with σ = 2 codes of sensor noise.
std::shared_ptr<Frame> cameraFrame(const cv::Mat& photo, uint64_t seed) {
    cv::Mat scaled;
    cv::resize(photo, scaled, cv::Size(kWidth, kHeight), 0, 0, cv::INTER_LINEAR);
    cv::Mat noise(scaled.size(), CV_16SC3);
    cv::theRNG().state = seed;
    cv::randn(noise, 0, 2);
    cv::Mat noisy;
    scaled.convertTo(noisy, CV_16SC3);
    noisy += noise;
    noisy.convertTo(scaled, CV_8UC3);
    auto f = std::make_shared<Frame>();
    f->width = kWidth;
    f->height = kHeight;
    f->rgb.assign(scaled.data, scaled.data + size_t(kWidth) * kHeight * 3);
    return f;
}

struct Throughput {
    double framesPerSecond = 0.0;
    double megabytesPerSecond = 0.0;
    uint64_t dropped = 0;
    double bytesPerFrame = 0.0;
};

// Queues `frames` frames of two cameras as fast as possible and times until the take is durable.
Throughput recordTwoCameras(TakeRecorder& recorder, const std::vector<std::shared_ptr<Frame>>& pool,
                            bool mjpeg, int frames) {
    Throughput r;
    Result<std::string> take = recorder.start(mjpeg ? "mjpeg" : "yuyv");
    if (!take) {
        logError("bench recorder: {}", take.message());
        return r;
    }
    const auto start = Clock::now();
    for (int i = 0; i < frames; ++i) {
        for (const char* camera : {"scene", "fisheye"}) {
            auto f = std::make_shared<Frame>(*pool[size_t(i) % pool.size()]);
            f->sequence = uint64_t(i);
            f->timestampNs = uint64_t(double(i) * 1e9 / kCameraFps) + 1;
            f->wallClockNs = 1'800'000'000'000'000'000ull + f->timestampNs;
            if (!mjpeg) {
                // As V4L2 delivers YUYV: 2 bytes a pixel (the bench's RGB stands in for the
                // bytes; the writer's cost is the size, not the content).
                f->captured = std::make_shared<const std::vector<uint8_t>>(
                    f->rgb.begin(), f->rgb.begin() + ptrdiff_t(kWidth) * kHeight * 2);
                f->capturedFourcc = v4l2_fourcc('Y', 'U', 'Y', 'V');
            }
            recorder.addFrame(camera, std::move(f));
        }
    }
    (void)recorder.stop();
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    const RecordStatus s = recorder.status();
    r.framesPerSecond = 2.0 * frames / seconds;
    r.megabytesPerSecond = double(s.bytes) / (1 << 20) / seconds;
    r.dropped = s.dropped;
    r.bytesPerFrame = double(s.bytes) / (2.0 * frames);
    std::error_code ec;
    fs::remove_all(*take, ec);
    return r;
}

}  // namespace

int runRecorderBench(const RecorderBenchOptions& o) {
    const std::string photoPath =
        o.dataDir + "/apriltag/apriltag_upstream_nasa/34139872896_defdb2f8d9_c.jpg";
    cv::Mat bgr = cv::imread(photoPath, cv::IMREAD_COLOR);
    if (bgr.empty()) {
        logError("bench recorder: cannot read {}", photoPath);
        return 2;
    }
    cv::Mat rgb;
    cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
    Result<ServiceConfig> config = loadServiceConfig(o.examplesDir + "/demo/previsd.toml");
    if (!config) {
        logError("bench recorder: {}", config.message());
        return 2;
    }
    const fs::path dir =
        fs::temp_directory_path() / fmt::format("previs_bench_recorder_{}", getpid());
    config->record.dir = dir.string();
    config->record.minFreeMb = 64;
    config->record.queueMb = 8192;  // everything queued: the writer's speed alone is timed
    // Eight different frames (noise differs), each also as an MJPEG camera would send it.
    std::vector<std::shared_ptr<Frame>> pool;
    for (uint64_t i = 0; i < 8; ++i) {
        std::shared_ptr<Frame> f = cameraFrame(rgb, i + 1);
        cv::Mat frameBgr;
        cv::cvtColor(cv::Mat(kHeight, kWidth, CV_8UC3, f->rgb.data()), frameBgr, cv::COLOR_RGB2BGR);
        std::vector<uint8_t> jpeg;
        cv::imencode(".jpg", frameBgr, jpeg, {cv::IMWRITE_JPEG_QUALITY, 90});
        f->captured = std::make_shared<const std::vector<uint8_t>>(std::move(jpeg));
        f->capturedFourcc = v4l2_fourcc('M', 'J', 'P', 'G');
        pool.push_back(std::move(f));
    }
    const int frames = o.quick ? 30 : 150;
    std::printf(
        "Take recorder, two cameras at %dx%d: %d frames each, queued at once; timed until "
        "the take is durable. Needed on set: %.0f frames/s (two cameras at %.0f fps).\n\n",
        kWidth, kHeight, frames, 2 * kCameraFps, kCameraFps);
    std::printf(
        "| camera format | stored as | frames/s | MB/s written | KiB a frame | vs 2 × 30 fps |\n");
    std::printf("|---|---|---|---|---|---|\n");
    TakeRecorder recorder(*config);
    for (bool mjpeg : {true, false}) {
        const Throughput r = recordTwoCameras(recorder, pool, mjpeg, frames);
        std::printf("| %s | %s | %.1f | %.1f | %.0f | %.2f× |\n", mjpeg ? "MJPEG" : "YUYV (raw)",
                    mjpeg ? "the camera's JPEG bytes" : "the camera's bytes (.yuyv)",
                    r.framesPerSecond, r.megabytesPerSecond, r.bytesPerFrame / 1024.0,
                    r.framesPerSecond / (2 * kCameraFps));
    }
    std::error_code ec;
    fs::remove_all(dir, ec);
    return 0;
}

}  // namespace previs::bench
