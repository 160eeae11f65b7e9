#pragma once

// CPU side of gpu/shaders/shared/env_sampling.h: owns a map and its tables and runs the shared
// sampling math on them (tests, CPU reference paths). Immutable after creation, so one instance
// may be shared between threads.

#include <glm/glm.hpp>
#include <memory>

#include "scene/environment_map.h"

namespace previs {

class EnvironmentSampler {
public:
    struct Sample {
        glm::vec3 direction;  // world, unit
        float pdfSolidAngle;  // 0: discard the sample (degenerate, at a pole)
    };

    explicit EnvironmentSampler(EnvironmentMap map);

    const EnvironmentMap& map() const { return map_; }
    const EnvironmentDistribution& distribution() const { return distribution_; }

    // u uniform in [0,1)^2. Uses map().rotationRad; scale is not applied (as on the GPU).
    Sample sample(glm::vec2 u) const;
    float pdf(const glm::vec3& dirWorld) const;
    glm::vec3 radiance(const glm::vec3& dirWorld) const;  // unscaled

    // The shared header's mapping, exposed for tests.
    static glm::vec2 directionToUv(const glm::vec3& d);
    static glm::vec3 uvToDirection(const glm::vec2& uv);

private:
    EnvironmentMap map_;
    EnvironmentDistribution distribution_;
};

}  // namespace previs
