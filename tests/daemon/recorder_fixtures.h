#pragma once

// What the take recorder's tests share (daemon_test.cpp, take_writers_test.cpp): a hang guard
// and a recorder config writing into the test's scratch folder.

#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <string>
#include <thread>

#include "daemon/service_config.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs::testing {

// A hang guard for tests of threads that could deadlock: past the deadline the test binary ends
// with a message (a stuck join cannot be cancelled), so a hang fails instead of stalling CI.
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

// The demo's config recording into a fresh scratch folder `name`, with no free-space floor.
inline ServiceConfig recorderConfig(const std::string& name) {
    Result<ServiceConfig> config = loadServiceConfig(sourcePath("examples/demo/previsd.toml"));
    EXPECT_TRUE(config) << config.message();
    ServiceConfig c = config ? *config : ServiceConfig{};
    const std::filesystem::path takes = scratchDir("previs_recorder_test") / name;
    std::filesystem::remove_all(takes);
    c.record.dir = takes.string();
    c.record.minFreeMb = 0;
    return c;
}

}  // namespace previs::testing
