#include "daemon/network_dropin.h"

#include <netdb.h>
#include <sys/socket.h>

#include <filesystem>
#include <memory>
#include <set>

#include "net/opentrackio.h"
#include "net/udp_socket.h"

namespace previs {
namespace {

// Every address `host` resolves to, numeric ("" and "0.0.0.0"/"::": any).
Result<std::set<std::string>> addressesOf(const std::string& host, const char* key) {
    addrinfo hints{};
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    addrinfo* found = nullptr;
    if (int rc = ::getaddrinfo(host.c_str(), nullptr, &hints, &found); rc != 0)
        return makeError("{} '{}' does not resolve: {} (use an address, or resolve it on the set)",
                         key, host, ::gai_strerror(rc));
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

Status addHost(const std::string& hostPort, const char* key, std::set<std::string>& allow) {
    Result<std::pair<std::string, std::string>> split = splitHostPort(hostPort);
    if (!split) return makeError("{}: {}", key, split.message());
    Result<std::set<std::string>> addresses = addressesOf(split->first, key);
    if (!addresses) return addresses.error();
    allow.insert(addresses->begin(), addresses->end());
    return {};
}

}  // namespace

Result<std::string> networkDropIn(const NetworkConfig& network, const DropInOptions& options) {
    std::string text =
        "# Written by `previsd --config FILE --network-dropin` for the config's network "
        "features\n# (docs/systemd.md). Install as "
        "/etc/systemd/system/previsd.service.d/network.conf,\n# then `systemctl daemon-reload`.\n";
    if (!network.usesNetwork()) return text + "# No network feature is configured.\n";
    std::set<std::string> allow;
    if (!network.freed.out.empty()) {
        if (Status st = addHost(network.freed.out, "[freed] out", allow); !st) return st.error();
    }
    const OpenTrackIoConfig& otio = network.opentrackio;
    if (otio.out == "multicast")
        allow.insert(openTrackIOMulticastGroup(uint8_t(otio.sourceNumber)));
    else if (!otio.out.empty()) {
        if (Status st = addHost(otio.out, "[opentrackio] out", allow); !st) return st.error();
    }
    text += "[Service]\nPrivateNetwork=no\nRestrictAddressFamilies=AF_INET AF_INET6\n";
    if (!network.web.listen.empty()) {
        // Viewers come from the set's own networks: the private and link-local ranges, never
        // the internet.
        allow.insert({"localhost", "link-local", "10.0.0.0/8", "172.16.0.0/12", "192.168.0.0/16",
                      "fc00::/7"});
        Result<std::pair<std::string, std::string>> listen = splitHostPort(network.web.listen);
        if (!listen) return makeError("[web] listen: {}", listen.message());
        text += fmt::format("SocketBindAllow=tcp:{}\n", listen->second);
        // A missing credential file would stop the unit from starting: without one the page
        // is for viewing only.
        std::error_code ec;
        if (network.web.tokenFile.empty() && !options.webTokenSource.empty() &&
            std::filesystem::is_regular_file(options.webTokenSource, ec))
            text += fmt::format("LoadCredential=web-token:{}\n", options.webTokenSource);
        else if (network.web.tokenFile.empty())
            text +=
                fmt::format("# No {}: the web page is for viewing only.\n", options.webTokenSource);
    }
    // No socket may listen but the web monitor's: the senders never bind (connect() picks
    // their port), and the bind hook sees only bind().
    text += "SocketBindDeny=any\n";
    // The unit's IPAddressDeny=any stays; these are the exceptions.
    std::string list;
    for (const std::string& a : allow) list += (list.empty() ? "" : " ") + a;
    text += fmt::format("IPAddressAllow={}\n", list);
    return text;
}

}  // namespace previs
