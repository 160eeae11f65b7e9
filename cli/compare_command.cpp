#include "cli/compare_command.h"

#include <cstdio>

#include "base/log.h"
#include "image/image.h"
#include "image/image_compare.h"

namespace previs {

namespace {

struct CompareOptions {
    std::string a;
    std::string b;
    std::vector<uint32_t> region;
};

int run(const CompareOptions& o) {
    Result<ImageF> images[2] = {readImage(o.a), readImage(o.b)};
    for (const auto& img : images) {
        if (!img) {
            logError("{}", img.message());
            return 2;
        }
        if (img->ldrSrgb) {
            logError("{} is 8-bit sRGB: compare linear images (.exr, .hdr)",
                     &img == &images[0] ? o.a : o.b);
            return 2;
        }
    }
    std::optional<PixelRegion> region;
    if (!o.region.empty()) region = PixelRegion{o.region[0], o.region[1], o.region[2], o.region[3]};
    auto d = compareImages(*images[0], *images[1], region);
    if (!d) {
        logError("{} against {}: {}", o.a, o.b, d.message());
        return 2;
    }
    std::printf("rmse %.9g relMse %.9g mean_a %.9g mean_b %.9g values %zu\n", d->rmse, d->relMse,
                d->meanA, d->meanB, d->values);
    return 0;
}

}  // namespace

std::function<int()> addCompareCommand(CLI::App& app) {
    auto o = std::make_shared<CompareOptions>();
    CLI::App* cmd = app.add_subcommand(
        "compare",
        "RMSE and relMSE (DESIGN.md §4) of a linear image against a reference, over every "
        "pixel and channel, and their means");
    cmd->add_option("IMAGE", o->a, "image (.exr or .hdr)")->required()->check(CLI::ExistingFile);
    cmd->add_option("REFERENCE", o->b,
                    "reference image, same size and channels, e.g. a long render")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--region", o->region,
                    "only pixels x0 <= x < x1, y0 <= y < y1 (e.g. a caustic): X0,Y0,X1,Y1")
        ->delimiter(',')
        ->expected(4);
    return [o] { return run(*o); };
}

}  // namespace previs
