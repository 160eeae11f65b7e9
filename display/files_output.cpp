#include "display/files_output.h"

#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string_view>
#include <tuple>
#include <vector>

#include "base/atomic_file.h"
#include "base/log.h"
#include "display/compose.h"

namespace previs {

namespace {

// "frame_000123.png" → 123.
std::optional<uint64_t> frameIndexOf(const std::string& name) {
    constexpr std::string_view kPrefix = "frame_", kSuffix = ".png";
    if (name.size() <= kPrefix.size() + kSuffix.size() || !name.starts_with(kPrefix) ||
        !name.ends_with(kSuffix))
        return std::nullopt;
    const std::string_view digits(name.data() + kPrefix.size(),
                                  name.size() - kPrefix.size() - kSuffix.size());
    uint64_t index = 0;
    const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), index);
    if (ec != std::errc() || end != digits.data() + digits.size()) return std::nullopt;
    return index;
}

}  // namespace

Result<std::unique_ptr<FilesOutput>> FilesOutput::create(const std::string& folder,
                                                         const FilesOutputLimits& limits) {
    if (folder.empty())
        return makeError("[output] kind = \"files\" needs folder = \"PATH\" for the PNG frames");
    std::error_code ec;
    std::filesystem::create_directories(folder, ec);
    if (ec || !std::filesystem::is_directory(folder))
        return makeError(
            "output folder {}: cannot create it ({}): check the path and its "
            "permissions",
            folder, ec ? ec.message() : "not a directory");
    std::unique_ptr<FilesOutput> out(new FilesOutput(folder, limits));
    out->adoptExisting();
    return out;
}

void FilesOutput::adoptExisting() {
    struct Found {
        std::filesystem::file_time_type written;
        uint64_t index;
        uint64_t bytes;
    };
    std::vector<Found> found;
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(folder_, ec)) {
        std::error_code entryError;
        // Regular files only (symlink_status): a link is never followed, nor counted.
        if (!entry.is_regular_file(entryError) || entry.is_symlink(entryError)) continue;
        const std::string name = entry.path().filename().string();
        if (name.starts_with(".frame_") && name.ends_with(".tmp")) {
            ::unlink(entry.path().c_str());  // a killed run's unfinished frame
            continue;
        }
        const std::optional<uint64_t> index = frameIndexOf(name);
        const uint64_t bytes = entry.file_size(entryError);
        const auto written = entry.last_write_time(entryError);
        if (index && !entryError) found.push_back({written, *index, bytes});
    }
    // A previous run's frames are older than any to come: first in line to go.
    std::sort(found.begin(), found.end(), [](const Found& a, const Found& b) {
        return std::tie(a.written, a.index) < std::tie(b.written, b.index);
    });
    for (const Found& f : found) remember(f.index, f.bytes);
    prune();
}

std::string FilesOutput::framePath(uint64_t index) const {
    return fmt::format("{}/frame_{:06d}.png", folder_, index);
}

void FilesOutput::remember(uint64_t index, uint64_t bytes) {
    if (auto it = frames_.find(index); it != frames_.end()) totalBytes_ -= it->second.first;
    frames_[index] = {bytes, ++generation_};
    order_.emplace_back(index, generation_);
    totalBytes_ += bytes;
    // A frame written again leaves its older place behind: compact before those pile up.
    if (order_.size() > 2 * frames_.size() + 64) {
        std::erase_if(order_, [&](const auto& o) {
            const auto it = frames_.find(o.first);
            return it == frames_.end() || it->second.second != o.second;
        });
    }
}

void FilesOutput::prune() {
    // The newest frame always stays, whatever the limits.
    while ((frames_.size() > limits_.keepFrames || totalBytes_ > limits_.maxBytes) &&
           frames_.size() > 1 && !order_.empty()) {
        const auto [index, generation] = order_.front();
        order_.pop_front();
        auto it = frames_.find(index);
        if (it == frames_.end() || it->second.second != generation) continue;
        ::unlink(framePath(index).c_str());  // never follows a link: removes the name only
        totalBytes_ -= it->second.first;
        frames_.erase(it);
    }
}

bool FilesOutput::roomFor(uint64_t bytes) {
    struct statvfs st {};
    if (::statvfs(folder_.c_str(), &st) != 0) return true;  // unknown: the write will tell
    const uint64_t free = uint64_t(st.f_bavail) * uint64_t(st.f_frsize);
    const bool room = free >= limits_.minFreeBytes + bytes;
    if (!room && !lowOnSpace_)
        logWarning(
            "output folder {}: {} MiB free, under [output] min_free_mb = {}; frames are not "
            "written until there is room (free space, or lower keep_frames or max_mb)",
            folder_, free >> 20, limits_.minFreeBytes >> 20);
    if (room && lowOnSpace_) logInfo("output folder {}: room again; writing frames", folder_);
    lowOnSpace_ = !room;
    return room;
}

Status FilesOutput::show(const DisplayFrame& frame) {
    lastDropped_ = false;
    const std::string path = framePath(frame.index);
    if (frame.width == 0 || frame.height == 0 ||
        frame.rgb.size() != size_t(frame.width) * frame.height * 3)
        return makeError("{}: frame {} has no valid pixels ({}x{}, {} bytes), not written", path,
                         frame.index, frame.width, frame.height, frame.rgb.size());

    // Overlay on a copy: the frame is an immutable snapshot other consumers may share.
    cv::Mat rgb(int(frame.height), int(frame.width), CV_8UC3);
    std::memcpy(rgb.data, frame.rgb.data(), frame.rgb.size());
    drawStatusRgb(rgb.data, frame.width, frame.height, frame.status);
    cv::Mat bgr;
    cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
    std::vector<uint8_t> png;
    try {
        if (!cv::imencode(".png", bgr, png)) return makeError("{}: PNG encoding failed", path);
    } catch (const cv::Exception& e) {
        return makeError("{}: PNG encoding failed: {}", path, e.what());
    }
    if (!roomFor(png.size())) {
        lastDropped_ = true;
        return {};
    }
    // Looked at live, never kept across a power cut: not synced.
    if (Status s = writeFileAtomic(path, png, {.durable = false, .hidden = true}); !s)
        return makeError("{}: check the output folder (is the disk full?)", s.message());
    remember(frame.index, png.size());
    prune();
    return {};
}

}  // namespace previs
