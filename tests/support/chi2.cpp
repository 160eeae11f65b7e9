#include "tests/support/chi2.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace previs::testing {

std::string Chi2Result::describe() const {
    return fmt::format("chi2 {:.1f}, dof {}, p {:.4g}, samples observed {:.0f} / expected {:.0f}",
                       statistic, degreesOfFreedom, pValue, observedTotal, expectedTotal);
}

double incompleteGammaQ(double a, double x) {
    if (x <= 0.0) return 1.0;
    double gln = std::lgamma(a);
    if (x < a + 1.0) {
        double ap = a, sum = 1.0 / a, del = sum;
        for (int n = 0; n < 1000; ++n) {
            ap += 1.0;
            del *= x / ap;
            sum += del;
            if (std::abs(del) < std::abs(sum) * 1e-15) break;
        }
        return 1.0 - sum * std::exp(-x + a * std::log(x) - gln);
    }
    double b = x + 1.0 - a, c = 1.0 / 1e-300, d = 1.0 / b, h = d;
    for (int i = 1; i < 1000; ++i) {
        double an = -i * (i - a);
        b += 2.0;
        d = an * d + b;
        if (std::abs(d) < 1e-300) d = 1e-300;
        c = b + an / c;
        if (std::abs(c) < 1e-300) c = 1e-300;
        d = 1.0 / d;
        double del = d * c;
        h *= del;
        if (std::abs(del - 1.0) < 1e-15) break;
    }
    return std::exp(-x + a * std::log(x) - gln) * h;
}

double sidakLevel(double alpha, int tests) { return 1.0 - std::pow(1.0 - alpha, 1.0 / tests); }

Chi2Result chi2DirectionTest(const std::function<std::optional<glm::vec3>(glm::vec2)>& sample,
                             const std::function<double(glm::vec3)>& pdf, int thetaBins,
                             int phiBins, int sampleCount, uint32_t seed) {
    const double pi = 3.14159265358979323846;
    auto cellOf = [&](glm::vec3 d) {
        double z = std::clamp(double(d.z), -1.0, 1.0);
        int t = std::min(int((1.0 - z) * 0.5 * thetaBins), thetaBins - 1);
        double phi = std::atan2(double(d.y), double(d.x));
        if (phi < 0) phi += 2 * pi;
        int p = std::min(int(phi / (2 * pi) * phiBins), phiBins - 1);
        return t * phiBins + p;
    };
    std::vector<double> observed(size_t(thetaBins) * phiBins, 0.0);
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> uni(0.0f, std::nextafter(1.0f, 0.0f));
    for (int i = 0; i < sampleCount; ++i) {
        auto d = sample(glm::vec2(uni(rng), uni(rng)));
        if (d && std::isfinite(d->x) && std::isfinite(d->y) && std::isfinite(d->z))
            observed[cellOf(glm::normalize(*d))] += 1.0;
    }
    // Expected counts: midpoint rule on a fine grid inside each cell (cells have equal solid
    // angle 4π/(thetaBins·phiBins) since they are uniform in cosθ and φ).
    const int sub = 48;
    std::vector<double> expected(observed.size(), 0.0);
    double cellArea = 4.0 * pi / (double(thetaBins) * phiBins);
    for (int t = 0; t < thetaBins; ++t) {
        for (int p = 0; p < phiBins; ++p) {
            double sum = 0.0;
            for (int i = 0; i < sub; ++i) {
                for (int j = 0; j < sub; ++j) {
                    double z = 1.0 - 2.0 * (t + (i + 0.5) / sub) / thetaBins;
                    double phi = 2 * pi * (p + (j + 0.5) / sub) / phiBins;
                    double r = std::sqrt(std::max(0.0, 1.0 - z * z));
                    sum += pdf(glm::vec3(r * std::cos(phi), r * std::sin(phi), z));
                }
            }
            expected[size_t(t) * phiBins + p] = sum / (sub * sub) * cellArea * sampleCount;
        }
    }
    // Merge cells with small expectations, in order of expectation (pbrt-v4's chi2test).
    std::vector<size_t> order(observed.size());
    for (size_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(),
              [&](size_t a, size_t b) { return expected[a] < expected[b]; });
    Chi2Result r;
    double pooledObs = 0.0, pooledExp = 0.0;
    int cells = 0;
    for (size_t k : order) {
        r.expectedTotal += expected[k];
        r.observedTotal += observed[k];
        if (expected[k] == 0.0) {
            // Samples where the pdf says none can be: a plain failure.
            if (observed[k] > sampleCount * 1e-5) {
                r.statistic = INFINITY;
                r.pValue = 0.0;
                return r;
            }
            continue;
        }
        if (expected[k] < 5.0) {
            pooledObs += observed[k];
            pooledExp += expected[k];
            continue;
        }
        r.statistic += (observed[k] - expected[k]) * (observed[k] - expected[k]) / expected[k];
        ++cells;
    }
    if (pooledExp > 0.0) {
        r.statistic += (pooledObs - pooledExp) * (pooledObs - pooledExp) / pooledExp;
        ++cells;
    }
    r.degreesOfFreedom = cells - 1;
    r.pValue = r.degreesOfFreedom > 0
                   ? incompleteGammaQ(0.5 * r.degreesOfFreedom, 0.5 * r.statistic)
                   : 1.0;
    return r;
}

}  // namespace previs::testing
