#pragma once

#include <fmt/format.h>

namespace previs {

enum class LogLevel { Debug, Info, Warning, Error };

void setLogLevel(LogLevel level);
void logMessage(LogLevel level, const std::string& message);
// The name log lines start with ("previs" unless set; previsd sets its own).
void setLogProgramName(const char* name);

template <typename... Args>
void logInfo(fmt::format_string<Args...> f, Args&&... args) {
    logMessage(LogLevel::Info, fmt::format(f, std::forward<Args>(args)...));
}
template <typename... Args>
void logWarning(fmt::format_string<Args...> f, Args&&... args) {
    logMessage(LogLevel::Warning, fmt::format(f, std::forward<Args>(args)...));
}
template <typename... Args>
void logError(fmt::format_string<Args...> f, Args&&... args) {
    logMessage(LogLevel::Error, fmt::format(f, std::forward<Args>(args)...));
}
template <typename... Args>
void logDebug(fmt::format_string<Args...> f, Args&&... args) {
    logMessage(LogLevel::Debug, fmt::format(f, std::forward<Args>(args)...));
}

}  // namespace previs

// Bugs only (STYLE.md error channel 1): never for input a user can get wrong.
#define PV_ASSERT(cond)                                                 \
    do {                                                                \
        if (!(cond)) ::previs::assertFailed(#cond, __FILE__, __LINE__); \
    } while (0)
#ifdef NDEBUG
#define PV_DCHECK(cond) ((void)0)
#else
#define PV_DCHECK(cond) PV_ASSERT(cond)
#endif

namespace previs {
[[noreturn]] void assertFailed(const char* expr, const char* file, int line);
}
