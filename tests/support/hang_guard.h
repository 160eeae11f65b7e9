#pragma once

// A hang guard for tests of code that could block forever (a join, a FIFO): past the deadline
// the test binary ends with a message, since a stuck call cannot be cancelled, so a regression
// fails instead of stalling CI. Deadlines are far beyond any loaded machine's time.

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <thread>

namespace previs::testing {

class HangGuard {
public:
    HangGuard(const char* what, std::chrono::seconds deadline)
        : thread_([this, what, deadline] {
              std::unique_lock lock(mutex_);
              if (!done_.wait_for(lock, deadline, [this] { return finished_; })) {
                  std::fprintf(stderr, "FAIL: %s did not finish within %lld s (a hang)\n", what,
                               static_cast<long long>(deadline.count()));
                  std::_Exit(1);
              }
          }) {}
    ~HangGuard() {
        {
            std::lock_guard lock(mutex_);
            finished_ = true;
        }
        done_.notify_all();
        thread_.join();
    }

private:
    std::mutex mutex_;
    std::condition_variable done_;
    bool finished_ = false;
    std::thread thread_;
};

}  // namespace previs::testing
