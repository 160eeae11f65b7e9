#include "base/stage_watch.h"

#include <algorithm>

namespace previs {

int64_t Stage::overdueNs(int64_t nowNs, int64_t limitNs) const {
    const int64_t start = stepStartNs_.load();
    if (start == 0) return 0;
    return std::max<int64_t>(0, nowNs - start - limitNs - allowanceNs_.load());
}

int64_t Stage::runningNs(int64_t nowNs) const {
    const int64_t start = stepStartNs_.load();
    return start == 0 ? 0 : std::max<int64_t>(0, nowNs - start);
}

int64_t stageClockNs() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

StageStep::StageStep(Stage* stage) : stage_(stage) {
    if (stage_) stage_->begin(stageClockNs());
}

StageStep::~StageStep() {
    if (stage_) stage_->end();
}

Stage& StageWatch::add(std::string name) { return stages_.emplace_back(std::move(name)); }

std::vector<StageWatch::Stuck> StageWatch::stuck(int64_t nowNs, int64_t limitNs) const {
    std::vector<Stuck> out;
    for (const Stage& s : stages_)
        if (s.overdueNs(nowNs, limitNs) > 0)
            out.push_back({s.name(), double(s.runningNs(nowNs)) * 1e-9});
    return out;
}

}  // namespace previs
