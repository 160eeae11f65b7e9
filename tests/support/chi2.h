#pragma once

// Chi-square goodness-of-fit of a direction sampler against its stated density, as pbrt-v4's
// sampling tests and Mitsuba's chi2.py do it: directions binned in (cosθ, φ) cells of equal
// area, expected counts from integrating the pdf over each cell, cells with expected < 5 merged.

#include <functional>
#include <glm/glm.hpp>
#include <optional>
#include <string>

namespace previs::testing {

struct Chi2Result {
    double statistic = 0.0;
    int degreesOfFreedom = 0;
    double pValue = 1.0;
    double expectedTotal = 0.0;  // N × (pdf mass over the sphere): ≈ accepted samples
    double observedTotal = 0.0;
    std::string describe() const;
};

// Regularised upper incomplete gamma Q(a, x) (Numerical Recipes §6.2).
double incompleteGammaQ(double a, double x);

// `sample(u)` returns a direction or nullopt (no sample); `pdf(d)` its solid-angle density.
Chi2Result chi2DirectionTest(const std::function<std::optional<glm::vec3>(glm::vec2)>& sample,
                             const std::function<double(glm::vec3)>& pdf, int thetaBins,
                             int phiBins, int sampleCount, uint32_t seed);

// Šidák-corrected significance for `tests` tests at overall level `alpha`.
double sidakLevel(double alpha, int tests);

}  // namespace previs::testing
