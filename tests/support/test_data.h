#pragma once

// Where the tests' inputs are, found at run time (base/data_paths.h; no machine path is compiled
// into a test): the checkout's own files (examples/, tests/*/data) and the shared data
// (../shared/data beside the checkout, or $PREVIS_DATA_DIR). CTest passes both folders in the
// environment (PREVIS_SOURCE_DIR, PREVIS_DATA_DIR); run by hand, a test finds them from its own
// location in the build tree. A test that needs the shared data skips, saying why, when they are
// absent (PREVIS_SKIP_WITHOUT_SHARED_DATA); CTest shows it as skipped, not passed.

#include <gtest/gtest.h>

#include <cstdlib>
#include <string>

#include "base/data_paths.h"

namespace previs::testing {

// The checkout's root with a trailing '/' ("" if it cannot be found).
inline const std::string& sourceDir() {
    static const std::string dir = [] {
        const char* env = std::getenv("PREVIS_SOURCE_DIR");
        if (env && *env) return std::string(env) + "/";
        const auto root = findUpward(executableDir(), "examples/demo/previsd.toml");
        return root ? root->parent_path().parent_path().parent_path().string() + "/"
                    : std::string();
    }();
    return dir;
}

// A file of the checkout: sourcePath("examples/demo/previsd.toml").
inline std::string sourcePath(const std::string& relative) { return sourceDir() + relative; }

// The shared data folder with a trailing '/', or "" when absent.
inline const std::string& sharedDataDir() {
    static const std::string dir = [] {
        const auto d = ::previs::sharedDataDir();
        return d ? d->string() + "/" : std::string();
    }();
    return dir;
}

}  // namespace previs::testing

// First statement of a test that reads the shared data.
#define PREVIS_SKIP_WITHOUT_SHARED_DATA()                                                     \
    if (::previs::testing::sharedDataDir().empty())                                           \
    GTEST_SKIP() << "the shared data were not found: set PREVIS_DATA_DIR or put shared/data " \
                    "beside the checkout"
