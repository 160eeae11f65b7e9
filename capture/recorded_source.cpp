#include "capture/recorded_source.h"

#include <linux/videodev2.h>

#include <cctype>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <thread>
#include <utility>

#include "base/log.h"
#include "capture/pixel_format.h"
#include "image/image.h"

namespace previs {

Result<Frame> readRecordedFrame(const RecordedFrameEntry& e) {
    // A take from elsewhere is untrusted: no symbolic link followed, the size checked before
    // decoding; OpenCV may throw on a hostile file, which stays inside this module.
    Result<std::vector<uint8_t>> bytes = readSessionFile(e.file);
    if (!bytes) return bytes.error();
    Frame frame;
    frame.width = e.width;
    frame.height = e.height;
    const std::string ext = e.file.substr(e.file.rfind('.') + 1);
    if (ext == "jpg" || ext == "png") {
        // The header's size first: a few kilobytes may declare 30000 x 30000, which would cost
        // gigabytes and minutes to decode before the size could be compared.
        Result<ImageSize> declared = encodedImageSize(*bytes, e.file);
        if (!declared) return declared.error();
        if (declared->width != e.width || declared->height != e.height)
            return makeError("{}: declares {}x{} pixels, its index line {}x{}; not decoded", e.file,
                             declared->width, declared->height, e.width, e.height);
        cv::Mat bgr;
        try {
            bgr = cv::imdecode(cv::Mat(1, int(bytes->size()), CV_8UC1, bytes->data()),
                               cv::IMREAD_COLOR);
        } catch (const cv::Exception&) {
            bgr.release();
        }
        if (bgr.empty() || uint32_t(bgr.cols) != e.width || uint32_t(bgr.rows) != e.height)
            return makeError("{}: unreadable or not {}x{}", e.file, e.width, e.height);
        frame.rgb.resize(size_t(e.width) * e.height * 3);
        cv::Mat rgb(bgr.rows, bgr.cols, CV_8UC3, frame.rgb.data());
        cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
        if (ext == "jpg") frame.capturedFourcc = V4L2_PIX_FMT_MJPEG;
    } else {
        // A raw frame as the camera sent it, its lines unpadded; the extension names its format.
        std::string name = ext;
        for (char& c : name) c = char(std::toupper(static_cast<unsigned char>(c)));
        const uint32_t fourcc = fourccFromString(name);
        if (!isSupportedFormat(fourcc) || isJpegFourcc(fourcc))
            return makeError("{}: '.{}' is not a frame format previs reads", e.file, ext);
        if (Status s = convertToRgb(fourcc, *bytes, e.width, e.height,
                                    packedStride(fourcc, e.width), frame.rgb);
            !s)
            return makeError("{}: {}", e.file, s.message());
        frame.capturedFourcc = fourcc;
    }
    frame.timestampNs = e.timestampNs;
    frame.wallClockNs = e.wallClockNs.value_or(0);
    frame.exposureStops = e.exposureStops;
    frame.deviceSequence = uint32_t(e.sequence);
    // A recorded JPEG or raw frame goes on as its bytes, so a take recorded from a replay keeps
    // them.
    if (frame.capturedFourcc != 0)
        frame.captured = std::make_shared<const std::vector<uint8_t>>(std::move(*bytes));
    return frame;
}

RecordedReader::RecordedReader(std::vector<RecordedFrameEntry> entries, ReplayTiming timing)
    : entries_(std::move(entries)), timing_(timing) {
    // Gaps in unsigned arithmetic (timestamps only grow, loadCameraIndex checks it), capped
    // before they become durations, so no timestamp can overflow the schedule.
    const uint64_t maxGapNs =
        uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(kMaxReplayGap).count());
    std::chrono::nanoseconds at{0};
    size_t capped = 0;
    for (size_t i = 0; i < entries_.size(); ++i) {
        if (i > 0) {
            uint64_t gap = entries_[i].timestampNs - entries_[i - 1].timestampNs;
            if (gap > maxGapNs) {
                if (capped++ == 0 && timing_ == ReplayTiming::Recorded)
                    logWarning(
                        "{}: {:.3g} s between frames {} and {}; replayed as {} s (and any "
                        "other such gap)",
                        entries_[i].file, double(gap) * 1e-9, entries_[i - 1].sequence,
                        entries_[i].sequence, kMaxReplayGap.count());
                gap = maxGapNs;
            }
            at += std::chrono::nanoseconds(int64_t(gap));
        }
        due_.push_back(at);
    }
}

Result<std::unique_ptr<RecordedReader>> RecordedReader::create(const std::string& cameraDir,
                                                               ReplayTiming timing) {
    auto entries = loadCameraIndex(cameraDir);
    if (!entries) return entries.error();
    return std::unique_ptr<RecordedReader>(new RecordedReader(std::move(*entries), timing));
}

Status RecordedReader::start() {
    next_ = 0;
    startTime_ = std::chrono::steady_clock::now();
    return {};
}

Result<bool> RecordedReader::read(int timeoutMs, Frame& frame) {
    while (next_ < entries_.size()) {
        const RecordedFrameEntry& e = entries_[next_];
        if (timing_ == ReplayTiming::Recorded) {
            const auto due = startTime_ + due_[next_];
            const auto now = std::chrono::steady_clock::now();
            if (due > now + std::chrono::milliseconds(timeoutMs)) {
                std::this_thread::sleep_for(std::chrono::milliseconds(timeoutMs));
                return false;
            }
            std::this_thread::sleep_until(due);
        }
        ++next_;
        Result<Frame> decoded = readRecordedFrame(e);
        if (!decoded) {
            if (badFrames_++ < 3) logWarning("{}; frame {} skipped", decoded.message(), e.sequence);
            continue;
        }
        frame = std::move(*decoded);
        return true;
    }
    return false;
}

std::unique_ptr<CameraSource> makeRecordedSource(const std::string& cameraDir, ReplayTiming timing,
                                                 CaptureOptions options) {
    FrameReaderFactory factory = [cameraDir, timing]() -> Result<std::unique_ptr<FrameReader>> {
        auto reader = RecordedReader::create(cameraDir, timing);
        if (!reader) return reader.error();
        return std::unique_ptr<FrameReader>(std::move(*reader));
    };
    return std::make_unique<CaptureThread>(std::move(factory), std::move(options));
}

}  // namespace previs
