// The sd_notify wrapper against a real AF_UNIX datagram socket standing in for the service
// manager's notification socket (the protocol is just datagrams on a socket: sd_notify(3)).

#include "systemd/notify.h"

#include <gtest/gtest.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>

#include "base/unique_fd.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

class NotifyTest : public ::testing::Test {
protected:
    void SetUp() override {
        char tmpl[] = "/tmp/previs_notify_XXXXXX";
        ASSERT_NE(mkdtemp(tmpl), nullptr) << std::strerror(errno);
        dir_ = tmpl;
        path_ = dir_ / "notify.sock";

        socket_ = UniqueFD(::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0));
        ASSERT_TRUE(socket_.isValid()) << std::strerror(errno);
        sockaddr_un addr{};
        addr.sun_family = AF_UNIX;
        ASSERT_LT(path_.native().size(), sizeof(addr.sun_path));
        std::strcpy(addr.sun_path, path_.c_str());
        ASSERT_EQ(::bind(socket_.get(), reinterpret_cast<sockaddr*>(&addr), sizeof(addr)), 0)
            << std::strerror(errno);

        ::setenv("NOTIFY_SOCKET", path_.c_str(), 1);
        ::unsetenv("WATCHDOG_USEC");
        ::unsetenv("WATCHDOG_PID");
    }

    void TearDown() override {
        ::unsetenv("NOTIFY_SOCKET");
        ::unsetenv("WATCHDOG_USEC");
        ::unsetenv("WATCHDOG_PID");
        socket_.reset();
        std::error_code ec;
        fs::remove_all(dir_, ec);
    }

    // sd_notify() has sent the datagram when it returns, so it is already queued: no waiting.
    std::optional<std::string> receive() {
        char buffer[4096];
        ssize_t n = ::recv(socket_.get(), buffer, sizeof(buffer), MSG_DONTWAIT);
        if (n < 0) return std::nullopt;
        return std::string(buffer, static_cast<size_t>(n));
    }

    fs::path dir_;
    fs::path path_;
    UniqueFD socket_;
};

TEST_F(NotifyTest, SendsExactMessages) {
    EXPECT_TRUE(systemd::underSystemd());

    systemd::notifyReady();
    EXPECT_EQ(receive(), "READY=1");

    systemd::notifyStatus("rendering: 30 fps");
    EXPECT_EQ(receive(), "STATUS=rendering: 30 fps");

    systemd::notifyWatchdog();
    EXPECT_EQ(receive(), "WATCHDOG=1");

    systemd::notifyStopping();
    EXPECT_EQ(receive(), "STOPPING=1");

    EXPECT_EQ(receive(), std::nullopt) << "one datagram per call";
}

TEST_F(NotifyTest, StatusIsOneLine) {
    // A newline would start a new assignment in the protocol ("STATUS=a\nREADY=1" would
    // declare readiness).
    systemd::notifyStatus("camera lost\nREADY=1");
    EXPECT_EQ(receive(), "STATUS=camera lost READY=1");
}

TEST_F(NotifyTest, ReloadingCarriesMonotonicTimestamp) {
    timespec before{};
    clock_gettime(CLOCK_MONOTONIC, &before);
    systemd::notifyReloading();
    timespec after{};
    clock_gettime(CLOCK_MONOTONIC, &after);

    std::optional<std::string> message = receive();
    ASSERT_TRUE(message);
    const std::string prefix = "RELOADING=1\nMONOTONIC_USEC=";
    ASSERT_EQ(message->rfind(prefix, 0), 0u) << *message;
    unsigned long long usec = std::stoull(message->substr(prefix.size()));
    auto toUsec = [](const timespec& t) {
        return static_cast<unsigned long long>(t.tv_sec) * 1000000ull +
               static_cast<unsigned long long>(t.tv_nsec) / 1000ull;
    };
    EXPECT_GE(usec, toUsec(before));
    EXPECT_LE(usec, toUsec(after));
}

TEST_F(NotifyTest, NoManagerIsNotAnError) {
    ::unsetenv("NOTIFY_SOCKET");
    EXPECT_FALSE(systemd::underSystemd());
    systemd::notifyReady();
    systemd::notifyWatchdog();
    EXPECT_EQ(receive(), std::nullopt);
}

TEST_F(NotifyTest, ManagerGoneIsNotFatal) {
    // The socket path no longer exists (manager restarted): calls return, nothing throws.
    ::setenv("NOTIFY_SOCKET", (dir_ / "gone.sock").c_str(), 1);
    systemd::notifyReady();
    systemd::notifyStatus("still running");
    EXPECT_EQ(receive(), std::nullopt);
}

TEST_F(NotifyTest, WatchdogIntervalFromEnvironment) {
    EXPECT_EQ(systemd::watchdogInterval(), std::nullopt) << "no WATCHDOG_USEC";

    ::setenv("WATCHDOG_USEC", "30000000", 1);
    EXPECT_EQ(systemd::watchdogInterval(), std::chrono::microseconds(30000000));

    // For this process explicitly.
    ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
    EXPECT_EQ(systemd::watchdogInterval(), std::chrono::seconds(30));

    // Meant for another process (e.g. the parent that forked us): not ours to feed.
    ::setenv("WATCHDOG_PID", std::to_string(::getpid() + 1).c_str(), 1);
    EXPECT_EQ(systemd::watchdogInterval(), std::nullopt);

    ::setenv("WATCHDOG_PID", std::to_string(::getpid()).c_str(), 1);
    ::setenv("WATCHDOG_USEC", "not a number", 1);
    EXPECT_EQ(systemd::watchdogInterval(), std::nullopt);

    // Asking does not consume the variables: a second query gives the same answer.
    ::setenv("WATCHDOG_USEC", "5000000", 1);
    EXPECT_EQ(systemd::watchdogInterval(), std::chrono::seconds(5));
    EXPECT_EQ(systemd::watchdogInterval(), std::chrono::seconds(5));
}

}  // namespace
}  // namespace previs
