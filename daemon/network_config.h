#pragma once

// The service config's sections for the set's network (issue 39, DESIGN.md §3, the keys in
// docs/config-format.md): camera tracking out as FreeD and OpenTrackIO, the timecode source and
// the browser monitor. Each is off unless its section names an address or a source.

#include <cstdint>
#include <string>

#include "base/result.h"

namespace previs {

// [freed]: one FreeD D1 packet per tracked frame (docs/freed.md).
struct FreedOutConfig {
    std::string out;  // "HOST:PORT"; "" = off
    uint8_t cameraId = 1;
    // A lost pose sends nothing by default; `hold` repeats the last trusted pose (a receiver that
    // cannot tell "no packet" from "camera off"), counted in the status as held packets.
    bool holdWhenLost = false;
};

// [opentrackio]: one SMPTE RIS OpenTrackIO sample per tracked frame (docs/opentrackio.md).
struct OpenTrackIoConfig {
    // "multicast" (group 235.135.1.<source_number>, port 55555) or "HOST:PORT"; "" = off.
    std::string out;
    int sourceNumber = 1;  // 1..200
    int multicastTtl = 1;  // hops: 1 stays on the set's subnet
};

// [timecode]: every frame's SMPTE timecode (docs/timecode.md).
struct TimecodeConfig {
    // source = "ltc": LTC on an audio input; "clock" (the default): the time of day.
    bool ltc = false;
    // The timecode rate ("25", "29.97df", ...); "" = the scene camera's rate, non-drop.
    std::string rate;
    std::string device = "default";  // ltc: the ALSA capture device ("hw:1,0")
    int channel = 0;                 // ltc: the input channel carrying LTC
    int sampleRate = 48000;          // ltc: the device's rate
};

// [web]: the monitor page (docs/web-monitor.md).
struct WebConfig {
    std::string listen;  // "HOST:PORT"; "" = off
    // The bearer token's file; "" = $CREDENTIALS_DIRECTORY/web-token (the unit's
    // LoadCredential=), else no token: viewing only.
    std::string tokenFile;
    double streamFps = 10.0;
    int streamWidth = 640;
    int jpegQuality = 80;
    int maxViewers = 4;
};

struct NetworkConfig {
    FreedOutConfig freed;
    OpenTrackIoConfig opentrackio;
    TimecodeConfig timecode;
    WebConfig web;

    // Whether any feature needs the network (the unit's drop-in opens it only then).
    bool usesNetwork() const {
        return !freed.out.empty() || !opentrackio.out.empty() || !web.listen.empty();
    }
};

// The web monitor's bearer token: `tokenFile`, else the unit's credential, else none (""). A
// token file that exists but cannot be read, or is empty, is an error naming it.
Result<std::string> readWebToken(const WebConfig& web);

}  // namespace previs
