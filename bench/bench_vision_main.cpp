// previs_bench_vision [DATA_DIR] [RUNS]: prints the vision timings (bench/bench_vision.h).
#include <cstdio>
#include <cstdlib>

#include "base/log.h"
#include "bench/bench_data_arg.h"
#include "bench/bench_vision.h"

int main(int argc, char** argv) {
    const auto dataDir = previs::bench::dataDirArgument(argc, argv);
    if (!dataDir) return 2;
    const std::string& data = *dataDir;
    const int runs = argc > 2 ? std::atoi(argv[2]) : 30;
    auto timings = previs::benchVision(data, runs);
    if (!timings) {
        previs::logError("{}", timings.message());
        return 1;
    }
    std::printf("%-48s %6s %10s %10s  %s\n", "measurement", "runs", "median ms", "p90 ms", "");
    for (const auto& t : *timings)
        std::printf("%-48s %6d %10.2f %10.2f  %s\n", t.name.c_str(), t.runs, t.medianMs, t.p90Ms,
                    t.note.c_str());
    return 0;
}
