#include "systemd/listen_fds.h"

#include <systemd/sd-daemon.h>

#include <algorithm>
#include <cstdlib>

#include "base/log.h"

namespace previs::systemd {

ListenFds ListenFds::fromEnvironment() {
    ListenFds out;
    char** names = nullptr;
    // unset_environment: the cameras' and the renderer's child libraries must not see them.
    const int count = sd_listen_fds_with_names(1, &names);
    if (count < 0) logWarning("systemd: the sockets passed cannot be read: {}", count);
    for (int i = 0; i < std::max(count, 0); ++i) {
        const std::string name = names && names[i] ? names[i] : "unknown";
        UniqueFD fd(SD_LISTEN_FDS_START + i);
        // A second socket of one name (two Listen lines in one socket unit): the first is used.
        if (!out.fds_.count(name)) out.fds_.emplace(name, std::move(fd));
        if (names) std::free(names[i]);
    }
    std::free(names);
    return out;
}

UniqueFD ListenFds::take(const std::string& name) {
    auto it = fds_.find(name);
    if (it == fds_.end()) return {};
    UniqueFD fd = std::move(it->second);
    fds_.erase(it);
    return fd;
}

}  // namespace previs::systemd
