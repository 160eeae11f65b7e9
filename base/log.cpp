#include "base/log.h"

#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>

namespace previs {

namespace {
std::atomic<LogLevel> gLevel{LogLevel::Info};
std::atomic<const char*> gProgram{"previs"};
}  // namespace

void setLogLevel(LogLevel level) { gLevel = level; }

void setLogProgramName(const char* name) { gProgram = name; }

bool stderrIsJournal() {
    // systemd.exec(5): JOURNAL_STREAM is "DEVICE:INODE" of the stream it connected stderr to;
    // a process that redirected stderr since (or inherited the variable) must not match.
    const char* stream = std::getenv("JOURNAL_STREAM");
    struct stat st {};
    uintmax_t device = 0, inode = 0;
    return stream && std::sscanf(stream, "%ju:%ju", &device, &inode) == 2 &&
           ::fstat(STDERR_FILENO, &st) == 0 && uintmax_t(st.st_dev) == device &&
           uintmax_t(st.st_ino) == inode;
}

void logMessage(LogLevel level, const std::string& message) {
    if (level < gLevel.load()) return;
    static constexpr const char* kPrefix[] = {"debug: ", "", "warning: ", "error: "};
    // sd-daemon(3)'s SD_DEBUG, SD_INFO, SD_WARNING, SD_ERR: the journal files each line under its
    // priority, so `journalctl -p err -u previsd` shows the errors.
    static constexpr const char* kPriority[] = {"<7>", "<6>", "<4>", "<3>"};
    const int i = static_cast<int>(level);
    std::fprintf(stderr, "%s%s: %s%s\n", stderrIsJournal() ? kPriority[i] : "", gProgram.load(),
                 kPrefix[i], message.c_str());
}

void assertFailed(const char* expr, const char* file, int line) {
    std::fprintf(stderr, "previs: internal error: assertion '%s' failed at %s:%d\n", expr, file,
                 line);
    std::abort();
}

}  // namespace previs
