#pragma once

#include <fmt/format.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <utility>
#include <variant>

namespace previs {

// The error half of a Result: a message a user can act on (names the file, device or option,
// what is wrong and what to do), and its kind, which decides how a program ends on it (previsd:
// a config error exits 2, which systemd does not restart; the others exit 1).
struct Error {
    enum class Kind {
        Runtime,  // may succeed when tried again (the default)
        Config,   // the config, or a file, option or name it gives: the user must change it
        Device,   // a device (the GPU, a camera) missing or failing
    };
    std::string message;
    Kind kind = Kind::Runtime;
};

template <typename... Args>
Error makeError(fmt::format_string<Args...> format, Args&&... args) {
    return Error{fmt::format(format, std::forward<Args>(args)...)};
}

// An error of `kind`: a new message, or one passed on (its message kept).
template <typename... Args>
Error makeError(Error::Kind kind, fmt::format_string<Args...> format, Args&&... args) {
    return Error{fmt::format(format, std::forward<Args>(args)...), kind};
}
inline Error withKind(Error error, Error::Kind kind) {
    error.kind = kind;
    return error;
}

// Taking the value of a Result that holds an error is a programming mistake: it stops the
// program with the error's own message instead of an anonymous bad_variant_access.
[[noreturn]] inline void failedValueAccess(const Error& error) {
    std::fprintf(stderr, "previs: internal error: the value of a failed result was used: %s\n",
                 error.message.c_str());
    std::abort();
}

// Value or error, for loading and initialisation (gcc 12 has no std::expected).
template <typename T>
class [[nodiscard]] Result {
public:
    Result(T value) : v_(std::move(value)) {}
    Result(Error error) : v_(std::move(error)) {}

    bool ok() const { return v_.index() == 0; }
    explicit operator bool() const { return ok(); }

    T& value() & { return checked(), *std::get_if<0>(&v_); }
    const T& value() const& { return checked(), *std::get_if<0>(&v_); }
    T&& value() && { return checked(), std::move(*std::get_if<0>(&v_)); }
    T& operator*() & { return value(); }
    const T& operator*() const& { return value(); }
    T* operator->() { return &value(); }
    const T* operator->() const { return &value(); }

    const Error& error() const {
        if (ok()) failedValueAccess(Error{"error() of a result that holds a value"});
        return *std::get_if<1>(&v_);
    }
    const std::string& message() const { return error().message; }

private:
    void checked() const {
        if (!ok()) failedValueAccess(std::get<1>(v_));
    }

    std::variant<T, Error> v_;
};

// Result of an operation with no value.
class [[nodiscard]] Status {
public:
    Status() = default;
    Status(Error error) : error_(std::move(error)), ok_(false) {}
    bool ok() const { return ok_; }
    explicit operator bool() const { return ok_; }
    const std::string& message() const { return error_.message; }
    const Error& error() const { return error_; }

private:
    Error error_;
    bool ok_ = true;
};

}  // namespace previs
