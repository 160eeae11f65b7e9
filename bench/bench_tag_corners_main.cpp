// previs_bench_tag_corners [DATA_DIR]: the box's tag corners and poses against ViSP's rendered
// benchmark's truth, by family and way of placing the corners (bench/visp_tag_poses.h), as the
// table of bench/results/benchmarks_2026-12-06.md, "Tag corners on third-party images".
#include <algorithm>
#include <cstdio>

#include "base/log.h"
#include "bench/bench_data_arg.h"
#include "bench/visp_tag_poses.h"

int main(int argc, char** argv) {
    const auto dataDir = previs::bench::dataDirArgument(argc, argv);
    if (!dataDir) return 2;
    const std::string& data = *dataDir;
    std::vector<previs::bench::VispFamilyResult> results;
    for (const previs::bench::VispTagFamily& f : previs::bench::vispTagFamilies()) {
        auto r = previs::bench::measureVispFamily(
            data, f, {previs::bench::VispImage::AsRendered, previs::bench::VispImage::ThroughSrgb},
            previs::bench::vispCornerMethods());
        if (!r) {
            previs::logError("{}", r.message());
            return 1;
        }
        results.insert(results.end(), r->begin(), r->end());
    }
    // As rendered first, then through sRGB.
    std::stable_partition(results.begin(), results.end(), [](const auto& r) {
        return r.image == previs::bench::VispImage::AsRendered;
    });
    std::fputs(previs::bench::vispTagTable(results).c_str(), stdout);
    auto yaws = previs::bench::measureDuckietownYaw(data, previs::bench::vispCornerMethods());
    if (!yaws) {
        previs::logError("{}", yaws.message());
        return 1;
    }
    std::fputs(("\n" + previs::bench::duckietownTable(*yaws)).c_str(), stdout);
    return 0;
}
