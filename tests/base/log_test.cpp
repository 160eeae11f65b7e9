// Log lines under systemd (base/log.h): with stderr connected to the journal (JOURNAL_STREAM
// names it), each line carries its syslog priority so `journalctl -p err` finds the errors; on a
// terminal or a file, and when the variable names another stream, the line is plain.
#include "base/log.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace previs {
namespace {

// What the logging calls write to stderr while it is the file `path` (and JOURNAL_STREAM is
// `journalStream`, or unset when empty).
std::string capture(const std::string& path, const std::string& journalStream) {
    std::fflush(stderr);
    const int saved = ::dup(STDERR_FILENO);
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    ::dup2(fd, STDERR_FILENO);
    if (journalStream.empty())
        ::unsetenv("JOURNAL_STREAM");
    else
        ::setenv("JOURNAL_STREAM", journalStream.c_str(), 1);
    logError("disk full");
    logWarning("slow");
    logInfo("started");
    std::fflush(stderr);
    ::dup2(saved, STDERR_FILENO);
    ::close(saved);
    ::close(fd);
    ::unsetenv("JOURNAL_STREAM");
    std::ifstream in(path);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
}

TEST(Log, PrioritiesOnlyWhenStderrIsTheJournal) {
    setLogProgramName("previsd");
    const std::string path =
        (std::filesystem::temp_directory_path() / ("previs_log_" + std::to_string(::getpid())))
            .string();
    std::ofstream(path) << "";
    struct stat st {};
    ASSERT_EQ(::stat(path.c_str(), &st), 0);
    const std::string self =
        std::to_string(uintmax_t(st.st_dev)) + ":" + std::to_string(uintmax_t(st.st_ino));
    EXPECT_EQ(capture(path, self),
              "<3>previsd: error: disk full\n<4>previsd: warning: slow\n<6>previsd: started\n");
    EXPECT_EQ(capture(path, ""),
              "previsd: error: disk full\nprevisd: warning: slow\nprevisd: started\n");
    EXPECT_EQ(capture(path, "1:2"),
              "previsd: error: disk full\nprevisd: warning: slow\nprevisd: started\n")
        << "a JOURNAL_STREAM naming another stream (stderr redirected since) is not the journal";
    std::filesystem::remove(path);
    setLogProgramName("previs");
}

}  // namespace
}  // namespace previs
