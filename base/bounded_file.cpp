#include "base/bounded_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "base/unique_fd.h"

namespace previs {

namespace {

const char* kindOf(mode_t mode) {
    if (S_ISDIR(mode)) return "a folder";
    if (S_ISFIFO(mode)) return "a FIFO";
    if (S_ISCHR(mode)) return "a character device";
    if (S_ISBLK(mode)) return "a block device";
    if (S_ISSOCK(mode)) return "a socket";
    return "not a regular file";
}

// The open file and its size, checked. O_NONBLOCK: opening a FIFO must not wait for a writer
// (it is refused right after, by fstat); it changes nothing for a regular file.
Result<UniqueFD> openChecked(const std::string& path, uint64_t maxBytes, FileLinks links,
                             const std::string& what, uint64_t& size) {
    const int flags = O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY |
                      (links == FileLinks::Refuse ? O_NOFOLLOW : 0);
    UniqueFD fd(::open(path.c_str(), flags));
    if (!fd.isValid()) {
        if (errno == ELOOP && links == FileLinks::Refuse)
            return makeError("{} {}: is a symbolic link, which is not followed here", what, path);
        return makeError("{} {}: cannot open: {}", what, path, std::strerror(errno));
    }
    struct stat st {};
    if (::fstat(fd.get(), &st) != 0)
        return makeError("{} {}: cannot stat: {}", what, path, std::strerror(errno));
    if (!S_ISREG(st.st_mode))
        return makeError("{} {}: is {}, not a regular file; refused", what, path,
                         kindOf(st.st_mode));
    size = uint64_t(st.st_size);
    if (size > maxBytes)
        return makeError("{} {}: {} bytes, more than such a file may hold ({} bytes); refused",
                         what, path, size, maxBytes);
    return fd;
}

}  // namespace

Result<std::vector<uint8_t>> readBoundedFile(const std::string& path, uint64_t maxBytes,
                                             FileLinks links, const std::string& what) {
    uint64_t size = 0;
    Result<UniqueFD> fd = openChecked(path, maxBytes, links, what, size);
    if (!fd) return fd.error();
    // Only the size fstat gave is read: a file that grows meanwhile cannot take more memory.
    std::vector<uint8_t> bytes(size);
    size_t got = 0;
    while (got < bytes.size()) {
        const ssize_t n = ::read(fd->get(), bytes.data() + got, bytes.size() - got);
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) return makeError("{} {}: read failed: {}", what, path, std::strerror(errno));
        if (n == 0) return makeError("{} {}: cut short while being read", what, path);
        got += size_t(n);
    }
    return bytes;
}

Result<std::string> readBoundedText(const std::string& path, uint64_t maxBytes, FileLinks links,
                                    const std::string& what) {
    Result<std::vector<uint8_t>> bytes = readBoundedFile(path, maxBytes, links, what);
    if (!bytes) return bytes.error();
    return std::string(bytes->begin(), bytes->end());
}

Status checkBoundedFile(const std::string& path, uint64_t maxBytes, FileLinks links,
                        const std::string& what) {
    uint64_t size = 0;
    Result<UniqueFD> fd = openChecked(path, maxBytes, links, what, size);
    if (!fd) return fd.error();
    return {};
}

}  // namespace previs
