#include "display/files_output.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "base/unique_fd.h"
#include "display/compose.h"

namespace previs {

Result<std::unique_ptr<FilesOutput>> FilesOutput::create(const std::string& folder) {
    if (folder.empty())
        return makeError("[output] kind = \"files\" needs folder = \"PATH\" for the PNG frames");
    std::error_code ec;
    std::filesystem::create_directories(folder, ec);
    if (ec || !std::filesystem::is_directory(folder))
        return makeError(
            "output folder {}: cannot create it ({}): check the path and its "
            "permissions",
            folder, ec ? ec.message() : "not a directory");
    return std::unique_ptr<FilesOutput>(new FilesOutput(folder));
}

std::string FilesOutput::framePath(uint64_t index) const {
    return fmt::format("{}/frame_{:06d}.png", folder_, index);
}

Status FilesOutput::show(const DisplayFrame& frame) {
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

    const std::string tmp = fmt::format("{}/.frame_{:06d}.png.tmp", folder_, frame.index);
    UniqueFD fd(::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644));
    if (!fd.isValid())
        return makeError("{}: cannot create ({}): check the output folder", tmp,
                         std::strerror(errno));
    size_t done = 0;
    while (done < png.size()) {
        const ssize_t n = ::write(fd.get(), png.data() + done, png.size() - done);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0) {
            const int err = n < 0 ? errno : EIO;
            ::unlink(tmp.c_str());
            return makeError("{}: write failed ({}): is the disk full?", tmp, std::strerror(err));
        }
        done += size_t(n);
    }
    fd.reset();
    if (::rename(tmp.c_str(), path.c_str()) != 0) {
        const int err = errno;
        ::unlink(tmp.c_str());
        return makeError("{}: rename failed ({})", path, std::strerror(err));
    }
    return {};
}

}  // namespace previs
