#include "scene/environment_sampler.h"

namespace previs {
namespace {

// The shared header reads its tables through macros; on the CPU they read through this
// thread-local pointer, set for the duration of each call (so concurrent samplers on different
// threads do not interfere).
struct EnvTables {
    const glm::vec3* radiance;
    const float* marginal;
    const float* conditional;
};
thread_local const EnvTables* currentTables = nullptr;

}  // namespace
}  // namespace previs

#define PV_ENV_RADIANCE(i) (::previs::currentTables->radiance[(i)])
#define PV_ENV_MARGINAL_CDF(i) (::previs::currentTables->marginal[(i)])
#define PV_ENV_CONDITIONAL_CDF(i) (::previs::currentTables->conditional[(i)])
#include "gpu/shaders/shared/env_sampling.h"

namespace previs {
namespace {

class TablesScope {
public:
    TablesScope(const EnvironmentMap& map, const EnvironmentDistribution& dist)
        : tables_{map.radiance.data(), dist.marginalCdf.data(), dist.conditionalCdf.data()},
          previous_(currentTables) {
        currentTables = &tables_;
    }
    ~TablesScope() { currentTables = previous_; }
    TablesScope(const TablesScope&) = delete;
    TablesScope& operator=(const TablesScope&) = delete;

private:
    EnvTables tables_;
    const EnvTables* previous_;
};

}  // namespace

EnvironmentSampler::EnvironmentSampler(EnvironmentMap map)
    : map_(std::move(map)), distribution_(buildEnvironmentDistribution(map_)) {}

EnvironmentSampler::Sample EnvironmentSampler::sample(glm::vec2 u) const {
    if (map_.width == 0) return {glm::vec3(0.0f, 1.0f, 0.0f), 0.0f};
    TablesScope scope(map_, distribution_);
    Sample s;
    s.direction = shader::envSample(u, map_.width, map_.height,
                                    shader::envRotationCosSin(map_.rotationRad), s.pdfSolidAngle);
    return s;
}

float EnvironmentSampler::pdf(const glm::vec3& dirWorld) const {
    if (map_.width == 0) return 0.0f;
    TablesScope scope(map_, distribution_);
    return shader::envPdf(dirWorld, map_.width, map_.height,
                          shader::envRotationCosSin(map_.rotationRad));
}

glm::vec3 EnvironmentSampler::radiance(const glm::vec3& dirWorld) const {
    if (map_.width == 0) return glm::vec3(0.0f);
    TablesScope scope(map_, distribution_);
    return shader::envRadiance(dirWorld, map_.width, map_.height,
                               shader::envRotationCosSin(map_.rotationRad));
}

glm::vec2 EnvironmentSampler::directionToUv(const glm::vec3& d) {
    return shader::envDirectionToUv(d);
}

glm::vec3 EnvironmentSampler::uvToDirection(const glm::vec2& uv) {
    return shader::envUvToDirection(uv);
}

}  // namespace previs
