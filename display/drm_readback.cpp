#include "display/drm_readback.h"

#include <drm_fourcc.h>
#include <fcntl.h>
#include <sys/mman.h>

#include <cerrno>
#include <cstring>

#include "base/unique_fd.h"
#include "display/drm_util.h"

namespace previs {

Result<std::vector<uint32_t>> readScanout(const std::string& card, uint32_t* width,
                                          uint32_t* height) {
    const std::string path = drm::cardPath(card);
    // Read-write: MAP_DUMB needs it. Not master while previsd is (and harmless if it becomes
    // one: nothing is committed).
    UniqueFD fd(::open(path.c_str(), O_RDWR | O_CLOEXEC));
    if (!fd.isValid()) return makeError("{}: cannot open ({})", path, std::strerror(errno));
    drm::ResourcesPtr res(drmModeGetResources(fd.get()));
    if (!res) return makeError("{}: not a KMS device", path);

    uint32_t fbId = 0;
    for (int i = 0; i < res->count_crtcs && !fbId; ++i) {
        drm::CrtcPtr crtc(drmModeGetCrtc(fd.get(), res->crtcs[i]));
        if (crtc && crtc->mode_valid && crtc->buffer_id) fbId = crtc->buffer_id;
    }
    if (!fbId) return makeError("{}: no active CRTC shows a framebuffer", path);

    drm::FB2Ptr fb(drmModeGetFB2(fd.get(), fbId));
    if (!fb) return makeError("{}: GETFB2 of fb {} failed ({})", path, fbId, std::strerror(errno));
    if (!fb->handles[0]) return makeError("{}: GETFB2 gave no buffer handle: run as root", path);
    // GETFB2 created a GEM handle in our file: close it whatever happens next.
    struct HandleCloser {
        int fd;
        uint32_t handle;
        ~HandleCloser() {
            drm_gem_close c = {};
            c.handle = handle;
            drmIoctl(fd, DRM_IOCTL_GEM_CLOSE, &c);
        }
    } closer{fd.get(), fb->handles[0]};
    if (fb->pixel_format != DRM_FORMAT_XRGB8888 && fb->pixel_format != DRM_FORMAT_ARGB8888)
        return makeError("{}: fb {} has format {:#x}, not XRGB8888", path, fbId, fb->pixel_format);

    drm_mode_map_dumb map = {};
    map.handle = fb->handles[0];
    if (drmIoctl(fd.get(), DRM_IOCTL_MODE_MAP_DUMB, &map) != 0)
        return makeError("{}: cannot map fb {} ({})", path, fbId, std::strerror(errno));
    const size_t size = size_t(fb->pitches[0]) * fb->height + fb->offsets[0];
    void* p = mmap(nullptr, size, PROT_READ, MAP_SHARED, fd.get(), map.offset);
    if (p == MAP_FAILED)
        return makeError("{}: cannot mmap fb {} ({})", path, fbId, std::strerror(errno));

    std::vector<uint32_t> pixels(size_t(fb->width) * fb->height);
    const auto* base = static_cast<const uint8_t*>(p) + fb->offsets[0];
    for (uint32_t y = 0; y < fb->height; ++y)
        std::memcpy(&pixels[size_t(y) * fb->width], base + size_t(y) * fb->pitches[0],
                    size_t(fb->width) * 4);
    munmap(p, size);
    *width = fb->width;
    *height = fb->height;
    return pixels;
}

}  // namespace previs
