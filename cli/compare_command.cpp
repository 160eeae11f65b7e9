#include "cli/compare_command.h"

#include <cmath>
#include <cstdio>
#include <memory>

#include "base/log.h"
#include "image/image.h"

namespace previs {

namespace {

struct CompareOptions {
    std::string image;
    std::string reference;
    bool json = false;
};

int run(const CompareOptions& o) {
    auto image = readImage(o.image);
    if (!image) {
        logError("{}", image.message());
        return 1;
    }
    auto reference = readImage(o.reference);
    if (!reference) {
        logError("{}", reference.message());
        return 1;
    }
    if (image->width != reference->width || image->height != reference->height ||
        image->channels != reference->channels) {
        logError("{} is {}x{}x{} but {} is {}x{}x{}: compare images of one size", o.image,
                 image->width, image->height, image->channels, o.reference, reference->width,
                 reference->height, reference->channels);
        return 2;
    }
    if (image->ldrSrgb || reference->ldrSrgb)
        logWarning("comparing 8-bit sRGB codes, not linear radiance: use .exr renders");
    // Over pixels and the RGB channels (alpha, if any, is not an error).
    const uint32_t channels = std::min(image->channels, 3u);
    double se = 0.0, rel = 0.0;
    size_t n = 0;
    for (size_t p = 0; p < size_t(image->width) * image->height; ++p) {
        for (uint32_t c = 0; c < channels; ++c) {
            const double x = image->pixels[p * image->channels + c];
            const double r = reference->pixels[p * image->channels + c];
            se += (x - r) * (x - r);
            rel += (x - r) * (x - r) / (r * r + 0.01);  // DESIGN.md §4's relMSE
            ++n;
        }
    }
    const double rmse = std::sqrt(se / double(n));
    const double relMse = rel / double(n);
    if (o.json)
        std::printf("{\"rmse\": %.9g, \"relMse\": %.9g}\n", rmse, relMse);
    else
        std::printf("rmse %.9g relMse %.9g\n", rmse, relMse);
    return 0;
}

}  // namespace

std::function<int()> addCompareCommand(CLI::App& app) {
    auto o = std::make_shared<CompareOptions>();
    CLI::App* cmd = app.add_subcommand(
        "compare", "error of a linear image against a reference: RMSE and relMSE (DESIGN.md §4)");
    cmd->add_option("IMAGE", o->image, "the image (.exr)")->required()->check(CLI::ExistingFile);
    cmd->add_option("REFERENCE", o->reference, "the reference (.exr), e.g. a long render")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_flag("--json", o->json, "print {\"rmse\", \"relMse\"}");
    return [o] { return run(*o); };
}

}  // namespace previs
