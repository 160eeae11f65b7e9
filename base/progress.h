#pragma once

// The progress of long work on stderr (DESIGN.md §3): on a terminal one line rewritten in place;
// otherwise (a log file, a pipe, journald) plain lines, at most one every few seconds, so logs
// stay readable; nothing with --quiet.

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <string>

namespace previs {

class ProgressLine {
public:
    // `prefix` names the command ("render"); `quiet` suppresses everything.
    ProgressLine(std::string prefix, bool quiet,
                 std::chrono::milliseconds plainInterval = std::chrono::seconds(5))
        : prefix_(std::move(prefix)),
          quiet_(quiet),
          terminal_(::isatty(STDERR_FILENO) == 1),
          plainInterval_(plainInterval) {}
    ProgressLine(const ProgressLine&) = delete;
    ProgressLine& operator=(const ProgressLine&) = delete;
    ~ProgressLine() { finish(); }

    bool terminal() const { return terminal_; }

    // The state now. On a terminal redrawn at most 10 times a second; otherwise printed when
    // plainInterval has passed since the last printed line.
    void update(const std::string& text) {
        if (quiet_) return;
        last_ = text;
        const auto now = std::chrono::steady_clock::now();
        const auto interval = terminal_ ? std::chrono::milliseconds(100) : plainInterval_;
        if (printed_ && now - printedAt_ < interval) return;
        print(text);
        printedAt_ = now;
    }

    // Ends the line (terminal) or prints the final state if it was not the last line printed.
    void finish() {
        if (quiet_ || finished_) return;
        finished_ = true;
        if (!last_.empty() && last_ != shown_) print(last_);
        if (terminal_ && printed_) std::fputc('\n', stderr);
    }

private:
    void print(const std::string& text) {
        if (terminal_)
            std::fprintf(stderr, "\r%s: %s\033[K", prefix_.c_str(), text.c_str());
        else
            std::fprintf(stderr, "%s: %s\n", prefix_.c_str(), text.c_str());
        std::fflush(stderr);
        shown_ = text;
        printed_ = true;
    }

    std::string prefix_;
    bool quiet_;
    bool terminal_;
    std::chrono::milliseconds plainInterval_;
    std::chrono::steady_clock::time_point printedAt_;
    std::string last_, shown_;
    bool printed_ = false;
    bool finished_ = false;
};

}  // namespace previs
