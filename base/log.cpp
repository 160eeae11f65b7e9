#include "base/log.h"

#include <atomic>
#include <cstdio>
#include <cstdlib>

namespace previs {

namespace {
std::atomic<LogLevel> gLevel{LogLevel::Info};
std::atomic<const char*> gProgram{"previs"};
}  // namespace

void setLogLevel(LogLevel level) { gLevel = level; }

void setLogProgramName(const char* name) { gProgram = name; }

void logMessage(LogLevel level, const std::string& message) {
    if (level < gLevel.load()) return;
    static constexpr const char* kPrefix[] = {"debug: ", "", "warning: ", "error: "};
    std::fprintf(stderr, "%s: %s%s\n", gProgram.load(), kPrefix[static_cast<int>(level)],
                 message.c_str());
}

void assertFailed(const char* expr, const char* file, int line) {
    std::fprintf(stderr, "previs: internal error: assertion '%s' failed at %s:%d\n", expr, file,
                 line);
    std::abort();
}

}  // namespace previs
