#pragma once

// Light-source estimation on an equirectangular HDR map (DESIGN.md §3 `previs lights`): bright
// regions become lights with a direction, solid angle and radiance; the rest of the map is the
// residual. Energy-preserving: Σ radiance·solidAngle + residualPower = totalPower exactly (sums in
// double over the same texels), powers being ∫L dω per channel with exact texel solid angles.

#include <atomic>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <thread>
#include <vector>

#include "base/latest_value_slot.h"
#include "base/result.h"
#include "scene/scene.h"

namespace previs {

struct LightEstimatorSettings {
    // Threshold rule: a texel belongs to a light when its Rec.709 luminance exceeds
    //   max(meanFactor × L̄, maxFraction × Lmax),
    // L̄ the solid-angle-weighted mean luminance of the map and Lmax its largest texel. The first
    // term picks what stands out of the average (lamps, sun, windows); the second keeps a sun of
    // 10⁴·L̄ from dragging its whole glare halo and the bright sky into one huge "light".
    double meanFactor = 8.0;
    double maxFraction = 0.02;
    // Components are ranked by luminance power; at most maxLights are kept, and only those
    // carrying at least minPowerFraction of the map's luminance power. The others stay in the
    // residual (so the energy balance is unaffected).
    int maxLights = 16;
    double minPowerFraction = 0.002;

    bool operator==(const LightEstimatorSettings&) const = default;
};

struct EstimatedLight {
    cv::Vec3d direction;      // unit, world (DESIGN.md §4): radiance-weighted centroid
    double solidAngleSr = 0;  // Σ texel solid angles
    cv::Vec3d radiance;       // mean radiance over the component: radiance·solidAngle = power
    cv::Vec3d power;          // ∫L dω over the component, per channel
    int texels = 0;
};

struct LightingSnapshot {
    std::vector<EstimatedLight> lights;  // brightest (luminance power) first
    cv::Mat residual;                    // CV_32FC3: the map with the lights' texels set to 0
    cv::Vec3d residualPower;
    cv::Vec3d totalPower;
    double thresholdLuminance = 0.0;
    uint64_t sequence = 0;  // of the environment snapshot it was computed from
};

class LightEstimator {
public:
    explicit LightEstimator(const LightEstimatorSettings& settings = {}) : settings_(settings) {}

    // Linear RGB equirectangular map (CV_32FC3, width = 2 × height). NaN, Inf and negative
    // texels count as 0.
    Result<LightingSnapshot> estimate(const cv::Mat& radiance) const;

private:
    LightEstimatorSettings settings_;
};

// EnvironmentMap (scene/scene.h) → CV_32FC3 (a copy).
cv::Mat environmentMapToMat(const EnvironmentMap& map);
// And back: a CV_32FC3 equirectangular map (the fisheye's, a residual) as an EnvironmentMap
// (rotation 0, scale 1), named `name` in messages.
EnvironmentMap matToEnvironmentMap(const cv::Mat& radiance, std::string name);

// An environment as the fisheye thread publishes it.
struct EnvironmentSnapshot {
    cv::Mat radiance;  // CV_32FC3, never modified after publishing
    uint64_t sequence = 0;
    int64_t timestampNs = 0;
};

// The lighting thread (DESIGN.md §6): takes the newest environment snapshot, estimates the
// lights, publishes a LightingSnapshot. submit() never blocks on the estimation; a snapshot that
// arrives while the thread is busy replaces the waiting one (counted as dropped).
class LightingEstimator {
public:
    explicit LightingEstimator(const LightEstimatorSettings& settings = {});
    ~LightingEstimator();
    LightingEstimator(const LightingEstimator&) = delete;
    LightingEstimator& operator=(const LightingEstimator&) = delete;

    void submit(std::shared_ptr<const EnvironmentSnapshot> environment);
    // Newest result, null until the first one.
    std::shared_ptr<const LightingSnapshot> latest() const { return output_.latest(); }
    uint64_t processed() const { return processed_.load(); }
    uint64_t dropped() const { return dropped_.load(); }
    uint64_t failed() const { return failed_.load(); }

private:
    void run();

    LightEstimator estimator_;
    LatestValueSlot<EnvironmentSnapshot> input_;
    LatestValueSlot<LightingSnapshot> output_;
    std::atomic<uint64_t> processed_{0};
    std::atomic<uint64_t> dropped_{0};
    std::atomic<uint64_t> failed_{0};
    bool stop_ = false;  // guarded by input_.mutex()
    std::thread thread_;
};

}  // namespace previs
