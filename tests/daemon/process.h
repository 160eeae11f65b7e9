#pragma once

// A child process for the service tests: previsd and previs run as users run them (real
// binaries, real signals), stderr captured to a file.

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace previs::testing {

class ChildProcess {
public:
    ChildProcess(const std::vector<std::string>& argv, const std::string& logPath)
        : logPath_(logPath) {
        pid_ = ::fork();
        if (pid_ == 0) {
            FILE* log = std::fopen(logPath.c_str(), "w");
            if (log) {
                ::dup2(fileno(log), STDERR_FILENO);
                ::dup2(fileno(log), STDOUT_FILENO);
            }
            std::vector<char*> args;
            for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
            args.push_back(nullptr);
            ::execv(args[0], args.data());
            ::_exit(127);
        }
    }
    ~ChildProcess() {
        if (pid_ > 0 && !status_) {
            ::kill(pid_, SIGKILL);
            ::waitpid(pid_, nullptr, 0);
        }
    }
    ChildProcess(const ChildProcess&) = delete;
    ChildProcess& operator=(const ChildProcess&) = delete;

    void signal(int sig) const { ::kill(pid_, sig); }
    // The exit code, or nullopt if it is still running after `timeout` (or died by a signal:
    // then 128 + signal).
    std::optional<int> wait(std::chrono::milliseconds timeout) {
        const auto deadline = std::chrono::steady_clock::now() + timeout;
        while (!status_) {
            int st = 0;
            const pid_t r = ::waitpid(pid_, &st, WNOHANG);
            if (r == pid_) {
                status_ = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
                break;
            }
            if (std::chrono::steady_clock::now() > deadline) return std::nullopt;
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        return status_;
    }
    bool running() { return !wait(std::chrono::milliseconds(0)); }
    std::string log() const {
        std::ifstream in(logPath_);
        std::stringstream s;
        s << in.rdbuf();
        return s.str();
    }

private:
    pid_t pid_ = -1;
    std::string logPath_;
    std::optional<int> status_;
};

// Runs to completion; returns the exit code (or -1 on timeout, the process killed).
inline int runProcess(const std::vector<std::string>& argv, const std::string& logPath,
                      std::chrono::seconds timeout) {
    ChildProcess p(argv, logPath);
    std::optional<int> code = p.wait(timeout);
    return code ? *code : -1;
}

}  // namespace previs::testing
