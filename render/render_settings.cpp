#include "render/render_settings.h"

#include <cctype>
#include <cstdlib>

namespace previs {

Status applyPhotonSpec(const std::string& spec, PhotonSettings& settings) {
    if (spec == "auto" || spec == "on" || spec == "off") {
        settings.mode = spec == "auto" ? PhotonMode::Auto
                        : spec == "on" ? PhotonMode::On
                                       : PhotonMode::Off;
        return {};
    }
    char* end = nullptr;
    unsigned long long n = std::strtoull(spec.c_str(), &end, 10);
    if (spec.empty() || !std::isdigit(static_cast<unsigned char>(spec[0])) || *end != '\0' ||
        n == 0 || n > kMaxPhotonsPerIteration)
        return makeError(
            "photons '{}' is not auto, on, off or a count of photons per iteration "
            "(1..{})",
            spec, kMaxPhotonsPerIteration);
    settings.mode = PhotonMode::On;
    settings.perIteration = uint32_t(n);
    return {};
}

RenderSettings renderSettings(uint32_t width, uint32_t height, uint32_t maxDepth) {
    RenderSettings rs;
    rs.width = width;
    rs.height = height;
    rs.maxDepth = maxDepth;
    return rs;
}

}  // namespace previs
