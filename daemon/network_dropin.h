#pragma once

// The unit's network, opened only as far as the config uses it (issue 39, docs/systemd.md). The
// installed previsd.service has no network at all (PrivateNetwork=yes, IPAddressDeny=any, only
// AF_UNIX and AF_NETLINK sockets). `previsd --config FILE --network-dropin` prints the drop-in
// that the config's network features need — the host's network, IPv4/IPv6 sockets, traffic to
// and from the configured addresses only, a listening socket only on [web]'s port, the web token
// as a credential — for /etc/systemd/system/previsd.service.d/network.conf. With no network
// feature configured the drop-in changes nothing.

#include <string>

#include "base/result.h"
#include "daemon/network_config.h"

namespace previs {

struct DropInOptions {
    // Where the unit's credential `web-token` is read from (LoadCredential=): the file
    // `web-token` beside the config (/etc/previs/web-token on the box); "" = none.
    std::string webTokenSource;
};

// The drop-in's text. Host names are resolved now (systemd's IP filters take addresses only):
// an unresolvable name is an error naming its key.
Result<std::string> networkDropIn(const NetworkConfig& network, const DropInOptions& options = {});

}  // namespace previs
