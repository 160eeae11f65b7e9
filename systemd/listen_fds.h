#pragma once

// Sockets systemd made for previsd (socket activation, sd_listen_fds_with_names(3)): with them
// the unit keeps PrivateNetwork=yes and no AF_INET of its own, yet serves the web page and sends
// FreeD and OpenTrackIO (docs/systemd.md, "The set's network"). Each socket unit names its
// socket with FileDescriptorName=: "web", "freed", "opentrackio".

#include <map>
#include <string>

#include "base/unique_fd.h"

namespace previs::systemd {

class ListenFds {
public:
    // The sockets passed to this process (none outside systemd, or for another pid); each fd is
    // owned from here on and closed unless taken.
    static ListenFds fromEnvironment();

    // The socket named `name`, once; an invalid UniqueFD when none was passed.
    UniqueFD take(const std::string& name);
    bool empty() const { return fds_.empty(); }

private:
    std::map<std::string, UniqueFD> fds_;
};

}  // namespace previs::systemd
