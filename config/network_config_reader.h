#pragma once

// Internal to the service config (it exposes toml++): the reader of config/network_config.h's
// sections, called by loadServiceConfig.

#include "base/toml_reader.h"
#include "config/network_config.h"

namespace previs {

// Reads the optional sections [freed], [opentrackio], [timecode] and [web] of `root`.
Status parseNetworkConfig(const TomlReader& reader, const toml::table& root, NetworkConfig& config);

}  // namespace previs
