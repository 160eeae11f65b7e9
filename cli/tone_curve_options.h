#pragma once

// The tone-curve options, named once for every command and after the service config's keys
// (docs/config-format.md [*.radiometry]): --tone-curve srgb|reinhard|banterle (tone_curve),
// --exposure-stops (exposure_stops), --white-balance R,G,B (white_balance), --max-radiance
// (max_radiance), --white-luminance (white_luminance). A curve names a pair: forward when
// previs writes an 8-bit image, inverted when it reads one (a plate, a fisheye frame). render
// gives the plate's with the prefix "plate-". An input camera that sends Rec.709 or a log
// encoding is decoded through OpenColorIO instead, as [cameras.<name>.colour] does:
// --colour INPUT (input) and --ocio-config FILE (ocio_config), built by colour/ocio_colour.h.

#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "base/result.h"
#include "colour/ocio_colour.h"
#include "render/tonemap.h"
#include "vision/inverse_tone_map.h"

namespace previs {

struct ToneCurveOptions {
    std::string curve = "srgb";
    float exposureStops = 0.0f;
    std::vector<float> whiteBalance{1.0f, 1.0f, 1.0f};
    float maxRadiance = 16.0f;
    float whiteLuminance = 16.0f;
    std::string colourInput;  // OCIO colour space; "" = the curve above
    std::string ocioConfig;   // "" = OCIO's built-in camera transforms

    // `what` ends each help text ("LDR plate", "PNG output"); `withWhiteBalance` for inputs.
    void addTo(CLI::App* cmd, const std::string& prefix, const std::string& what,
               bool withWhiteBalance);
    // --<prefix>colour and --<prefix>ocio-config, for an input; they exclude the curve's options.
    void addColourTo(CLI::App* cmd, const std::string& prefix, const std::string& what);
    // Builds the OCIO transform when --colour was given: an unknown colour space or an unreadable
    // config is one line naming the option (exit 2). Call before inverse().
    Status buildColour();
    bool colourGiven() const { return !colourInput.empty(); }
    InverseToneMapSettings inverse() const;
    ToneMapSettings forward() const;

private:
    std::string colourPrefix_;
    std::shared_ptr<const CameraColourTransform> colour_;
};

}  // namespace previs
