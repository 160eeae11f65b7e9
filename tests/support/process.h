#pragma once

// Child processes for the tests that run previs and previsd as users run them (real binaries,
// real signals): ChildProcess for long-running services (output to a file), runCommand for
// one command's exit code, stdout and stderr.

#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

namespace previs::testing {

// Sockets handed to a child as systemd's socket activation does (sd_listen_fds(3)): each fd
// becomes 3, 4, ... in the child with LISTEN_FDS, LISTEN_PID and LISTEN_FDNAMES set.
using PassedSockets = std::vector<std::pair<int, std::string>>;

class ChildProcess {
public:
    ChildProcess(const std::vector<std::string>& argv, const std::string& logPath,
                 const PassedSockets& sockets = {})
        : logPath_(logPath) {
        pid_ = ::fork();
        if (pid_ == 0) {
            FILE* log = std::fopen(logPath.c_str(), "w");
            if (log) {
                ::dup2(fileno(log), STDERR_FILENO);
                ::dup2(fileno(log), STDOUT_FILENO);
            }
            if (!sockets.empty()) passSockets(sockets);
            std::vector<char*> args;
            for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
            args.push_back(nullptr);
            ::execv(args[0], args.data());
            ::_exit(127);
        }
    }
    // In the child, before exec: first out of the way (a socket may already sit on 3 or 4),
    // then into place.
    static void passSockets(const PassedSockets& sockets) {
        std::vector<int> moved;
        for (const auto& [fd, name] : sockets) moved.push_back(::fcntl(fd, F_DUPFD, 100));
        std::string names;
        for (size_t i = 0; i < moved.size(); ++i) {
            ::dup2(moved[i], 3 + int(i));
            ::close(moved[i]);
            names += (i ? ":" : "") + sockets[i].second;
        }
        ::setenv("LISTEN_FDS", std::to_string(moved.size()).c_str(), 1);
        ::setenv("LISTEN_PID", std::to_string(::getpid()).c_str(), 1);
        ::setenv("LISTEN_FDNAMES", names.c_str(), 1);
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
    pid_t pid() const { return pid_; }
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
    // The process's threads, one line each: name, state and the kernel function it sleeps in
    // (/proc/PID/task/*/{comm,stat,wchan}); says where a process that does not exit waits.
    std::string threads() const {
        std::string out;
        std::error_code gone;  // the process exited meanwhile: no threads
        for (const auto& task :
             std::filesystem::directory_iterator("/proc/" + std::to_string(pid_) + "/task", gone)) {
            auto read = [&](const char* file) {
                std::ifstream in(task.path() / file);
                std::string line;
                std::getline(in, line);
                return line;
            };
            const std::string stat = read("stat");
            const size_t close = stat.rfind(')');
            const std::string state = close == std::string::npos ? "?" : stat.substr(close + 2, 1);
            out += read("comm") + " " + state + " " + read("wchan") + "\n";
        }
        return out;
    }
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

struct CommandResult {
    int exitCode = -1;  // -1: killed at the timeout; 128 + N: died by signal N
    std::string out, err;
};

// Runs argv to completion with stdin closed. stderrTerminal: stderr is a pseudo-terminal (as
// when a user runs the command by hand) instead of a pipe.
inline CommandResult runCommand(const std::vector<std::string>& argv, std::chrono::seconds timeout,
                                bool stderrTerminal = false) {
    CommandResult result;
    int outPipe[2], errPipe[2];
    if (::pipe2(outPipe, O_CLOEXEC) != 0) return result;
    int errRead = -1, errWrite = -1;
    if (stderrTerminal) {
        if (::openpty(&errRead, &errWrite, nullptr, nullptr, nullptr) != 0) return result;
    } else {
        if (::pipe2(errPipe, O_CLOEXEC) != 0) return result;
        errRead = errPipe[0];
        errWrite = errPipe[1];
    }
    const pid_t pid = ::fork();
    if (pid == 0) {
        const int devNull = ::open("/dev/null", O_RDONLY);
        ::dup2(devNull, STDIN_FILENO);
        ::dup2(outPipe[1], STDOUT_FILENO);
        ::dup2(errWrite, STDERR_FILENO);
        std::vector<char*> args;
        for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
        args.push_back(nullptr);
        ::execv(args[0], args.data());
        ::_exit(127);
    }
    ::close(outPipe[1]);
    ::close(errWrite);
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    pollfd fds[2] = {{outPipe[0], POLLIN, 0}, {errRead, POLLIN, 0}};
    std::string* sinks[2] = {&result.out, &result.err};
    int open = 2;
    bool timedOut = false;
    while (open > 0) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
            deadline - std::chrono::steady_clock::now());
        if (left.count() <= 0) {
            timedOut = true;
            break;
        }
        if (::poll(fds, 2, int(std::min<int64_t>(left.count(), 1000))) < 0) break;
        for (int i = 0; i < 2; ++i) {
            if (fds[i].fd < 0 || !(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
            char buf[4096];
            const ssize_t n = ::read(fds[i].fd, buf, sizeof buf);
            if (n > 0) {
                sinks[i]->append(buf, size_t(n));
            } else {  // EOF (a pipe) or EIO (a pseudo-terminal whose other end closed)
                ::close(fds[i].fd);
                fds[i].fd = -1;
                --open;
            }
        }
    }
    for (const pollfd& f : fds)
        if (f.fd >= 0) ::close(f.fd);
    if (timedOut) ::kill(pid, SIGKILL);
    int st = 0;
    ::waitpid(pid, &st, 0);
    if (!timedOut) result.exitCode = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    return result;
}

}  // namespace previs::testing
