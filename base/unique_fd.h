#pragma once

// Sole owner of a file descriptor (the idea of libcamera's UniqueFD): closed exactly once, on
// destruction or reset(); moved, never copied, so no two objects can close the same number.

#include <unistd.h>

#include <utility>

namespace previs {

class UniqueFD {
public:
    UniqueFD() = default;
    explicit UniqueFD(int fd) : fd_(fd) {}
    ~UniqueFD() { reset(); }

    UniqueFD(UniqueFD&& other) noexcept : fd_(other.release()) {}
    UniqueFD& operator=(UniqueFD&& other) noexcept {
        reset(other.release());
        return *this;
    }
    UniqueFD(const UniqueFD&) = delete;
    UniqueFD& operator=(const UniqueFD&) = delete;

    int get() const { return fd_; }
    bool isValid() const { return fd_ >= 0; }

    // Gives up ownership without closing.
    [[nodiscard]] int release() { return std::exchange(fd_, -1); }

    // Closes the owned descriptor (if any) and takes `fd`. close() errors are ignored: after
    // close() the number is released whatever it returns (retrying could close a reused fd).
    void reset(int fd = -1) {
        int old = std::exchange(fd_, fd);
        if (old >= 0 && old != fd) ::close(old);
    }

private:
    int fd_ = -1;
};

}  // namespace previs
