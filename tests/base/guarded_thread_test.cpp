// runGuarded: what escapes a worker thread is caught, named and handed to its owner.
#include "base/guarded_thread.h"

#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <thread>

namespace previs {
namespace {

TEST(GuardedThread, AnEscapedExceptionReachesTheOwnerInsteadOfTerminating) {
    std::string reason;
    std::thread t([&] {
        runGuarded(
            "worker", [] { throw std::runtime_error("disk on fire"); },
            [&](const std::string& why) { reason = why; });
    });
    t.join();
    EXPECT_EQ(reason, "disk on fire");

    bool called = false;
    std::thread quiet([&] {
        runGuarded(
            "worker", [] {}, [&](const std::string&) { called = true; });
    });
    quiet.join();
    EXPECT_FALSE(called);

    std::thread odd([&] {
        runGuarded(
            "worker", [] { throw 42; }, [&](const std::string& why) { reason = why; });
    });
    odd.join();
    EXPECT_EQ(reason, "unknown exception");
}

}  // namespace
}  // namespace previs
