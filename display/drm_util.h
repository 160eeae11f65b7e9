#pragma once

// libdrm handles owned by unique_ptr (STYLE.md ownership), and small naming helpers shared by
// the KMS output and the scanout readback. Internal to display/.

#include <xf86drm.h>
#include <xf86drmMode.h>

#include <memory>
#include <string>

namespace previs::drm {

template <auto FreeFn>
struct Free {
    template <typename T>
    void operator()(T* p) const {
        if (p) FreeFn(p);
    }
};

using ResourcesPtr = std::unique_ptr<drmModeRes, Free<drmModeFreeResources>>;
using ConnectorPtr = std::unique_ptr<drmModeConnector, Free<drmModeFreeConnector>>;
using EncoderPtr = std::unique_ptr<drmModeEncoder, Free<drmModeFreeEncoder>>;
using CrtcPtr = std::unique_ptr<drmModeCrtc, Free<drmModeFreeCrtc>>;
using PlaneResourcesPtr = std::unique_ptr<drmModePlaneRes, Free<drmModeFreePlaneResources>>;
using PlanePtr = std::unique_ptr<drmModePlane, Free<drmModeFreePlane>>;
using ObjectPropertiesPtr =
    std::unique_ptr<drmModeObjectProperties, Free<drmModeFreeObjectProperties>>;
using PropertyPtr = std::unique_ptr<drmModePropertyRes, Free<drmModeFreeProperty>>;
using AtomicReqPtr = std::unique_ptr<drmModeAtomicReq, Free<drmModeAtomicFree>>;
using FB2Ptr = std::unique_ptr<drmModeFB2, Free<drmModeFreeFB2>>;

// "card0" → "/dev/dri/card0"; a path stays as it is.
inline std::string cardPath(const std::string& card) {
    return card.find('/') == std::string::npos ? "/dev/dri/" + card : card;
}

// The kernel's connector name, as in sysfs and `modetest`: "Virtual-1", "HDMI-A-1".
inline std::string connectorName(const drmModeConnector& c) {
    const char* type = drmModeGetConnectorTypeName(c.connector_type);
    return std::string(type ? type : "Unknown") + "-" + std::to_string(c.connector_type_id);
}

}  // namespace previs::drm
