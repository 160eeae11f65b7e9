#include "vision/hdr_bracket.h"

#include <algorithm>
#include <cmath>

#include "base/log.h"
#include "base/luminance.h"

namespace previs {

namespace {

// Labels are decimal text in a take: equal within this.
constexpr float kSameStops = 0.01f;

// Channels within this range in both frames are trusted for the exposure check: above the
// noise floor and below the shoulder where the curve compresses and JPEG rings.
constexpr int kCheckLow = 24;
constexpr int kCheckHigh = 230;

float hatWeight(int maxCode) {
    if (maxCode >= kClippedCode) return 0.0f;
    return float(std::min(maxCode + 1, 255 - maxCode));
}

int maxChannel(const uint8_t* p) { return std::max({p[0], p[1], p[2]}); }

// Two frames' codes differ by more than this to order a pixel: well above sensor noise (a few
// codes), so a correct pair's pixels never go the wrong way but for motion.
constexpr int kOrderMarginCodes = 12;

}  // namespace

Status checkBracketStops(const std::vector<float>& stops, const std::string& where) {
    if (stops.size() < 2 || stops.size() > 8)
        return makeError("{}: {} exposures; a bracket takes 2 to 8 (e.g. [0, -4, -8])", where,
                         stops.size());
    for (size_t i = 0; i < stops.size(); ++i) {
        if (!std::isfinite(stops[i]) || std::abs(stops[i]) > 20.0f)
            return makeError("{}: {} is not a number of stops within ±20", where, stops[i]);
        for (size_t j = 0; j < i; ++j)
            if (std::abs(stops[i] - stops[j]) < 1.0f)
                return makeError(
                    "{}: {} and {} are less than a stop apart; a bracket's exposures must differ "
                    "by at least 1 stop",
                    where, stops[j], stops[i]);
    }
    return {};
}

Result<MergedBracket> mergeBracket(const std::vector<cv::Mat>& rgb8,
                                   const std::vector<float>& stops,
                                   const InverseToneMapSettings& radiometry) {
    if (rgb8.empty() || rgb8.size() != stops.size())
        return makeError("bracket: {} frames for {} exposures", rgb8.size(), stops.size());
    const cv::Size size = rgb8[0].size();
    for (const cv::Mat& m : rgb8)
        if (m.type() != CV_8UC3 || m.size() != size || !m.isContinuous())
            return makeError("bracket: frames must be 8-bit RGB of one size ({}x{})", size.width,
                             size.height);
    const size_t shortest = size_t(std::min_element(stops.begin(), stops.end()) - stops.begin());
    const size_t longest = size_t(std::max_element(stops.begin(), stops.end()) - stops.begin());
    std::vector<cv::Mat> linear;
    std::vector<float> exposure;
    for (size_t i = 0; i < rgb8.size(); ++i) {
        linear.push_back(inverseToneMapRgb8(rgb8[i], radiometry));
        exposure.push_back(std::exp2(stops[i]));
    }
    MergedBracket out;
    out.radiance.create(size, CV_32FC3);
    out.clipped = cv::Mat::zeros(size, CV_8U);
    const int n = size.area();
    uint64_t clipped = 0;
    for (int p = 0; p < n; ++p) {
        double sum[3] = {0.0, 0.0, 0.0};
        double weightSum = 0.0;
        for (size_t i = 0; i < rgb8.size(); ++i) {
            const float hat = hatWeight(maxChannel(rgb8[i].data + 3 * p));
            if (hat <= 0.0f) continue;
            const float* l = linear[i].ptr<float>() + 3 * p;
            // wᵢ·Eᵢ = (tᵢ·hat)·(lᵢ / tᵢ): the exposure cancels in the numerator.
            for (int c = 0; c < 3; ++c) sum[c] += double(hat) * l[c];
            weightSum += double(exposure[i]) * hat;
        }
        float* o = out.radiance.ptr<float>() + 3 * p;
        if (weightSum > 0.0) {
            for (int c = 0; c < 3; ++c) o[c] = float(sum[c] / weightSum);
            continue;
        }
        // No frame exposed it well: clipped everywhere (a lower bound from the shortest) or
        // black everywhere (the longest says it best).
        const bool isClipped = maxChannel(rgb8[shortest].data + 3 * p) >= kClippedCode;
        const size_t from = isClipped ? shortest : longest;
        const float* l = linear[from].ptr<float>() + 3 * p;
        for (int c = 0; c < 3; ++c) o[c] = l[c] / exposure[from];
        if (isClipped) {
            out.clipped.data[p] = 255;
            ++clipped;
        }
    }
    out.clippedFraction = n > 0 ? double(clipped) / n : 0.0;
    return out;
}

std::optional<float> measuredStopsBetween(const cv::Mat& rgb8A, const cv::Mat& rgb8B,
                                          const InverseToneMapSettings& radiometry, int minPixels) {
    PV_ASSERT(rgb8A.type() == CV_8UC3 && rgb8B.type() == CV_8UC3 && rgb8A.size() == rgb8B.size());
    const cv::Mat a = rgb8A.isContinuous() ? rgb8A : rgb8A.clone();
    const cv::Mat b = rgb8B.isContinuous() ? rgb8B : rgb8B.clone();
    const cv::Mat la = inverseToneMapRgb8(a, radiometry);
    const cv::Mat lb = inverseToneMapRgb8(b, radiometry);
    auto trusted = [](const uint8_t* p) {
        return std::min({p[0], p[1], p[2]}) >= kCheckLow && maxChannel(p) <= kCheckHigh;
    };
    std::vector<float> ratios;
    for (int p = 0; p < a.rows * a.cols; ++p) {
        if (!trusted(a.data + 3 * p) || !trusted(b.data + 3 * p)) continue;
        const float* pa = la.ptr<float>() + 3 * p;
        const float* pb = lb.ptr<float>() + 3 * p;
        const float ya = luminance(pa[0], pa[1], pa[2]);
        const float yb = luminance(pb[0], pb[1], pb[2]);
        if (ya > 0.0f && yb > 0.0f) ratios.push_back(std::log2(yb / ya));
    }
    if (int(ratios.size()) < minPixels) return std::nullopt;
    auto mid = ratios.begin() + ratios.size() / 2;
    std::nth_element(ratios.begin(), mid, ratios.end());
    return *mid;
}

bool exposureOrderContradicted(const cv::Mat& rgb8A, const cv::Mat& rgb8B, float expectedStops,
                               int minPixels) {
    PV_ASSERT(rgb8A.type() == CV_8UC3 && rgb8B.type() == CV_8UC3 && rgb8A.size() == rgb8B.size());
    if (expectedStops == 0.0f) return false;
    const cv::Mat a = rgb8A.isContinuous() ? rgb8A : rgb8A.clone();
    const cv::Mat b = rgb8B.isContinuous() ? rgb8B : rgb8B.clone();
    int agree = 0, contradict = 0;
    for (int p = 0; p < a.rows * a.cols; ++p) {
        // > 0: b brighter than a.
        const int d = maxChannel(b.data + 3 * p) - maxChannel(a.data + 3 * p);
        const int towardLabel = expectedStops > 0.0f ? d : -d;
        if (towardLabel > kOrderMarginCodes)
            ++agree;
        else if (towardLabel < -kOrderMarginCodes)
            ++contradict;
    }
    return contradict >= minPixels && contradict > agree;
}

Result<BracketAssembler> BracketAssembler::create(BracketSettings settings,
                                                  InverseToneMapSettings radiometry) {
    if (Status s = checkBracketStops(settings.stops, "bracket stops"); !s) return s.error();
    if (!(settings.ratioToleranceStops > 0.0f) || settings.minCheckPixels < 1)
        return makeError("bracket: the exposure check needs a positive tolerance and pixel count");
    return BracketAssembler(std::move(settings), radiometry);
}

bool BracketAssembler::startsBracket(std::optional<float> exposureStops) const {
    return exposureStops && std::abs(*exposureStops - settings_.stops.front()) < kSameStops;
}

void BracketAssembler::drop(uint64_t& counter, std::string why) {
    ++counter;
    lastDrop_ = std::move(why);
    frames_.clear();
}

std::optional<MergedBracket> BracketAssembler::add(const cv::Mat& rgb8, uint64_t sequence,
                                                   uint64_t timestampNs,
                                                   std::optional<float> exposureStops) {
    if (!exposureStops) {
        drop(counts_.droppedUnlabelled,
             fmt::format("frame {} came without its exposure", sequence));
        return std::nullopt;
    }
    const size_t next = frames_.size();
    const bool isNext = std::abs(*exposureStops - settings_.stops[next]) < kSameStops;
    if (!frames_.empty() && sequence != lastSequence_ + 1) {
        drop(counts_.droppedMissing, fmt::format("frames {} to {} are missing from the bracket",
                                                 lastSequence_ + 1, sequence - 1));
    } else if (!isNext && !frames_.empty() && startsBracket(exposureStops)) {
        drop(counts_.droppedMissing,
             fmt::format("the bracket from frame {} was cut short by frame {}", firstSequence_,
                         sequence));
    } else if (!isNext && !frames_.empty()) {
        drop(counts_.droppedWrongExposure,
             fmt::format("frame {} is at {} stops where the bracket's next is {}", sequence,
                         *exposureStops, settings_.stops[next]));
    }
    if (frames_.empty()) {
        if (!startsBracket(exposureStops)) {
            // Between brackets a frame of another exposure is the tail of one already dropped
            // (or the camera's cycle starting mid-way): it waits for the next start, uncounted.
            return std::nullopt;
        }
        firstSequence_ = sequence;
    }
    frames_.push_back(rgb8.clone());  // the caller's frame is a borrowed view
    lastSequence_ = sequence;
    lastTimestampNs_ = timestampNs;
    if (frames_.size() < settings_.stops.size()) return std::nullopt;
    return complete();
}

std::optional<MergedBracket> BracketAssembler::complete() {
    const std::vector<float>& stops = settings_.stops;
    for (size_t i = 1; i < frames_.size(); ++i) {
        const std::optional<float> measured =
            measuredStopsBetween(frames_[i - 1], frames_[i], radiometry_, settings_.minCheckPixels);
        const float expected = stops[i] - stops[i - 1];
        if (!measured) {
            if (exposureOrderContradicted(frames_[i - 1], frames_[i], expected,
                                          settings_.minCheckPixels)) {
                drop(counts_.droppedMismatch,
                     fmt::format("frames {} and {} are ordered against their exposures ({:+.2f} "
                                 "stops) in their pictures (a control that landed late?)",
                                 firstSequence_ + i - 1, firstSequence_ + i, expected));
                return std::nullopt;
            }
            ++counts_.unchecked;
            continue;
        }
        if (std::abs(*measured - expected) > settings_.ratioToleranceStops) {
            drop(counts_.droppedMismatch,
                 fmt::format("frames {} and {} differ by {:.2f} stops in their pictures, not the "
                             "{:.2f} their exposures say (a control that landed late?)",
                             firstSequence_ + i - 1, firstSequence_ + i, *measured, expected));
            return std::nullopt;
        }
    }
    Result<MergedBracket> merged = mergeBracket(frames_, stops, radiometry_);
    frames_.clear();
    if (!merged) {
        ++counts_.droppedMismatch;
        lastDrop_ = merged.message();
        return std::nullopt;
    }
    merged->firstSequence = firstSequence_;
    merged->lastSequence = lastSequence_;
    merged->timestampNs = lastTimestampNs_;
    ++counts_.merged;
    return std::move(*merged);
}

}  // namespace previs
