#pragma once

// The refinement restart rule's thresholds the shot's tests are written against (shot/
// refine_watch.h): fixed here, so that a change of RefineConfig's defaults
// (docs/config-format.md) leaves the tests' cases where they were.

#include "config/service_config.h"

namespace previs::testing {

// A move of 1 cm or 0.5°, or a 5 % change of the lighting, seen three times in a row restarts.
inline RefineConfig restartRuleConfig() {
    RefineConfig c;
    c.poseThresholdM = 0.01;
    c.poseThresholdDeg = 0.5;
    c.lightingThreshold = 0.05;
    c.restartAfter = 3;
    return c;
}

}  // namespace previs::testing
