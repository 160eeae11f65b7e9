#pragma once

// The fixture of the web cases that each start one monitor in front of a fake service.

#include <gtest/gtest.h>

#include <memory>
#include <utility>

#include "tests/web/web_test_support.h"
#include "web/web_monitor.h"

namespace previs::test {

class MonitorTest : public ::testing::Test {
protected:
    // The case's monitor on a free port, or null when it did not start.
    WebMonitor* start(WebMonitorSettings settings = testSettings()) {
        monitor = startMonitor(service, std::move(settings));
        return monitor.get();
    }

    FakeService service;
    std::unique_ptr<WebMonitor> monitor;
};

}  // namespace previs::test
