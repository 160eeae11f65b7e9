#pragma once

// The service config's sections for the set's network (issue 39, DESIGN.md §3, the keys in
// docs/config-format.md): camera tracking out as FreeD and OpenTrackIO, the timecode source and
// the browser monitor. Each is off unless its section names an address or a source.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "base/result.h"

namespace previs {

// [freed]: one FreeD D1 packet per tracked frame (docs/freed.md).
struct FreedOutConfig {
    std::string out;  // "HOST:PORT"; "" = off
    uint8_t cameraId = 1;
    // A lost pose sends nothing by default; `hold` repeats the last trusted pose (a receiver that
    // cannot tell "no packet" from "camera off"), counted in the status as held packets.
    bool holdWhenLost = false;

    bool operator==(const FreedOutConfig&) const = default;
};

// [opentrackio]: one SMPTE RIS OpenTrackIO sample per tracked frame (docs/opentrackio.md).
struct OpenTrackIoConfig {
    // "multicast" (group 235.135.1.<source_number>, port 55555) or "HOST:PORT"; "" = off.
    std::string out;
    int sourceNumber = 1;  // 1..200
    int multicastTtl = 1;  // hops: 1 stays on the set's subnet

    bool operator==(const OpenTrackIoConfig&) const = default;
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

    bool operator==(const TimecodeConfig&) const = default;
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
    // Names the page is opened by besides IP literals, localhost and the listen host (the
    // monitor answers any other Host 421: DNS rebinding, docs/web-monitor.md).
    std::vector<std::string> hostNames;

    bool operator==(const WebConfig&) const = default;
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

    bool operator==(const NetworkConfig&) const = default;
};

// Whether `value` holds a control character (a newline, a tab, DEL). previsd writes addresses
// into systemd units (`previsd --network-units`), where a newline would start a setting of its
// own: the config refuses them.
bool hasControlCharacter(std::string_view value);

// The shortest web token accepted: a guessable token opens the box's controls to the set.
constexpr size_t kMinWebTokenChars = 16;

// The web monitor's bearer token: `tokenFile`, else the unit's credential, else none (""). One
// line ending (echo, an editor) is not part of it. A token file that cannot be read, or whose
// token is shorter than kMinWebTokenChars, starts or ends with white space or holds a control
// character (it could never be presented in an Authorization header) is an error naming the
// file, `configPath` and the key.
Result<std::string> readWebToken(const WebConfig& web, const std::string& configPath);
// The same for the token file `path`, named in errors by `key`.
Result<std::string> readWebTokenFile(const std::string& path, const std::string& configPath,
                                     std::string_view key);

// The key the unit's credential is named by in errors.
constexpr std::string_view kWebTokenCredentialKey =
    "the unit's credential web-token (the file web-token beside the config)";

}  // namespace previs
