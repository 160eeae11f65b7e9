#include "vision/light_estimator.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/imgproc.hpp>

#include "base/guarded_thread.h"
#include "base/log.h"
#include "base/luminance.h"
#include "vision/equirect.h"

namespace previs {

namespace {

struct UnionFind {
    std::vector<int> parent;
    explicit UnionFind(int n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
    int find(int a) {
        while (parent[a] != a) a = parent[a] = parent[parent[a]];
        return a;
    }
    void unite(int a, int b) {
        a = find(a);
        b = find(b);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
};

struct Component {
    double solidAngle = 0.0;
    cv::Vec3d power{0.0, 0.0, 0.0};
    double luminancePower = 0.0;
    cv::Vec3d weightedDirection{0.0, 0.0, 0.0};
    int texels = 0;
};

}  // namespace

cv::Mat environmentMapToMat(const EnvironmentMap& map) {
    cv::Mat out(int(map.height), int(map.width), CV_32FC3);
    for (uint32_t y = 0; y < map.height; ++y) {
        cv::Vec3f* row = out.ptr<cv::Vec3f>(int(y));
        for (uint32_t x = 0; x < map.width; ++x) {
            const glm::vec3& c = map.radiance[size_t(y) * map.width + x];
            row[x] = cv::Vec3f(c.r, c.g, c.b);
        }
    }
    return out;
}

EnvironmentMap matToEnvironmentMap(const cv::Mat& radiance, std::string name) {
    EnvironmentMap map;
    map.path = std::move(name);
    map.width = uint32_t(radiance.cols);
    map.height = uint32_t(radiance.rows);
    map.radiance.resize(size_t(map.width) * map.height);
    for (int y = 0; y < radiance.rows; ++y) {
        const cv::Vec3f* row = radiance.ptr<cv::Vec3f>(y);
        for (int x = 0; x < radiance.cols; ++x)
            map.radiance[size_t(y) * map.width + size_t(x)] =
                glm::vec3(row[x][0], row[x][1], row[x][2]);
    }
    return map;
}

Result<LightingSnapshot> LightEstimator::estimate(const cv::Mat& radiance) const {
    if (radiance.type() != CV_32FC3 || radiance.cols < 2 || radiance.rows < 1)
        return makeError("light estimation: expected a linear RGB float map (got {}x{}, type {})",
                         radiance.cols, radiance.rows, radiance.type());
    const int w = radiance.cols;
    const int h = radiance.rows;

    LightingSnapshot snap;
    snap.residual.create(h, w, CV_32FC3);
    cv::Mat luminance(h, w, CV_64F);
    std::vector<double> rowSolidAngle(h);
    double luminancePower = 0.0;
    double maxLuminance = 0.0;
    snap.totalPower = cv::Vec3d(0, 0, 0);
    for (int y = 0; y < h; ++y) {
        rowSolidAngle[y] = equirectTexelSolidAngle(y, w, h);
        const cv::Vec3f* in = radiance.ptr<cv::Vec3f>(y);
        cv::Vec3f* res = snap.residual.ptr<cv::Vec3f>(y);
        double* lum = luminance.ptr<double>(y);
        for (int x = 0; x < w; ++x) {
            cv::Vec3f c = in[x];
            for (int k = 0; k < 3; ++k)
                if (!(c[k] >= 0.0f) || !std::isfinite(c[k])) c[k] = 0.0f;
            res[x] = c;
            lum[x] = previs::luminance(double(c[0]), double(c[1]), double(c[2]));
            maxLuminance = std::max(maxLuminance, lum[x]);
            luminancePower += lum[x] * rowSolidAngle[y];
            for (int k = 0; k < 3; ++k) snap.totalPower[k] += double(c[k]) * rowSolidAngle[y];
        }
    }
    const double meanLuminance = luminancePower / (4.0 * M_PI);
    snap.thresholdLuminance =
        std::max(settings_.meanFactor * meanLuminance, settings_.maxFraction * maxLuminance);

    if (maxLuminance > 0.0) {
        cv::Mat mask = luminance > snap.thresholdLuminance;
        cv::Mat labels;
        const int count = cv::connectedComponents(mask, labels, 8, CV_32S);

        // The map wraps in u: a component touching column 0 and one touching column w−1 in the
        // same or a neighbouring row (8-connectivity) are one. Texels of the top row all meet
        // at the zenith, those of the bottom row at the nadir: their components are one too.
        UnionFind sets(count);
        for (int y = 0; y < h; ++y) {
            const int a = labels.at<int>(y, 0);
            if (a == 0) continue;
            for (int dy = -1; dy <= 1; ++dy) {
                const int yy = y + dy;
                if (yy < 0 || yy >= h) continue;
                const int b = labels.at<int>(yy, w - 1);
                if (b != 0) sets.unite(a, b);
            }
        }
        for (int y : {0, h - 1}) {
            int first = 0;
            for (int x = 0; x < w; ++x) {
                const int a = labels.at<int>(y, x);
                if (a == 0) continue;
                if (first == 0) first = a;
                sets.unite(first, a);
            }
        }

        std::vector<Component> components(count);
        for (int y = 0; y < h; ++y) {
            const int* lab = labels.ptr<int>(y);
            const cv::Vec3f* c = snap.residual.ptr<cv::Vec3f>(y);
            const double* lum = luminance.ptr<double>(y);
            for (int x = 0; x < w; ++x) {
                if (lab[x] == 0) continue;
                Component& comp = components[sets.find(lab[x])];
                const double omega = rowSolidAngle[y];
                comp.solidAngle += omega;
                for (int k = 0; k < 3; ++k) comp.power[k] += double(c[x][k]) * omega;
                comp.luminancePower += lum[x] * omega;
                comp.weightedDirection += lum[x] * omega * equirectTexelDirection(x, y, w, h);
                ++comp.texels;
            }
        }

        std::vector<int> order;
        for (int i = 1; i < count; ++i)
            if (components[i].texels > 0) order.push_back(i);
        std::sort(order.begin(), order.end(), [&](int a, int b) {
            return components[a].luminancePower > components[b].luminancePower;
        });
        std::vector<uint8_t> keep(count, 0);
        for (int i : order) {
            const Component& comp = components[i];
            if (int(snap.lights.size()) >= settings_.maxLights) break;
            if (comp.luminancePower < settings_.minPowerFraction * luminancePower) break;
            const double n = cv::norm(comp.weightedDirection);
            if (!(n > 0.0)) continue;
            EstimatedLight light;
            light.direction = comp.weightedDirection / n;
            light.solidAngleSr = comp.solidAngle;
            light.power = comp.power;
            light.radiance = comp.power / comp.solidAngle;
            light.texels = comp.texels;
            snap.lights.push_back(light);
            keep[i] = 1;
        }
        for (int y = 0; y < h; ++y) {
            const int* lab = labels.ptr<int>(y);
            cv::Vec3f* res = snap.residual.ptr<cv::Vec3f>(y);
            for (int x = 0; x < w; ++x)
                if (lab[x] != 0 && keep[sets.find(lab[x])]) res[x] = cv::Vec3f(0, 0, 0);
        }
    }

    snap.residualPower = cv::Vec3d(0, 0, 0);
    for (int y = 0; y < h; ++y) {
        const cv::Vec3f* res = snap.residual.ptr<cv::Vec3f>(y);
        cv::Vec3d rowSum(0, 0, 0);
        for (int x = 0; x < w; ++x)
            for (int k = 0; k < 3; ++k) rowSum[k] += res[x][k];
        snap.residualPower += rowSum * rowSolidAngle[y];
    }
    return snap;
}

LightingEstimator::LightingEstimator(const LightEstimatorSettings& settings)
    : estimator_(settings), thread_([this] {
          // run() returns only when stopping; after an exception (counted as a failed
          // estimate) the last good lighting stays and the loop goes on.
          for (bool failed = true; failed;) {
              failed = false;
              runGuarded(
                  "lighting estimation", [this] { run(); },
                  [&](const std::string&) {
                      failed = true;
                      ++failed_;
                  });
          }
      }) {}

LightingEstimator::~LightingEstimator() {
    {
        std::lock_guard lock(input_.mutex());
        stop_ = true;
    }
    input_.wakeAll();
    thread_.join();
}

void LightingEstimator::submit(std::shared_ptr<const EnvironmentSnapshot> environment) {
    if (input_.publish(std::move(environment))) ++dropped_;
}

void LightingEstimator::run() {
    for (;;) {
        std::shared_ptr<const EnvironmentSnapshot> env = input_.waitTake(stop_);
        if (!env) return;  // stopping
        Result<LightingSnapshot> result = estimator_.estimate(env->radiance);
        if (!result) {
            // Keep the last good lighting; say why once per failure.
            ++failed_;
            logWarning("lighting estimation: {}; keeping the previous lighting", result.message());
            continue;
        }
        result->sequence = env->sequence;
        // Count before publishing: a reader that sees this snapshot must also see it counted.
        ++processed_;
        output_.publish(std::make_shared<const LightingSnapshot>(std::move(result).value()));
    }
}

}  // namespace previs
