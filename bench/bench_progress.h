#pragma once

// `previs bench`'s progress on stderr: "bench: ..." lines, silenced by --quiet (the results go
// to stdout either way). One flag for the process: the sections run one after another.

#include <fmt/format.h>

#include <atomic>
#include <cstdio>
#include <utility>

namespace previs::bench {

inline std::atomic<bool>& benchQuiet() {
    static std::atomic<bool> quiet{false};
    return quiet;
}

template <typename... Args>
void benchProgress(fmt::format_string<Args...> format, Args&&... args) {
    if (benchQuiet()) return;
    fmt::print(stderr, "bench: {}\n", fmt::format(format, std::forward<Args>(args)...));
}

}  // namespace previs::bench
