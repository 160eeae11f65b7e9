#pragma once

// The tone-curve options, named once for every command and after the service config's keys
// (docs/config-format.md [*.radiometry]): --tone-curve srgb|reinhard|banterle (tone_curve),
// --exposure-stops (exposure_stops), --white-balance R,G,B (white_balance), --max-radiance
// (max_radiance), --white-luminance (white_luminance). A curve names a pair: forward when
// previs writes an 8-bit image, inverted when it reads one (a plate, a fisheye frame). render
// gives the plate's with the prefix "plate-".

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "render/tonemap.h"
#include "vision/inverse_tone_map.h"

namespace previs {

struct ToneCurveOptions {
    std::string curve = "srgb";
    float exposureStops = 0.0f;
    std::vector<float> whiteBalance{1.0f, 1.0f, 1.0f};
    float maxRadiance = 16.0f;
    float whiteLuminance = 16.0f;

    // `what` ends each help text ("LDR plate", "PNG output"); `withWhiteBalance` for inputs.
    void addTo(CLI::App* cmd, const std::string& prefix, const std::string& what,
               bool withWhiteBalance);
    InverseToneMapSettings inverse() const;
    ToneMapSettings forward() const;
};

}  // namespace previs
