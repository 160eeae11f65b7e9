#pragma once

#include <fmt/format.h>

namespace previs {

enum class LogLevel { Debug, Info, Warning, Error };

void setLogLevel(LogLevel level);
// One line on stderr: "PROGRAM: [warning: |error: ]MESSAGE". When stderr is systemd's journal
// stream (stderrIsJournal), the line starts with its syslog priority ("<3>" errors, "<4>"
// warnings, "<6>" info, "<7>" debug; sd-daemon(3)).
void logMessage(LogLevel level, const std::string& message);
// Whether stderr is the stream systemd connected to the journal (JOURNAL_STREAM matches it).
bool stderrIsJournal();
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
