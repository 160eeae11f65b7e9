#include "bench/light_truth.h"

#include <toml++/toml.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <opencv2/imgproc.hpp>

#include "base/luminance.h"

namespace previs {

namespace {

// Luminance of a 3-channel image (or the one channel of a mask) as a CV_64F matrix.
cv::Mat luminanceOf(const ImageF& img) {
    cv::Mat out(int(img.height), int(img.width), CV_64F);
    for (uint32_t y = 0; y < img.height; ++y)
        for (uint32_t x = 0; x < img.width; ++x) {
            const float* p = &img.pixels[(size_t(y) * img.width + x) * img.channels];
            out.at<double>(int(y), int(x)) =
                img.channels >= 3 ? luminance(double(p[0]), double(p[1]), double(p[2])) : p[0];
        }
    return out;
}

// Box-filters `m` down by a whole factor.
cv::Mat shrink(const cv::Mat& m, int factor) {
    if (factor == 1) return m;
    cv::Mat out;
    cv::resize(m, out, cv::Size(m.cols / factor, m.rows / factor), 0, 0, cv::INTER_AREA);
    return out;
}

// Shadow pixels: real in `mask`, and the objects take more than kShadowFraction of L_or there
// (both 3×3-smoothed).
cv::Mat shadowRegion(const cv::Mat& real, const cv::Mat& taken, const cv::Mat& mask) {
    cv::Mat realSmooth, takenSmooth;
    cv::blur(real, realSmooth, {3, 3});
    cv::blur(taken, takenSmooth, {3, 3});
    cv::Mat region = (takenSmooth > kShadowFraction * realSmooth) & (mask < 0.01);
    return region;
}

}  // namespace

Result<std::vector<TruthFrame>> loadTruth(const std::string& truthDir) {
    const std::string path = truthDir + "/truth.toml";
    toml::table t;
    try {
        t = toml::parse_file(path);
    } catch (const toml::parse_error& e) {
        return makeError("{}: {}", path, e.description());
    }
    const toml::array* frames = t["frame"].as_array();
    if (!frames || frames->empty()) return makeError("{}: no [[frame]]", path);
    std::vector<TruthFrame> out;
    for (const toml::node& node : *frames) {
        const toml::table* f = node.as_table();
        if (!f) return makeError("{}: a [[frame]] is not a table", path);
        TruthFrame frame;
        frame.index = int((*f)["index"].value_or(int64_t(-1)));
        frame.still = (*f)["still"].value_or(false);
        for (auto [key, image] : {std::pair<const char*, ImageF*>{"mixed", &frame.mixed},
                                  {"real", &frame.real},
                                  {"mask", &frame.mask}}) {
            const std::optional<std::string> file = (*f)[key].value<std::string>();
            if (!file) return makeError("{}: frame {} names no '{}'", path, frame.index, key);
            Result<ImageF> img = readImage(truthDir + "/" + *file);
            if (!img) return img.error();
            *image = std::move(*img);
        }
        out.push_back(std::move(frame));
    }
    return out;
}

Result<BoxFrame> loadBoxFrame(const std::string& exrPath) {
    BoxFrame b;
    for (auto [layer, image] : {std::pair<const char*, ImageF*>{"", &b.composite},
                                {"mixed", &b.mixed},
                                {"real", &b.real},
                                {"mask", &b.mask}}) {
        Result<ImageF> img = readExrLayer(exrPath, layer);
        if (!img) return img.error();
        *image = std::move(*img);
    }
    return b;
}

Result<TruthScore> scoreAgainstTruth(const BoxFrame& box, const TruthFrame& truth) {
    const int w = int(box.real.width), h = int(box.real.height);
    if (w == 0 || h == 0 || int(truth.real.width) % w != 0 ||
        int(truth.real.width) / w != int(truth.real.height) / h || int(truth.real.height) % h != 0)
        return makeError(
            "the box's frame ({}x{}) is not the truth's ({}x{}) shrunk by a whole "
            "factor",
            w, h, truth.real.width, truth.real.height);
    const int factor = int(truth.real.width) / w;
    const cv::Mat tReal = shrink(luminanceOf(truth.real), factor);
    const cv::Mat tMixed = shrink(luminanceOf(truth.mixed), factor);
    const cv::Mat tMask = shrink(luminanceOf(truth.mask), factor);
    const cv::Mat bReal = luminanceOf(box.real), bMixed = luminanceOf(box.mixed);
    const cv::Mat bMask = luminanceOf(box.mask), bComposite = luminanceOf(box.composite);

    TruthScore s;
    const cv::Mat tTaken = tReal - tMixed, bTaken = bReal - bMixed;
    const cv::Mat tShadow = shadowRegion(tReal, tTaken, tMask);
    const cv::Mat bShadow = shadowRegion(bReal, bTaken, bMask);
    const cv::Mat either = tShadow | bShadow;
    s.shadowPixelsTruth = size_t(cv::countNonZero(tShadow));
    s.shadowPixelsBox = size_t(cv::countNonZero(bShadow));
    const double unionCount = cv::countNonZero(either);
    s.shadowIoU = unionCount > 0 ? cv::countNonZero(tShadow & bShadow) / unionCount : 0.0;
    cv::Mat inEither;
    either.convertTo(inEither, CV_64F, 1.0 / 255.0);
    const double tEnergy = cv::sum(tTaken.mul(inEither))[0];
    const double bEnergy = cv::sum(bTaken.mul(inEither))[0];
    s.shadowEnergyRatio = tEnergy > 0.0 ? bEnergy / tEnergy : 0.0;

    // The virtual objects: connected parts of the truth's fully virtual pixels.
    cv::Mat labels, stats, centroids;
    const cv::Mat solid = tMask > 0.99;
    const int n = cv::connectedComponentsWithStats(solid, labels, stats, centroids, 8, CV_32S);
    std::vector<std::pair<double, int>> parts;  // (centroid x, label)
    for (int l = 1; l < n; ++l)
        if (stats.at<int>(l, cv::CC_STAT_AREA) >= 12)
            parts.emplace_back(centroids.at<double>(l, 0), l);
    std::sort(parts.begin(), parts.end());
    for (auto [x, l] : parts) {
        const cv::Mat in = labels == l;
        s.objectRatios.push_back(cv::mean(bComposite, in)[0] / cv::mean(tMixed, in)[0]);
        s.objectPixels.push_back(size_t(cv::countNonZero(in)));
    }
    return s;
}

}  // namespace previs
