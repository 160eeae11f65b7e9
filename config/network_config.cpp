#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "config/network_config_reader.h"
#include "net/udp_socket.h"
#include "timecode/timecode.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

// A "HOST:PORT" key; absent leaves `value` empty. The address is resolved when the service
// starts (a name may only resolve on the set's network), so here only its form is checked.
Status hostPortKey(const TomlReader& r, const toml::table& t, std::string_view section,
                   std::string_view key, std::string& value) {
    Result<std::optional<std::string>> v = r.string(t, section, key);
    if (!v) return v.error();
    if (!*v) return {};
    if (hasControlCharacter(**v))
        return r.fail(t.get(key),
                      "'{}' holds a control character (a newline?); write HOST:PORT alone, e.g. "
                      "\"192.168.1.20:40000\"",
                      TomlReader::dotted(section, key));
    Result<std::pair<std::string, std::string>> split = splitHostPort(**v);
    if (!split)
        return r.fail(t.get(key), "'{}' is '{}': {} (use HOST:PORT, e.g. \"192.168.1.20:40000\")",
                      TomlReader::dotted(section, key), **v, split.message());
    value = **v;
    return {};
}

Status parseFreed(const TomlReader& r, const toml::table& t, FreedOutConfig& c) {
    if (Status st = r.checkKeys(t, "freed", {"out", "camera_id", "when_lost"}); !st) return st;
    if (Status st = hostPortKey(r, t, "freed", "out", c.out); !st) return st;
    if (c.out.empty())
        return r.fail(&t, "[freed] needs 'out' (where the packets go, e.g. out = \"HOST:40000\")");
    if (Status st = r.integerIn(t, "freed", "camera_id", c.cameraId, 0, 255); !st) return st;
    Result<std::optional<std::string>> lost = r.string(t, "freed", "when_lost");
    if (!lost) return lost.error();
    if (*lost && **lost != "nothing" && **lost != "hold")
        return r.fail(t.get("when_lost"), "'freed.when_lost' is '{}'; use nothing or hold", **lost);
    c.holdWhenLost = *lost && **lost == "hold";
    return {};
}

Status parseOpenTrackIo(const TomlReader& r, const toml::table& t, OpenTrackIoConfig& c) {
    if (Status st = r.checkKeys(t, "opentrackio", {"out", "source_number", "ttl"}); !st) return st;
    Result<std::optional<std::string>> out = r.string(t, "opentrackio", "out");
    if (!out) return out.error();
    if (!*out) return r.fail(&t, "[opentrackio] needs 'out' (\"multicast\" or \"HOST:PORT\")");
    if (**out == "multicast")
        c.out = **out;
    else if (Status st = hostPortKey(r, t, "opentrackio", "out", c.out); !st)
        return st;
    if (Status st = r.integerIn(t, "opentrackio", "source_number", c.sourceNumber, 1, 200); !st)
        return st;
    if (Status st = r.integerIn(t, "opentrackio", "ttl", c.multicastTtl, 1, 255); !st) return st;
    return {};
}

Status parseTimecode(const TomlReader& r, const toml::table& t, TimecodeConfig& c) {
    if (Status st =
            r.checkKeys(t, "timecode", {"source", "rate", "device", "channel", "sample_rate"});
        !st)
        return st;
    Result<std::optional<std::string>> source = r.string(t, "timecode", "source");
    if (!source) return source.error();
    if (*source && **source != "clock" && **source != "ltc")
        return r.fail(t.get("source"), "'timecode.source' is '{}'; use clock or ltc", **source);
    c.ltc = *source && **source == "ltc";
    Result<std::optional<std::string>> rate = r.string(t, "timecode", "rate");
    if (!rate) return rate.error();
    if (*rate) {
        if (Result<TimecodeRate> parsed = TimecodeRate::parse(**rate); !parsed)
            return r.fail(t.get("rate"), "'timecode.rate': {}", parsed.message());
        c.rate = **rate;
    }
    Result<std::optional<std::string>> device = r.string(t, "timecode", "device");
    if (!device) return device.error();
    if (*device) c.device = **device;
    if (Status st = r.integerIn(t, "timecode", "channel", c.channel, 0, 63); !st) return st;
    if (Status st = r.integerIn(t, "timecode", "sample_rate", c.sampleRate, 8000, 384000); !st)
        return st;
    return {};
}

Status parseWeb(const TomlReader& r, const toml::table& t, WebConfig& c) {
    if (Status st = r.checkKeys(t, "web",
                                {"listen", "token_file", "stream_fps", "stream_width",
                                 "jpeg_quality", "max_viewers", "host_names"});
        !st)
        return st;
    if (Status st = hostPortKey(r, t, "web", "listen", c.listen); !st) return st;
    if (c.listen.empty())
        return r.fail(&t, "[web] needs 'listen' (e.g. listen = \"0.0.0.0:8080\")");
    Result<std::optional<std::string>> token = r.string(t, "web", "token_file");
    if (!token) return token.error();
    // "" (docs/config-format.md): the unit's credential, as when the key is absent.
    if (*token && !(*token)->empty())
        c.tokenFile = (r.folder() / fs::path(**token)).lexically_normal().string();
    if (Status st = r.numberIn(t, "web", "stream_fps", c.streamFps, 0.0, 60.0, true); !st)
        return st;
    if (Status st = r.integerIn(t, "web", "stream_width", c.streamWidth, 64, 7680); !st) return st;
    if (Status st = r.integerIn(t, "web", "jpeg_quality", c.jpegQuality, 1, 100); !st) return st;
    if (Status st = r.integerIn(t, "web", "max_viewers", c.maxViewers, 1, 64); !st) return st;
    Result<std::optional<std::vector<std::string>>> names = r.strings(t, "web", "host_names");
    if (!names) return names.error();
    if (*names) c.hostNames = **names;
    for (const std::string& name : c.hostNames)
        if (name.empty() || hasControlCharacter(name) ||
            name.find_first_of(" /:") != std::string::npos)
            return r.fail(&t,
                          "'web.host_names' holds '{}', not a host name (e.g. \"previs.local\")",
                          hasControlCharacter(name) ? std::string("a control character") : name);
    return {};
}

}  // namespace

Status parseNetworkConfig(const TomlReader& r, const toml::table& root, NetworkConfig& config) {
    struct Section {
        const char* key;
        Status (*parse)(const TomlReader&, const toml::table&, NetworkConfig&);
    };
    const Section sections[] = {
        {"freed",
         [](auto& reader, auto& t, NetworkConfig& c) { return parseFreed(reader, t, c.freed); }},
        {"opentrackio",
         [](auto& reader, auto& t, NetworkConfig& c) {
             return parseOpenTrackIo(reader, t, c.opentrackio);
         }},
        {"timecode", [](auto& reader, auto& t,
                        NetworkConfig& c) { return parseTimecode(reader, t, c.timecode); }},
        {"web", [](auto& reader, auto& t, NetworkConfig& c) { return parseWeb(reader, t, c.web); }},
    };
    for (const Section& section : sections) {
        Result<const toml::table*> t = r.table(root, "", section.key);
        if (!t) return t.error();
        if (*t) {
            if (Status st = section.parse(r, **t, config); !st) return st;
        }
    }
    return {};
}

bool hasControlCharacter(std::string_view value) {
    return std::any_of(value.begin(), value.end(),
                       [](char c) { return std::iscntrl(static_cast<unsigned char>(c)) != 0; });
}

namespace {

// What is wrong with a token, or "" when nothing is.
std::string tokenProblem(const std::string& token) {
    if (token.empty()) return "is empty";
    if (hasControlCharacter(token)) return "holds a control character (a tab or a second line?)";
    if (std::isspace(static_cast<unsigned char>(token.front())) ||
        std::isspace(static_cast<unsigned char>(token.back())))
        return "starts or ends with a space, which an Authorization header cannot carry";
    if (token.size() < kMinWebTokenChars)
        return fmt::format("is {} characters long, under the {} required", token.size(),
                           kMinWebTokenChars);
    return {};
}

}  // namespace

Result<std::string> readWebToken(const WebConfig& web, const std::string& configPath) {
    std::string path = web.tokenFile;
    if (path.empty()) {
        const char* credentials = std::getenv("CREDENTIALS_DIRECTORY");
        if (!credentials) return std::string();
        path = (fs::path(credentials) / "web-token").string();
        std::error_code ec;
        if (!fs::exists(path, ec)) return std::string();
    }
    return readWebTokenFile(path, configPath,
                            web.tokenFile.empty() ? kWebTokenCredentialKey : "[web] token_file");
}

Result<std::string> readWebTokenFile(const std::string& path, const std::string& configPath,
                                     std::string_view key) {
    std::ifstream in(path);
    if (!in)
        return makeError(
            "{}: {}: cannot read the web token file '{}' (check it exists and is readable by the "
            "service)",
            configPath, key, path);
    std::stringstream text;
    text << in.rdbuf();
    // The file's line ending (echo, an editor) is not part of the token.
    std::string token = text.str();
    if (token.ends_with('\n')) token.pop_back();
    if (token.ends_with('\r')) token.pop_back();
    if (const std::string problem = tokenProblem(token); !problem.empty())
        return makeError(
            "{}: {}: the token in '{}' {}; write one line of at least {} characters without "
            "spaces, e.g. `openssl rand -hex 24 > {}`",
            configPath, key, path, problem, kMinWebTokenChars, path);
    return token;
}

}  // namespace previs
