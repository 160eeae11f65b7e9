#pragma once

// main() of the tests that run inside ../shared/vmtest (scripts/vmtest.sh sets VMTEST): on the
// host they report skipped with CTest's SKIP_RETURN_CODE (tests/CMakeLists.txt), not failed.

#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>

namespace previs::testing {

inline constexpr int kSkipReturnCode = 77;

// `name` is the executable's, for the skip line.
inline int runVmTests(int argc, char** argv, const char* name) {
    if (!std::getenv("VMTEST")) {
        std::printf("%s: not inside vmtest (VMTEST unset): skipped\n", name);
        return kSkipReturnCode;
    }
    ::testing::InitGoogleTest(&argc, argv);
    return RUN_ALL_TESTS();
}

}  // namespace previs::testing
