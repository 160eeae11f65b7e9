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

void ToneCurveOptions::addColourTo(CLI::App* cmd, const std::string& prefix,
                                   const std::string& what) {
    colourPrefix_ = prefix;
    CLI::Option* input = cmd->add_option(
        "--" + prefix + "colour", colourInput,
        what +
            ": the camera's OpenColorIO colour space (e.g. \"ARRI LogC3 (EI800)\", "
            "\"Sony S-Log3 S-Gamut3\", \"Rec.709 - Camera\"), decoded to scene-linear in "
            "place of the tone curve; exposure and white balance still apply");
    for (const char* curveOption : {"tone-curve", "max-radiance", "white-luminance"})
        if (CLI::Option* o = cmd->get_option_no_throw("--" + prefix + curveOption))
            input->excludes(o);
    cmd->add_option("--" + prefix + "ocio-config", ocioConfig,
                    what + ": OCIO config file for --" + prefix +
                        "colour (default: OCIO's built-in camera transforms)")
        ->needs(input);
}

Status ToneCurveOptions::buildColour() {
    if (!colourGiven()) return {};
    const OcioSource source = OcioSource::fromOptions(ocioConfig, "--" + colourPrefix_ + "colour",
                                                      "--" + colourPrefix_ + "ocio-config");
    Result<std::shared_ptr<const CameraColourTransform>> transform =
        CameraColourTransform::create(source, colourInput);
    if (!transform) return transform.error();
    colour_ = std::move(*transform);
    return {};
}

InverseToneMapSettings ToneCurveOptions::inverse() const {
    InverseToneMapSettings s;
    s.op = *parseInverseToneMapOperator(curve);  // the option's check admits only known names
    s.exposureStops = exposureStops;
    s.whiteBalance = {whiteBalance[0], whiteBalance[1], whiteBalance[2]};
    s.maxRadiance = maxRadiance;
    s.whiteLuminance = whiteLuminance;
    s.colour = colour_;
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
