#include "cli/tone_curve_options.h"

namespace previs {

void ToneCurveOptions::addTo(CLI::App* cmd, const std::string& prefix, const std::string& what,
                             bool withWhiteBalance) {
    cmd->add_option("--" + prefix + "tone-curve", curve,
                    what +
                        ": srgb (default; linear, clipped), reinhard or banterle (Reinhard's "
                        "extended curve with --" +
                        prefix + "max-radiance and --" + prefix + "white-luminance)")
        ->check(CLI::IsMember({"srgb", "reinhard", "banterle"}));
    cmd->add_option("--" + prefix + "exposure-stops", exposureStops,
                    what + ": exposure in stops (display = curve(radiance · 2^stops))");
    if (withWhiteBalance)
        cmd->add_option("--" + prefix + "white-balance", whiteBalance,
                        what + ": R,G,B gains applied to the radiance (default 1,1,1)")
            ->delimiter(',')
            ->expected(3)
            ->check(CLI::PositiveNumber);
    cmd->add_option("--" + prefix + "max-radiance", maxRadiance,
                    what + ", banterle: the radiance display white stands for (L_max)")
        ->check(CLI::PositiveNumber);
    cmd->add_option("--" + prefix + "white-luminance", whiteLuminance,
                    what + ", banterle: the curve's shape, Reinhard's L_white")
        ->check(CLI::PositiveNumber);
}

InverseToneMapSettings ToneCurveOptions::inverse() const {
    InverseToneMapSettings s;
    s.op = *parseInverseToneMapOperator(curve);  // the option's check admits only known names
    s.exposureStops = exposureStops;
    s.whiteBalance = {whiteBalance[0], whiteBalance[1], whiteBalance[2]};
    s.maxRadiance = maxRadiance;
    s.whiteLuminance = whiteLuminance;
    return s;
}

ToneMapSettings ToneCurveOptions::forward() const {
    ToneMapSettings s;
    s.op = *parseToneMapOperator(curve);
    s.exposureStops = exposureStops;
    s.maxRadiance = maxRadiance;
    s.whiteLuminance = whiteLuminance;
    return s;
}

}  // namespace previs
