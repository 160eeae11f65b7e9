#include "vision/tag_edges.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include "base/log.h"
#include "vision/camera_calibration.h"

namespace previs {

namespace {

constexpr double kMinBitPx = 2.5;        // below this a bit has no room for a profile
constexpr double kProfileBits = 0.8;     // the profile's half length, in bits
constexpr double kMaxProfilePx = 8.0;    // ... and in pixels (beyond it blur is not the issue)
constexpr double kProfileStepPx = 0.25;  // sampling along the profile
constexpr double kTailFraction = 0.6;    // |s| beyond this fraction of the half length: ink/paper
constexpr double kMinContrast = 0.25;    // (paper − ink) / paper, below it the edge is not clear
constexpr double kProfileSpacingPx = 1.0;  // along the edge
constexpr int kMaxProfiles = 64;
constexpr double kMaxCornerMovePx = 1.5;
// The second pass centres its profiles on the first pass's edges and narrows them to the
// measured blur: the shorter the window, the less noise its area integrates.
constexpr int kPasses = 2;
constexpr double kWindowSpreads = 3.0;  // the narrowed half length: 3 σ of the edge's blur …
constexpr double kWindowSlackPx = 1.0;  // … plus a pixel for the first pass's error
constexpr double kMinWindowPx = 2.0;

// The frame in linear light, sampled bilinearly with pixel centres at integers (OpenCV's
// convention): each code goes through the table first, so nothing converts the whole frame.
struct LinearFrame {
    const cv::Mat& gray8;
    const LinearFromCode& table;
};

// nullopt outside the frame.
std::optional<float> sample(const LinearFrame& img, cv::Point2d p) {
    const double fx = std::floor(p.x), fy = std::floor(p.y);
    const int x = int(fx), y = int(fy);
    if (!(fx >= 0.0) || !(fy >= 0.0) || x + 1 >= img.gray8.cols || y + 1 >= img.gray8.rows)
        return std::nullopt;
    const float ax = float(p.x - fx), ay = float(p.y - fy);
    const uint8_t* r0 = img.gray8.ptr<uint8_t>(y) + x;
    const uint8_t* r1 = img.gray8.ptr<uint8_t>(y + 1) + x;
    const LinearFromCode& t = img.table;
    return (1 - ay) * ((1 - ax) * t[r0[0]] + ax * t[r0[1]]) +
           ay * ((1 - ax) * t[r1[0]] + ax * t[r1[1]]);
}

// A profile across an edge: linear values every kProfileStepPx on [−half, half] along the
// outward normal, and the means of its ink and paper tails.
struct Profile {
    cv::Point2d at;
    double half = 0.0;
    std::vector<float> values;
    double ink = 0.0, paper = 0.0;
};

std::optional<Profile> sampleProfile(const LinearFrame& linear, cv::Point2d q, cv::Point2d n,
                                     double r) {
    const int count = int(std::floor(2.0 * r / kProfileStepPx));
    if (count < 8) return std::nullopt;
    Profile p{q, 0.5 * count * kProfileStepPx, std::vector<float>(size_t(count)), 0.0, 0.0};
    int inkCount = 0, paperCount = 0;
    for (int j = 0; j < count; ++j) {
        const double s = -p.half + (j + 0.5) * kProfileStepPx;
        std::optional<float> v = sample(linear, q + s * n);
        if (!v) return std::nullopt;
        p.values[size_t(j)] = *v;
        if (s < -kTailFraction * p.half) p.ink += *v, ++inkCount;
        if (s > kTailFraction * p.half) p.paper += *v, ++paperCount;
    }
    p.ink /= inkCount;
    p.paper /= paperCount;
    return p;
}

// Where the edge crosses the profile, as an offset along its normal: a step at e has area
// (half − e) of its normalised profile on [−half, half], and so does the step blurred by any
// symmetric kernel narrower than the window. The ink and paper levels are the edge's (medians
// over its profiles): one profile's tails are too few pixels to set them against noise.
std::optional<double> edgeOffset(const Profile& p, double ink, double paper) {
    double area = 0.0;
    for (float v : p.values) area += (v - ink) / (paper - ink) * kProfileStepPx;
    const double e = p.half - area;
    if (!(std::abs(e) < 0.75 * p.half)) return std::nullopt;  // the transition is not inside
    return e;
}

// The edge's blur: the standard deviation of the profile's slope about the edge (noise on the
// flat tails widens it, so a window made from it errs on the wide side).
double edgeSpread(const Profile& p, double ink, double paper, double e) {
    double sum = 0.0, moment = 0.0;
    for (size_t j = 0; j + 1 < p.values.size(); ++j) {
        const double slope = std::max(0.0, (p.values[j + 1] - p.values[j]) / (paper - ink));
        const double s = -p.half + (double(j) + 1.0) * kProfileStepPx - e;
        sum += slope;
        moment += slope * s * s;
    }
    return sum > 0.0 ? std::sqrt(moment / sum) : p.half;
}

double median(std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
}

struct Line {
    cv::Point2d point, direction;  // direction of unit length
};

// Total least squares through the points, one refit without those farther than 3× the median
// distance (a profile that crossed a smudge or the neighbouring tag).
std::optional<Line> fitLine(std::vector<cv::Point2d> points) {
    auto fit = [](const std::vector<cv::Point2d>& p) {
        cv::Point2d mean(0, 0);
        for (const cv::Point2d& q : p) mean += q;
        mean *= 1.0 / double(p.size());
        double sxx = 0, sxy = 0, syy = 0;
        for (const cv::Point2d& q : p) {
            const cv::Point2d d = q - mean;
            sxx += d.x * d.x, sxy += d.x * d.y, syy += d.y * d.y;
        }
        const double angle = 0.5 * std::atan2(2.0 * sxy, sxx - syy);
        return Line{mean, {std::cos(angle), std::sin(angle)}};
    };
    if (points.size() < 3) return std::nullopt;
    Line line = fit(points);
    std::vector<double> dist;
    for (const cv::Point2d& q : points) {
        const cv::Point2d d = q - line.point;
        dist.push_back(std::abs(d.x * line.direction.y - d.y * line.direction.x));
    }
    std::vector<double> sorted = dist;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    const double limit = std::max(0.1, 3.0 * sorted[sorted.size() / 2]);
    std::vector<cv::Point2d> inliers;
    for (size_t i = 0; i < points.size(); ++i)
        if (dist[i] <= limit) inliers.push_back(points[i]);
    if (inliers.size() < 3) return std::nullopt;
    return fit(inliers);
}

std::optional<cv::Point2d> intersect(const Line& a, const Line& b) {
    const double det = a.direction.x * b.direction.y - a.direction.y * b.direction.x;
    if (std::abs(det) < 1e-6) return std::nullopt;
    const cv::Point2d d = b.point - a.point;
    const double t = (d.x * b.direction.y - d.y * b.direction.x) / det;
    return a.point + t * a.direction;
}

// One pass over the four edges of a quad (OpenCV pixels); nullopt when any edge fails.
// A distorting lens bends a tag's edges; lines are fitted where they are straight, in the ideal
// pinhole pixels of the same camera matrix, and the corners mapped back.
std::vector<cv::Point2d> toIdeal(const CameraCalibration* lens, std::vector<cv::Point2d> points) {
    if (!lens || !lens->hasDistortion()) return points;
    std::vector<cv::Point2d> ideal;
    for (const cv::Point2d& p : lens->undistortPixels(points))
        if (std::isfinite(p.x) && std::isfinite(p.y)) ideal.push_back(p);
    return ideal;
}

std::array<cv::Point2d, 4> fromIdeal(const CameraCalibration* lens,
                                     const std::array<cv::Point2d, 4>& ideal) {
    if (!lens || !lens->hasDistortion()) return ideal;
    std::vector<cv::Point3d> rays;
    for (const cv::Point2d& p : ideal)
        rays.emplace_back((p.x - lens->cx()) / lens->fx(), (p.y - lens->cy()) / lens->fy(), 1.0);
    std::vector<cv::Point2d> pixels = lens->projectPoints(rays);
    return {pixels[0], pixels[1], pixels[2], pixels[3]};
}

// One pass over the four edges of a quad (OpenCV pixels); nullopt when any edge fails. Each
// edge's profiles reach `window` pixels each side (0: as far as the border allows); `spread`
// receives each edge's blur.
std::optional<std::array<cv::Point2d, 4>> refineQuad(const std::array<cv::Point2d, 4>& c,
                                                     const LinearFrame& linear,
                                                     const TagBorder& border,
                                                     const CameraCalibration* lens,
                                                     const std::array<double, 4>& window,
                                                     std::array<double, 4>& spread) {
    const cv::Point2d centre = 0.25 * (c[0] + c[1] + c[2] + c[3]);
    std::array<Line, 4> lines;
    for (int i = 0; i < 4; ++i) {
        const cv::Point2d a = c[i], b = c[(i + 1) % 4];
        const double length = cv::norm(b - a);
        const cv::Point2d u = (b - a) * (1.0 / length);
        cv::Point2d n(u.y, -u.x);
        if (n.dot(0.5 * (a + b) - centre) < 0) n = -n;
        // Profiles run from ink to paper: inward across a reversed border.
        if (border.reversed) n = -n;
        // The border's width along the profile: the tag's extent across this edge, in bits (in
        // perspective the extent along the edge says nothing about it).
        double lo = 0.0, hi = 0.0;
        for (const cv::Point2d& p : c) {
            lo = std::min(lo, n.dot(p - a));
            hi = std::max(hi, n.dot(p - a));
        }
        const double bitPx = (hi - lo) / border.bits;
        if (bitPx < kMinBitPx || length / border.bits < kMinBitPx) return std::nullopt;
        double r = std::min(kProfileBits * bitPx, kMaxProfilePx);
        if (window[i] > 0.0) r = std::min(r, window[i]);
        // Stay a profile's length clear of the corners, where the other edge's blur enters.
        const double margin = std::min(0.3, (r + 1.0) / length);
        const int samples = std::clamp(int(length / kProfileSpacingPx), 4, kMaxProfiles);
        std::vector<Profile> profiles;
        std::vector<double> inks, papers;
        for (int k = 0; k < samples; ++k) {
            const double t = margin + (1.0 - 2.0 * margin) * (k + 0.5) / samples;
            if (std::optional<Profile> p = sampleProfile(linear, a + t * length * u, n, r)) {
                inks.push_back(p->ink);
                papers.push_back(p->paper);
                profiles.push_back(std::move(*p));
            }
        }
        if (profiles.size() < 3) return std::nullopt;
        const double ink = median(inks), paper = median(papers);
        if (!(paper - ink > kMinContrast * paper)) return std::nullopt;
        std::vector<cv::Point2d> points;
        for (const Profile& p : profiles)
            if (std::optional<double> e = edgeOffset(p, ink, paper))
                points.push_back(p.at + *e * n);
        // The blur from the edge's mean profile: one profile's noise would widen it.
        Profile mean = profiles[0];
        for (size_t j = 0; j < mean.values.size(); ++j) {
            double sum = 0.0;
            for (const Profile& p : profiles) sum += p.values[j];
            mean.values[j] = float(sum / double(profiles.size()));
        }
        std::optional<double> meanEdge = edgeOffset(mean, ink, paper);
        if (!meanEdge) return std::nullopt;
        spread[i] = edgeSpread(mean, ink, paper, *meanEdge);
        std::optional<Line> line = fitLine(toIdeal(lens, std::move(points)));
        if (!line) return std::nullopt;
        lines[i] = *line;
    }
    std::array<cv::Point2d, 4> out;
    for (int i = 0; i < 4; ++i) {
        std::optional<cv::Point2d> p = intersect(lines[(i + 3) % 4], lines[i]);
        if (!p) return std::nullopt;
        out[i] = *p;
    }
    return fromIdeal(lens, out);
}

}  // namespace

LinearFromCode linearFromCodeTable(const InverseToneMapSettings& radiometry) {
    InverseToneMapSettings grey = radiometry;
    grey.whiteBalance = {1.0f, 1.0f, 1.0f};  // a scale per channel: edges use ratios
    LinearFromCode t{};
    for (int i = 0; i < 256; ++i) {
        const float v = float(i) / 255.0f;
        t[i] = inverseToneMapRgb({v, v, v}, grey)[1];
    }
    return t;
}

LinearFromCode identityLinearFromCode() {
    LinearFromCode t{};
    for (int i = 0; i < 256; ++i) t[i] = float(i) / 255.0f;
    return t;
}

EdgeRefineStats refineTagCornersInLinearLight(std::vector<TagDetection>& detections,
                                              const cv::Mat& gray8, const LinearFromCode& table,
                                              const TagBorder& border,
                                              const CameraCalibration* lens) {
    PV_ASSERT(gray8.type() == CV_8UC1 && border.bits > 0);
    const LinearFrame linear{gray8, table};
    EdgeRefineStats stats;
    for (TagDetection& d : detections) {
        std::array<cv::Point2d, 4> detected;
        for (int i = 0; i < 4; ++i) detected[i] = openCvPixel(d.corners[i]);
        std::optional<std::array<cv::Point2d, 4>> quad = detected;
        std::array<double, 4> window{}, spread{};
        for (int pass = 0; pass < kPasses && quad; ++pass) {
            quad = refineQuad(*quad, linear, border, lens, window, spread);
            for (int i = 0; i < 4; ++i)
                window[i] = std::max(kMinWindowPx, kWindowSpreads * spread[i] + kWindowSlackPx);
        }
        bool plausible = quad.has_value();
        for (int i = 0; plausible && i < 4; ++i)
            plausible = cv::norm((*quad)[i] - detected[i]) <= kMaxCornerMovePx;
        if (!plausible) {
            ++stats.kept;
            continue;
        }
        for (int i = 0; i < 4; ++i) d.corners[i] = (*quad)[i] + cv::Point2d(0.5, 0.5);
        ++stats.refined;
    }
    return stats;
}

}  // namespace previs
