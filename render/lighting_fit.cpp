#include "render/lighting_fit.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <opencv2/imgproc.hpp>

#include "base/luminance.h"
#include "vision/equirect.h"

namespace previs {

namespace {

// DESIGN.md §4's equirectangular parameterisation, from its one owner (vision/equirect.h).
glm::dvec3 texelDirection(int x, int y, int width, int height) {
    const cv::Vec3d d = equirectTexelDirection(x, y, width, height);
    return {d[0], d[1], d[2]};
}

double texelSolidAngle(int y, int width, int height) {
    return equirectTexelSolidAngle(y, width, height);
}

// A direction's light as seen from a surface: RGB radiance × solid angle.
struct DirectionalLight {
    glm::vec3 direction;
    glm::vec3 power;
};

float lum(const glm::vec3& v) { return luminance(v.r, v.g, v.b); }

// Offsets a shadow ray's origin off the surface (metres), as the shaders' ray epsilon does.
constexpr float kShadowRayOffsetM = 1e-3f;

glm::dvec3 irradiance(const CpuTracer& tracer, const PlateSample& s,
                      const std::vector<DirectionalLight>& lights) {
    glm::dvec3 e(0.0);
    for (const DirectionalLight& l : lights) {
        const float cosine = glm::dot(s.normal, l.direction);
        if (cosine <= 0.0f) continue;
        shader::Ray ray;
        ray.origin = s.position + kShadowRayOffsetM * s.normal;
        ray.direction = l.direction;
        ray.tMin = 0.0f;
        ray.tMax = 1e30f;
        if (!tracer.occluded(ray, /*realOnly=*/true)) e += glm::dvec3(l.power) * double(cosine);
    }
    return e;
}

// The map's light outside the clusters, averaged onto a coarse grid of directions.
std::vector<DirectionalLight> coarseLights(const cv::Mat& map, const cv::Mat& inCluster,
                                           int coarseWidth) {
    const int w = map.cols, h = map.rows;
    const int cw = std::clamp(coarseWidth, 4, w), ch = std::max(2, cw / 2);
    std::vector<glm::dvec3> power(size_t(cw) * ch, glm::dvec3(0.0));
    for (int y = 0; y < h; ++y) {
        const double omega = texelSolidAngle(y, w, h);
        for (int x = 0; x < w; ++x) {
            if (inCluster.at<uint8_t>(y, x)) continue;
            const cv::Vec3f v = map.at<cv::Vec3f>(y, x);
            power[size_t(y * ch / h) * cw + size_t(x * cw / w)] +=
                glm::dvec3(v[0], v[1], v[2]) * omega;
        }
    }
    std::vector<DirectionalLight> out;
    for (int y = 0; y < ch; ++y)
        for (int x = 0; x < cw; ++x)
            if (const glm::dvec3 p = power[size_t(y) * cw + x]; p.r + p.g + p.b > 0.0)
                out.push_back({glm::vec3(texelDirection(x, y, cw, ch)), glm::vec3(p)});
    return out;
}

// At most `maxTexels` of a cluster's texels, the brightest, carrying the whole cluster's power
// in proportion (so the irradiance fraction is right even when texels are dropped).
std::vector<DirectionalLight> clusterLights(const cv::Mat& map, const std::vector<int>& texels,
                                            int maxTexels) {
    const int w = map.cols, h = map.rows;
    std::vector<DirectionalLight> all;
    glm::dvec3 total(0.0);
    for (int t : texels) {
        const int x = t % w, y = t / w;
        const cv::Vec3f v = map.at<cv::Vec3f>(y, x);
        const glm::vec3 p = glm::vec3(v[0], v[1], v[2]) * float(texelSolidAngle(y, w, h));
        all.push_back({glm::vec3(texelDirection(x, y, w, h)), p});
        total += glm::dvec3(p);
    }
    std::sort(all.begin(), all.end(), [](const DirectionalLight& a, const DirectionalLight& b) {
        return lum(a.power) > lum(b.power);
    });
    if (int(all.size()) > maxTexels) all.resize(size_t(maxTexels));
    glm::dvec3 kept(0.0);
    for (const DirectionalLight& l : all) kept += glm::dvec3(l.power);
    for (DirectionalLight& l : all)
        for (int c = 0; c < 3; ++c)
            if (kept[c] > 0.0) l.power[c] = float(l.power[c] * total[c] / kept[c]);
    return all;
}

struct Sample {
    std::array<double, 3> logRatio;               // log(L_or / plate) per channel
    std::vector<std::array<double, 3>> fraction;  // f_k per channel: a lamp has its own colour
};

// log(1 + Σ h_k f_kc) for channel c, and its gradient.
double clusterTerm(const std::vector<double>& h, const Sample& s, int c,
                   std::vector<double>* gradient) {
    double sum = 1.0;
    for (size_t k = 0; k < h.size(); ++k) sum += h[k] * s.fraction[k][size_t(c)];
    if (gradient)
        for (size_t k = 0; k < h.size(); ++k) (*gradient)[k] = s.fraction[k][size_t(c)] / sum;
    return std::log(sum);
}

double huberWeight(double r, double delta) {
    return std::abs(r) <= delta ? 1.0 : delta / std::abs(r);
}

// The median over samples and channels of |log(L_or' / plate)|: the fit's residual, untouched
// by the few samples the model cannot hold (highlights, edges).
double medianAbsResidual(const std::vector<Sample>& samples, const std::array<double, 3>& logGain,
                         const std::vector<double>& h) {
    std::vector<double> r;
    r.reserve(samples.size() * 3);
    for (const Sample& s : samples)
        for (int ch = 0; ch < 3; ++ch)
            r.push_back(std::abs(logGain[size_t(ch)] + clusterTerm(h, s, ch, nullptr) +
                                 s.logRatio[size_t(ch)]));
    auto mid = r.begin() + r.size() / 2;
    std::nth_element(r.begin(), mid, r.end());
    return *mid;
}

}  // namespace

std::vector<std::vector<int>> clippedClusters(const cv::Mat& clippedTexels) {
    if (clippedTexels.empty() || cv::countNonZero(clippedTexels) == 0) return {};
    cv::Mat labels;
    const int n = cv::connectedComponents(clippedTexels != 0, labels, 8, CV_32S);
    // Join components that meet across the u seam (column 0 beside column W−1).
    std::vector<int> parent(static_cast<size_t>(n));
    std::iota(parent.begin(), parent.end(), 0);
    auto root = [&](int a) {
        while (parent[size_t(a)] != a) a = parent[size_t(a)] = parent[size_t(parent[size_t(a)])];
        return a;
    };
    const int w = labels.cols;
    for (int y = 0; y < labels.rows; ++y)
        for (int dy = -1; dy <= 1; ++dy) {
            const int y2 = y + dy;
            if (y2 < 0 || y2 >= labels.rows) continue;
            const int a = labels.at<int>(y, 0), b = labels.at<int>(y2, w - 1);
            if (a > 0 && b > 0) parent[size_t(root(a))] = root(b);
        }
    std::vector<std::vector<int>> byRoot(static_cast<size_t>(n));
    for (int y = 0; y < labels.rows; ++y)
        for (int x = 0; x < w; ++x)
            if (const int l = labels.at<int>(y, x); l > 0)
                byRoot[size_t(root(l))].push_back(y * w + x);
    std::vector<std::vector<int>> out;
    for (auto& c : byRoot)
        if (!c.empty()) out.push_back(std::move(c));
    return out;
}

Result<LightingFit> fitLightingToPlate(const CpuTracer& tracer, const cv::Mat& map,
                                       const std::vector<std::vector<int>>& clusters,
                                       const std::vector<PlateSample>& plateSamples,
                                       const LightingFitSettings& settings) {
    if (map.type() != CV_32FC3 || map.cols != 2 * map.rows || map.empty())
        return makeError("lighting fit: the map must be a W×W/2 linear RGB equirectangular image");
    cv::Mat inCluster = cv::Mat::zeros(map.size(), CV_8U);
    for (const auto& c : clusters)
        for (int t : c) inCluster.data[t] = 1;
    const std::vector<DirectionalLight> rest =
        coarseLights(map, inCluster, settings.coarseMapWidth);
    std::vector<std::vector<DirectionalLight>> clusterDirs;
    for (const auto& c : clusters)
        clusterDirs.push_back(clusterLights(map, c, settings.maxTexelsPerCluster));

    // Usable samples: finite and positive in every channel of both images.
    std::vector<const PlateSample*> usable;
    for (const PlateSample& s : plateSamples) {
        bool ok = true;
        for (int c = 0; c < 3; ++c)
            ok = ok && std::isfinite(s.position[c]) && std::isfinite(s.normal[c]);
        for (int c = 0; c < 3; ++c)
            ok = ok && s.plate[c] > 0.0f && s.real[c] > 0.0f && std::isfinite(s.plate[c]) &&
                 std::isfinite(s.real[c]);
        if (ok) usable.push_back(&s);
    }
    if (usable.size() < settings.minSamples)
        return makeError(
            "lighting fit: {} usable plate samples, {} needed (is the pose trusted "
            "and a real surface in view?)",
            usable.size(), settings.minSamples);
    std::vector<Sample> samples(usable.size());
    cv::parallel_for_(cv::Range(0, int(usable.size())), [&](const cv::Range& range) {
        for (int i = range.start; i < range.end; ++i) {
            const PlateSample& p = *usable[size_t(i)];
            Sample& s = samples[size_t(i)];
            for (int c = 0; c < 3; ++c) s.logRatio[c] = std::log(double(p.real[c]) / p.plate[c]);
            std::vector<glm::dvec3> e;
            glm::dvec3 total = irradiance(tracer, p, rest);
            for (const auto& dirs : clusterDirs) {
                e.push_back(irradiance(tracer, p, dirs));
                total += e.back();
            }
            s.fraction.resize(e.size());
            for (size_t k = 0; k < e.size(); ++k)
                for (int c = 0; c < 3; ++c)
                    s.fraction[k][size_t(c)] = total[c] > 0.0 ? e[k][c] / total[c] : 0.0;
        }
    });

    // Gauss–Newton with IRLS weights on x = (log G_r, log G_g, log G_b, h_1 … h_K), h_k = g_k − 1
    // projected onto [0, maxClusterGain − 1].
    const size_t k = clusters.size();
    const int n = int(3 + k);
    std::array<double, 3> logGain{0, 0, 0};
    std::vector<double> h(k, 0.0);
    const double priorWeight = 1.0 / std::pow(settings.globalGainSigmaStops * std::log(2.0), 2.0);
    std::vector<double> grad(k);
    for (int iteration = 0; iteration < settings.iterations; ++iteration) {
        cv::Mat a = cv::Mat::zeros(n, n, CV_64F), b = cv::Mat::zeros(n, 1, CV_64F);
        for (const Sample& s : samples) {
            for (int ch = 0; ch < 3; ++ch) {
                const double r =
                    logGain[size_t(ch)] + clusterTerm(h, s, ch, &grad) + s.logRatio[size_t(ch)];
                const double w = huberWeight(r, settings.huberLog);
                // J row: ∂r/∂logG_ch = 1, ∂r/∂h_k = f_k / (1 + Σ h f).
                std::vector<std::pair<int, double>> j{{ch, 1.0}};
                for (size_t q = 0; q < k; ++q) j.emplace_back(int(3 + q), grad[q]);
                for (auto [ra, va] : j) {
                    b.at<double>(ra) -= w * va * r;
                    for (auto [rb, vb] : j) a.at<double>(ra, rb) += w * va * vb;
                }
            }
        }
        // The prior holds log G at 0 with the weight of kPriorSamples samples: it decides only
        // what the data cannot (a cluster lighting every sample alike trades off against G),
        // and shrinks a well-determined log G by about kPriorSamples·2/N.
        constexpr double kPriorSamples = 8.0;
        for (int ch = 0; ch < 3; ++ch) {
            a.at<double>(ch, ch) += kPriorSamples * priorWeight;
            b.at<double>(ch) -= kPriorSamples * priorWeight * logGain[size_t(ch)];
        }
        // A cluster no sample sees gets a tiny ridge so the system stays solvable (its gain
        // stays where it is).
        for (size_t q = 0; q < k; ++q) a.at<double>(int(3 + q), int(3 + q)) += 1e-9;
        cv::Mat step;
        if (!cv::solve(a, b, step, cv::DECOMP_CHOLESKY) && !cv::solve(a, b, step, cv::DECOMP_SVD))
            return makeError("lighting fit: the system is singular");
        double largest = 0.0;
        for (int ch = 0; ch < 3; ++ch) {
            logGain[size_t(ch)] += step.at<double>(ch);
            largest = std::max(largest, std::abs(step.at<double>(ch)));
        }
        for (size_t q = 0; q < k; ++q) {
            const double before = h[q];
            h[q] =
                std::clamp(h[q] + step.at<double>(int(3 + q)), 0.0, settings.maxClusterGain - 1.0);
            largest = std::max(largest, std::abs(h[q] - before) / (1.0 + before));
        }
        if (largest < 1e-6) break;
    }

    LightingFit fit;
    fit.samples = samples.size();
    fit.residualBefore = medianAbsResidual(samples, {0, 0, 0}, std::vector<double>(k, 0.0));
    fit.residualAfter = medianAbsResidual(samples, logGain, h);
    for (int ch = 0; ch < 3; ++ch) fit.globalGain[size_t(ch)] = std::exp(logGain[size_t(ch)]);
    for (double x : h) fit.clusterGains.push_back(1.0 + x);
    for (double g : fit.globalGain)
        if (!std::isfinite(g)) return makeError("lighting fit: no finite solution");
    if (!(fit.residualAfter <= fit.residualBefore))
        return makeError(
            "lighting fit: the fitted lighting explains the plate no better (log "
            "residual {:.3f} against {:.3f})",
            fit.residualAfter, fit.residualBefore);
    return fit;
}

glm::vec3 clusterDirection(const cv::Mat& map, const std::vector<int>& texels) {
    glm::dvec3 sum(0.0);
    for (int t : texels) {
        const int x = t % map.cols, y = t / map.cols;
        const cv::Vec3f v = map.at<cv::Vec3f>(y, x);
        sum += texelDirection(x, y, map.cols, map.rows) *
               (lum(glm::vec3(v[0], v[1], v[2])) * texelSolidAngle(y, map.cols, map.rows));
    }
    const double n = glm::length(sum);
    return n > 0.0 ? glm::vec3(sum / n) : glm::vec3(0.0f, 1.0f, 0.0f);
}

LightingCorrection correctionFromFit(const cv::Mat& map,
                                     const std::vector<std::vector<int>>& clusters,
                                     const LightingFit& fit) {
    LightingCorrection c;
    c.globalGain = fit.globalGain;
    for (size_t k = 0; k < clusters.size() && k < fit.clusterGains.size(); ++k)
        c.clusters.push_back({clusterDirection(map, clusters[k]), fit.clusterGains[k]});
    return c;
}

LightingCorrection composeCorrections(const LightingCorrection& earlier,
                                      const LightingCorrection& later) {
    const float cosMatch = float(std::cos(kCorrectionMatchDeg * M_PI / 180.0));
    LightingCorrection out;
    for (int c = 0; c < 3; ++c)
        out.globalGain[size_t(c)] = earlier.globalGain[size_t(c)] * later.globalGain[size_t(c)];
    std::vector<bool> carried(earlier.clusters.size(), false);
    for (const LightingCorrection::Cluster& l : later.clusters) {
        double gain = l.gain;
        for (size_t e = 0; e < earlier.clusters.size(); ++e)
            if (!carried[e] && glm::dot(earlier.clusters[e].direction, l.direction) >= cosMatch) {
                gain *= earlier.clusters[e].gain;
                carried[e] = true;
                break;
            }
        out.clusters.push_back({l.direction, gain});
    }
    for (size_t e = 0; e < earlier.clusters.size(); ++e)
        if (!carried[e]) out.clusters.push_back(earlier.clusters[e]);
    return out;
}

cv::Mat applyCorrection(const cv::Mat& map, const std::vector<std::vector<int>>& clusters,
                        const LightingCorrection& correction, size_t* unmatched) {
    cv::Mat out = map.clone();
    cv::Vec3f* texels = out.ptr<cv::Vec3f>(0);
    const float cosMatch = float(std::cos(kCorrectionMatchDeg * M_PI / 180.0));
    size_t missed = 0;
    for (const std::vector<int>& cluster : clusters) {
        const glm::vec3 d = clusterDirection(map, cluster);
        const LightingCorrection::Cluster* best = nullptr;
        for (const LightingCorrection::Cluster& c : correction.clusters)
            if (glm::dot(c.direction, d) >= cosMatch &&
                (!best || glm::dot(c.direction, d) > glm::dot(best->direction, d)))
                best = &c;
        if (!best) {
            ++missed;
            continue;
        }
        for (int t : cluster) texels[t] *= float(best->gain);
    }
    if (unmatched) *unmatched = missed;
    return out.mul(
        cv::Scalar(correction.globalGain[0], correction.globalGain[1], correction.globalGain[2]));
}

std::vector<std::optional<PlateSample>> realSurfacesAlongRays(
    const CpuTracer& tracer, const glm::vec3& origin, const std::vector<glm::vec3>& directions) {
    std::vector<std::optional<PlateSample>> out(directions.size());
    for (size_t i = 0; i < directions.size(); ++i) {
        const shader::Ray ray{origin, 0.0f, directions[i], 1e30f};
        const std::optional<shader::Hit> hit = tracer.closestHit(ray, /*realOnly=*/true);
        if (!hit) continue;
        const glm::uvec3 tri = tracer.triangles()[hit->triangle];
        const glm::vec3 a = tracer.positions()[tri.x], b = tracer.positions()[tri.y],
                        c = tracer.positions()[tri.z];
        glm::vec3 n = glm::cross(b - a, c - a);
        if (glm::length(n) <= 0.0f) continue;
        n = glm::normalize(n);
        if (glm::dot(n, directions[i]) > 0.0f) n = -n;  // facing the camera
        PlateSample s;
        s.position = origin + hit->t * directions[i];
        s.normal = n;
        out[i] = s;
    }
    return out;
}

}  // namespace previs
