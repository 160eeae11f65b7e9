#pragma once

// OCIO 2.1 has no built-in config (ocio://default came in 2.2), only built-in transforms
// (BuiltinTransformRegistry). This assembles a small in-memory config from them: the cameras a
// set sends (ARRI, Sony, Panasonic, Canon, RED log encodings and Rec.709), the renderer's
// working space and two displays with an ACES and a plain view. Reference space: ACES2065-1,
// also its aces_interchange role, so a user's config connects to it through
// Config::GetProcessorFromConfigs.

#include <OpenColorIO/OpenColorIO.h>

#include <string>
#include <vector>

namespace previs {

// The renderer's working space: scene-linear, Rec.709 (sRGB) primaries, D65 white — the space
// the path tracer, the environment maps and the plates are in.
inline constexpr const char* kWorkingColourSpace = "Linear Rec.709 (sRGB)";
inline constexpr const char* kInterchangeColourSpace = "ACES2065-1";

// Built once per process (a few microseconds); immutable afterwards, so shared between threads.
OCIO_NAMESPACE::ConstConfigRcPtr builtinColourConfig();

// The camera colour spaces of builtinColourConfig(), by name (each also answers to its OCIO
// built-in transform's style, e.g. "ARRI_ALEXA-LOGC-EI800-AWG_to_ACES2065-1").
std::vector<std::string> builtinCameraColourSpaces();

}  // namespace previs
