// Run by systemd as previsd.service's ExecStart (sandbox_vm.sh swaps it in with a drop-in), inside
// the test VM: does, with each device, the kind of thing previsd does, under the unit's real
// sandbox (DynamicUser, device cgroup, seccomp filter, namespaces). Prints one line per check;
// exits 1 if any failed. Plain C APIs on purpose: it checks the sandbox, not previs' wrappers.

#include <fcntl.h>
#include <gpiod.h>
#include <linux/media.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <unistd.h>
#include <xf86drm.h>
#include <xf86drmMode.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

#include "base/unique_fd.h"

namespace {

int gFailures = 0;

void report(bool ok, const char* what, int err = 0) {
    std::printf("%s %s%s%s\n", ok ? "ok  " : "FAIL", what, err ? ": " : "",
                err ? std::strerror(err) : "");
    if (!ok) ++gFailures;
}

previs::UniqueFD openNode(const char* path, int flags) {
    previs::UniqueFD fd(::open(path, flags | O_CLOEXEC));
    if (!fd.isValid()) {
        char what[128];
        std::snprintf(what, sizeof(what), "open %s", path);
        report(false, what, errno);
    }
    return fd;
}

// Capture: format, mmap buffers, stream two frames (V4L2 ioctls and mmap through seccomp).
void camera(const char* path) {
    previs::UniqueFD fd = openNode(path, O_RDWR);
    if (!fd.isValid()) return;
    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    fmt.fmt.pix.width = 640;
    fmt.fmt.pix.height = 360;
    fmt.fmt.pix.pixelformat = V4L2_PIX_FMT_YUYV;
    if (ioctl(fd.get(), VIDIOC_S_FMT, &fmt) != 0) return report(false, "VIDIOC_S_FMT", errno);
    v4l2_requestbuffers rb{};
    rb.count = 2;
    rb.type = fmt.type;
    rb.memory = V4L2_MEMORY_MMAP;
    if (ioctl(fd.get(), VIDIOC_REQBUFS, &rb) != 0) return report(false, "VIDIOC_REQBUFS", errno);
    for (unsigned i = 0; i < rb.count; ++i) {
        v4l2_buffer b{};
        b.type = fmt.type;
        b.memory = V4L2_MEMORY_MMAP;
        b.index = i;
        if (ioctl(fd.get(), VIDIOC_QUERYBUF, &b) != 0) return report(false, "QUERYBUF", errno);
        void* p = mmap(nullptr, b.length, PROT_READ, MAP_SHARED, fd.get(), b.m.offset);
        if (p == MAP_FAILED) return report(false, "mmap capture buffer", errno);
        munmap(p, b.length);
        if (ioctl(fd.get(), VIDIOC_QBUF, &b) != 0) return report(false, "QBUF", errno);
    }
    int type = fmt.type;
    if (ioctl(fd.get(), VIDIOC_STREAMON, &type) != 0) return report(false, "STREAMON", errno);
    for (int n = 0; n < 2; ++n) {
        v4l2_buffer b{};
        b.type = fmt.type;
        b.memory = V4L2_MEMORY_MMAP;
        if (ioctl(fd.get(), VIDIOC_DQBUF, &b) != 0) return report(false, "DQBUF", errno);
        if (ioctl(fd.get(), VIDIOC_QBUF, &b) != 0) return report(false, "QBUF", errno);
    }
    ioctl(fd.get(), VIDIOC_STREAMOFF, &type);
    report(true, "camera: streamed 2 frames from /dev/video0");
}

void media(const char* path) {
    previs::UniqueFD fd = openNode(path, O_RDWR);
    if (!fd.isValid()) return;
    media_device_info info{};
    int ok = ioctl(fd.get(), MEDIA_IOC_DEVICE_INFO, &info);
    report(ok == 0, "media: MEDIA_IOC_DEVICE_INFO on /dev/media0", ok ? errno : 0);
}

// Display: become DRM master (first opener, no capability) and read the KMS resources.
void display(const char* path) {
    previs::UniqueFD fd = openNode(path, O_RDWR);
    if (!fd.isValid()) return;
    int master = drmSetMaster(fd.get());
    report(master == 0 && drmIsMaster(fd.get()), "display: DRM master on /dev/dri/card0",
           master ? errno : 0);
    std::unique_ptr<drmModeRes, decltype(&drmModeFreeResources)> res(drmModeGetResources(fd.get()),
                                                                     drmModeFreeResources);
    report(res && res->count_connectors > 0, "display: KMS resources with a connector",
           res ? 0 : errno);
}

// Button: request a line as input and read it (libgpiod 1.6, as io/ does).
void button(const char* path) {
    std::unique_ptr<gpiod_chip, decltype(&gpiod_chip_close)> chip(gpiod_chip_open(path),
                                                                  gpiod_chip_close);
    if (!chip) return report(false, "gpio: open /dev/gpiochip0", errno);
    gpiod_line* line = gpiod_chip_find_line(chip.get(), "mode-button");
    if (!line) return report(false, "gpio: line mode-button", errno);
    if (gpiod_line_request_both_edges_events(line, "previs-probe") != 0)
        return report(false, "gpio: request mode-button for edge events", errno);
    int value = gpiod_line_get_value(line);
    gpiod_line_release(line);
    report(value >= 0, "gpio: mode-button requested for edges and read", value < 0 ? errno : 0);
}

// The device cgroup must refuse what DeviceAllow= does not list, even where file permissions
// allow it (sandbox_vm.sh made /dev/uinput and the input event node 0666): EPERM from the cgroup,
// not EACCES. previsd opens no input device, so none is let through (a keyboard is one).
void refused(const char* path) {
    int fd = ::open(path, O_RDWR | O_CLOEXEC);
    int err = errno;
    if (fd >= 0) ::close(fd);
    char what[160];
    std::snprintf(what, sizeof(what), "device cgroup refuses %s (mode 0666) with EPERM", path);
    report(fd < 0 && err == EPERM, what, fd < 0 ? err : 0);
}

// llvmpipe/lavapipe JIT-compiles shaders into writable, then executable memory: the reason the
// unit leaves MemoryDenyWriteExecute= off.
void jitMemory() {
    void* p =
        mmap(nullptr, 4096, PROT_READ | PROT_WRITE | PROT_EXEC, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    report(p != MAP_FAILED, "writable+executable memory (llvmpipe JIT)",
           p == MAP_FAILED ? errno : 0);
    if (p != MAP_FAILED) munmap(p, 4096);
}

}  // namespace

int main() {
    jitMemory();
    camera("/dev/video0");
    media("/dev/media0");
    display("/dev/dri/card0");
    button("/dev/gpiochip0");
    refused("/dev/input/event0");
    refused("/dev/uinput");
    std::printf("%d failure(s)\n", gFailures);
    return gFailures ? 1 : 0;
}
