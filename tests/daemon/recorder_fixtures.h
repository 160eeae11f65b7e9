#pragma once

// What the take recorder's tests share (daemon_test.cpp, take_writers_test.cpp): a recorder
// config writing into the test's scratch folder (and tests/support/hang_guard.h).

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "config/service_config.h"
#include "tests/support/hang_guard.h"
#include "tests/support/temp_dir.h"
#include "tests/support/test_data.h"

namespace previs::testing {

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
