// Compiles only while the settings headers stay free of Vulkan: the service's config and the
// command line parse into them without the renderer's classes (render/render_settings.h).
#include "config/service_config.h"
#include "render/render_settings.h"

#ifdef VULKAN_CORE_H_
#error \
    "a settings header includes the Vulkan headers; keep them in render/render_settings.h's plain structs"
#endif
