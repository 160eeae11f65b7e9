#include "daemon/network_dropin.h"

#include <netdb.h>
#include <sys/socket.h>

#include <filesystem>
#include <memory>
#include <set>
#include <vector>

#include "net/opentrackio.h"
#include "net/udp_socket.h"

namespace previs {
namespace {

constexpr const char* kHeader =
    "# Written by `previsd --config FILE --network-units DIR` for the config's network features\n"
    "# (docs/systemd.md): the service keeps no network of its own; systemd makes this socket in\n"
    "# the host's network and hands it over.\n";

// Viewers of the web page and trackers come from the set's own networks, never the internet.
constexpr const char* kSetNetworks =
    "localhost link-local 10.0.0.0/8 172.16.0.0/12 192.168.0.0/16 fc00::/7";

std::string joined(const std::set<std::string>& items) {
    std::string out;
    for (const std::string& item : items) out += (out.empty() ? "" : " ") + item;
    return out;
}

// Every address `host` resolves to, numeric.
Result<std::set<std::string>> addressesOf(const std::string& host, const char* key) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    addrinfo* found = nullptr;
    if (int rc = ::getaddrinfo(host.c_str(), nullptr, &hints, &found); rc != 0)
        return makeError("{} '{}' does not resolve: {} (use an address)", key, host,
                         ::gai_strerror(rc));
    std::unique_ptr<addrinfo, decltype(&::freeaddrinfo)> owned(found, ::freeaddrinfo);
    std::set<std::string> out;
    for (const addrinfo* a = found; a; a = a->ai_next) {
        char text[NI_MAXHOST];
        if (::getnameinfo(a->ai_addr, a->ai_addrlen, text, sizeof text, nullptr, 0,
                          NI_NUMERICHOST) == 0)
            out.insert(text);
    }
    return out;
}

// A socket unit handing previsd one socket named `name`. BindsTo=: the socket lives only while
// previsd does, so a packet never starts a previsd an operator stopped or that exited 2 (a config
// error); `systemctl start previsd` brings its sockets back. FreeBind=: an address that is not up
// yet at boot (a DHCP lease, a cable plugged in later) does not keep previsd from starting.
std::string socketUnit(const std::string& what, const std::string& listen, const std::string& name,
                       const std::string& allow) {
    return fmt::format(
        "{}[Unit]\nDescription=previs: {}\nBindsTo=previsd.service\n\n[Socket]\n{}\n"
        "FreeBind=yes\nFileDescriptorName={}\nService=previsd.service\nIPAddressDeny=any\n"
        "IPAddressAllow={}\n",
        kHeader, what, listen, name, allow);
}

// The sending socket for `hostPort` ([freed] out, [opentrackio] out): bound, as a socket unit
// must be, to the destination's port on any address of its family.
Result<std::string> senderUnit(const std::string& what, const std::string& hostPort,
                               const std::string& name, const char* key) {
    Result<std::pair<std::string, std::string>> split = splitHostPort(hostPort);
    if (!split) return makeError("{}: {}", key, split.message());
    Result<std::set<std::string>> addresses = addressesOf(split->first, key);
    if (!addresses) return addresses.error();
    const bool v6 = addresses->begin()->find(':') != std::string::npos;
    return socketUnit(
        what,
        fmt::format("ListenDatagram={}:{}\nReusePort=yes", v6 ? "[::]" : "0.0.0.0", split->second),
        name, joined(*addresses));
}

}  // namespace

Result<std::map<std::string, std::string>> networkUnits(const NetworkConfig& network,
                                                        const NetworkUnitOptions& options) {
    // Each value is written into a unit as a setting's value: a newline would add a setting.
    const std::pair<const char*, const std::string&> written[] = {
        {"[freed] out", network.freed.out},
        {"[opentrackio] out", network.opentrackio.out},
        {"[tracking] listen", options.freedInListen},
        {"[web] listen", network.web.listen},
        {"the config's folder", options.webTokenSource}};
    for (const auto& [key, value] : written)
        if (hasControlCharacter(value))
            return makeError(
                "{} holds a control character (a newline?), which would end up in a systemd unit "
                "as a setting of its own; write it on one line",
                key);
    std::map<std::string, std::string> units;
    std::vector<std::string> sockets;
    if (!network.freed.out.empty()) {
        Result<std::string> unit =
            senderUnit("FreeD out (the tracked camera)", network.freed.out, "freed", "[freed] out");
        if (!unit) return unit.error();
        units["previsd-freed.socket"] = *unit;
        sockets.push_back("previsd-freed.socket");
    }
    const OpenTrackIoConfig& otio = network.opentrackio;
    if (!otio.out.empty()) {
        const std::string to =
            otio.out == "multicast"
                ? fmt::format("{}:{}", openTrackIOMulticastGroup(uint8_t(otio.sourceNumber)),
                              kOpenTrackIOPort)
                : otio.out;
        Result<std::string> unit = senderUnit("OpenTrackIO out (the tracked camera)", to,
                                              "opentrackio", "[opentrackio] out");
        if (!unit) return unit.error();
        units["previsd-opentrackio.socket"] = *unit;
        sockets.push_back("previsd-opentrackio.socket");
    }
    if (!options.freedInListen.empty()) {
        // Trackers on the set's networks send to it; a packet's content is checked, not trusted.
        units["previsd-freed-in.socket"] =
            socketUnit("FreeD in (a tracker's packets, docs/freed.md)",
                       "ListenDatagram=" + options.freedInListen, "freed-in", kSetNetworks);
        sockets.push_back("previsd-freed-in.socket");
    }
    std::string credential;
    if (!network.web.listen.empty()) {
        units["previsd-web.socket"] =
            socketUnit("the monitor page (docs/web-monitor.md)",
                       "ListenStream=" + network.web.listen, "web", kSetNetworks);
        sockets.push_back("previsd-web.socket");
        // A missing credential file would stop the unit from starting: without one the page is
        // for viewing only.
        std::error_code ec;
        if (network.web.tokenFile.empty() && !options.webTokenSource.empty() &&
            std::filesystem::is_regular_file(options.webTokenSource, ec))
            credential = "LoadCredential=web-token:" + options.webTokenSource + "\n";
    }
    std::string names;
    for (const std::string& s : sockets) names += (names.empty() ? "" : " ") + s;
    std::string dropIn =
        "# Written by `previsd --config FILE --network-units DIR` (docs/systemd.md).\n";
    if (!sockets.empty())
        dropIn += fmt::format("[Unit]\nRequires={0}\nAfter={0}\n\n[Service]\nSockets={0}\n{1}",
                              names, credential);
    else
        dropIn += "# No network feature is configured: the unit stays as installed.\n";
    units["previsd.service.d/network.conf"] = dropIn;
    return units;
}

}  // namespace previs
