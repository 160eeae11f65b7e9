#include "capture/recorded_source.h"

#include <charconv>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <string_view>
#include <thread>
#include <utility>

#include "base/log.h"

namespace previs {

namespace {

// docs/session-format.md: the version this reader understands.
constexpr int kCameraIndexVersion = 1;

template <typename T>
bool parseNumber(const std::string& s, T& out) {
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
    return ec == std::errc() && end == s.data() + s.size();
}

}  // namespace

Result<std::vector<RecordedFrameEntry>> loadCameraIndex(const std::string& cameraDir) {
    const std::string path = cameraDir + "/index.csv";
    std::ifstream in(path, std::ios::binary);
    if (!in)
        return makeError(
            "{}: cannot open (is {} a session camera folder? see "
            "docs/session-format.md)",
            path, cameraDir);
    std::stringstream buffer;
    buffer << in.rdbuf();
    const std::string text = buffer.str();

    std::vector<RecordedFrameEntry> entries;
    size_t pos = 0;
    int lineNo = 0;
    while (pos < text.size()) {
        const size_t eol = text.find('\n', pos);
        // No terminating newline: the recorder was cut off mid-append; that line never counted.
        if (eol == std::string::npos) break;
        std::string line = text.substr(pos, eol - pos);
        pos = eol + 1;
        ++lineNo;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        // The header names the format version; a newer major version may mean columns this
        // reader would misread, so it refuses rather than replay wrong data.
        constexpr std::string_view kHeader = "# previs-session camera index v";
        if (line.starts_with(kHeader)) {
            const std::string rest = line.substr(kHeader.size(), line.find(':') - kHeader.size());
            int version = 0;
            if (!parseNumber(rest, version) || version < 1)
                return makeError("{}:{}: unreadable format version in '{}'", path, lineNo, line);
            if (version > kCameraIndexVersion)
                return makeError(
                    "{}: format version {} is newer than this previs reads ({}); "
                    "replay it with a newer previs",
                    path, version, kCameraIndexVersion);
            continue;
        }
        if (line.empty() || line[0] == '#') continue;
        std::vector<std::string> fields;
        std::stringstream ls(line);
        for (std::string f; std::getline(ls, f, ',');) fields.push_back(f);
        RecordedFrameEntry e;
        // Five fields; later versions may append columns (docs/session-format.md, versioning).
        if (fields.size() < 5 || !parseNumber(fields[0], e.sequence) ||
            !parseNumber(fields[1], e.timestampNs) || fields[2].empty() ||
            fields[2].find('/') != std::string::npos || !parseNumber(fields[3], e.width) ||
            !parseNumber(fields[4], e.height))
            return makeError(
                "{}:{}: malformed frame line '{}' (expected "
                "sequence,timestampNs,file,width,height)",
                path, lineNo, line);
        if (!entries.empty() &&
            (e.sequence <= entries.back().sequence || e.timestampNs < entries.back().timestampNs))
            return makeError("{}:{}: sequence or timestamp goes backwards", path, lineNo);
        e.file = cameraDir + "/" + fields[2];
        entries.push_back(std::move(e));
    }
    return entries;
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
        // OpenCV may throw on a hostile file; that stays inside this module.
        cv::Mat bgr;
        try {
            bgr = cv::imread(e.file, cv::IMREAD_COLOR);
        } catch (const cv::Exception&) {
            bgr.release();
        }
        if (bgr.empty() || uint32_t(bgr.cols) != e.width || uint32_t(bgr.rows) != e.height) {
            if (badFrames_++ < 3)
                logWarning("{}: unreadable or not {}x{}; frame {} skipped", e.file, e.width,
                           e.height, e.sequence);
            continue;
        }
        frame.width = e.width;
        frame.height = e.height;
        frame.rgb.resize(size_t(e.width) * e.height * 3);
        cv::Mat rgb(bgr.rows, bgr.cols, CV_8UC3, frame.rgb.data());
        cv::cvtColor(bgr, rgb, cv::COLOR_BGR2RGB);
        frame.timestampNs = e.timestampNs;
        frame.deviceSequence = uint32_t(e.sequence);
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
