#include "base/atomic_file.h"

#include <fcntl.h>
#include <sys/random.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <filesystem>
#include <utility>

#include "base/log.h"

namespace previs {

namespace {

// Names tried before giving up: another file at a 64-bit random name is already a sign of
// something wrong, sixteen in a row of a folder someone fills on purpose.
constexpr int kNameAttempts = 16;

uint64_t randomBits() {
    uint64_t bits = 0;
    // getrandom() of 8 bytes from the urandom pool does not block once it is initialised (early
    // boot only). Should it fail, the clock and a counter still make each name new; O_EXCL keeps
    // any name safe.
    while (::getrandom(&bits, sizeof bits, GRND_NONBLOCK) < 0 && errno == EINTR) {
    }
    static std::atomic<uint64_t> counter{0};
    const uint64_t now = uint64_t(std::chrono::steady_clock::now().time_since_epoch().count());
    return bits ^ (now * 0x9e3779b97f4a7c15ull) ^ counter.fetch_add(1);
}

std::string temporaryName(const std::string& path, bool hidden) {
    const std::string suffix = fmt::format(".{:016x}.tmp", randomBits());
    if (!hidden) return path + suffix;
    const std::filesystem::path p(path);
    return (p.parent_path() / ("." + p.filename().string() + suffix)).string();
}

}  // namespace

Result<AtomicFile> AtomicFile::create(const std::string& path, const AtomicFileOptions& options) {
    std::string temporary;
    for (int attempt = 0; attempt < kNameAttempts; ++attempt) {
        temporary = temporaryName(path, options.hidden);
        // O_EXCL: never an existing file (nor, with O_NOFOLLOW, through a link) — a new inode.
        UniqueFD fd(
            ::open(temporary.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_NOFOLLOW | O_CLOEXEC, 0644));
        if (fd.isValid())
            return AtomicFile(path, std::move(temporary), std::move(fd), options.durable);
        if (errno != EEXIST)
            return makeError("{}: cannot create: {}; check the folder exists and is writable",
                             temporary, std::strerror(errno));
    }
    return makeError("{}: cannot create a temporary file: {} names in a row were taken", temporary,
                     kNameAttempts);
}

AtomicFile::AtomicFile(AtomicFile&& other) noexcept
    : path_(std::move(other.path_)),
      temporary_(std::exchange(other.temporary_, {})),
      fd_(std::move(other.fd_)),
      durable_(other.durable_) {}

AtomicFile& AtomicFile::operator=(AtomicFile&& other) noexcept {
    if (this != &other) {
        discard();
        path_ = std::move(other.path_);
        temporary_ = std::exchange(other.temporary_, {});
        fd_ = std::move(other.fd_);
        durable_ = other.durable_;
    }
    return *this;
}

Status AtomicFile::write(std::span<const uint8_t> bytes) {
    PV_ASSERT(fd_.isValid());
    const uint8_t* p = bytes.data();
    size_t left = bytes.size();
    while (left > 0) {
        const ssize_t n = ::write(fd_.get(), p, left);
        if (n < 0 && errno == EINTR) continue;
        if (n <= 0)
            return makeError("{}: write failed: {} (is the disk full?)", temporary_,
                             n < 0 ? std::strerror(errno) : "no progress");
        p += n;
        left -= size_t(n);
    }
    return {};
}

Status AtomicFile::commit() {
    PV_ASSERT(fd_.isValid() && !temporary_.empty());
    if (durable_ && ::fdatasync(fd_.get()) != 0) {
        const int err = errno;
        const std::string temporary = temporary_;
        discard();
        return makeError("{}: fdatasync failed: {}", temporary, std::strerror(err));
    }
    fd_.reset();
    if (::rename(temporary_.c_str(), path_.c_str()) != 0) {
        const int err = errno;
        const std::string temporary = temporary_;
        discard();
        return makeError("{}: cannot rename to {}: {}", temporary, path_, std::strerror(err));
    }
    temporary_.clear();
    return {};
}

void AtomicFile::discard() {
    fd_.reset();
    if (temporary_.empty()) return;
    ::unlink(temporary_.c_str());
    temporary_.clear();
}

Status writeFileAtomic(const std::string& path, std::span<const uint8_t> bytes,
                       const AtomicFileOptions& options) {
    Result<AtomicFile> file = AtomicFile::create(path, options);
    if (!file) return file.error();
    if (Status s = file->write(bytes); !s) return s;
    return file->commit();
}

}  // namespace previs
