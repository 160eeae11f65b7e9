#pragma once

// The unit's network, opened only as far as the config uses it (issue 39, docs/systemd.md).
// previsd.service has no network at all (PrivateNetwork=yes, IPAddressDeny=any, only AF_UNIX and
// AF_NETLINK sockets), and keeps it that way with every network feature on: systemd makes the
// sockets — one socket unit per feature, in the host's network, each with its own IP allow list
// — and hands them to previsd (socket activation, systemd/listen_fds.h). `previsd --config FILE
// --network-units DIR` writes those units and the service's drop-in naming them, for
// /etc/systemd/system.

#include <map>
#include <string>

#include "base/result.h"
#include "config/network_config.h"

namespace previs {

struct NetworkUnitOptions {
    // Where the unit's credential `web-token` is read from (LoadCredential=): the file
    // `web-token` beside the config (/etc/previs/web-token on the box); "" = none.
    std::string webTokenSource;
    // [tracking] listen: where a tracker's FreeD packets arrive ("" = none).
    std::string freedInListen;
};

// File name (relative to /etc/systemd/system) → content: `previsd-web.socket`,
// `previsd-freed.socket`, `previsd-opentrackio.socket`, `previsd-freed-in.socket` as configured,
// and
// `previsd.service.d/network.conf` (always: without a network feature it names no socket, so a
// stale one is replaced). Host names are resolved now (systemd's IP filters take addresses
// only): an unresolvable name is an error naming its key.
Result<std::map<std::string, std::string>> networkUnits(const NetworkConfig& network,
                                                        const NetworkUnitOptions& options = {});

}  // namespace previs
