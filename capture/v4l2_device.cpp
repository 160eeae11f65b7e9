#include "capture/v4l2_device.h"

#include <fcntl.h>
#include <linux/videodev2.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <span>
#include <utility>

#include "base/log.h"
#include "capture/pixel_format.h"

namespace previs {

namespace {

// ioctl restarted on EINTR (a signal to the service must not look like a device error).
int xioctl(int fd, unsigned long request, void* arg) {
    int r;
    do {
        r = ::ioctl(fd, request, arg);
    } while (r < 0 && errno == EINTR);
    return r < 0 ? -errno : 0;
}

// The errors that mean the hardware is gone rather than misused.
bool isGone(int err) { return err == ENODEV || err == ENXIO || err == EIO || err == EPIPE; }

// Finds the control `name` (either form, v4l2ControlKey) into `q`; false with `names` listing the
// controls the device has.
bool findControl(int fd, std::string_view name, v4l2_query_ext_ctrl& q, std::string& names) {
    q = {};
    q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
    while (xioctl(fd, VIDIOC_QUERY_EXT_CTRL, &q) == 0) {
        const std::string_view qname(q.name);
        if (q.type != V4L2_CTRL_TYPE_CTRL_CLASS) {
            if (v4l2ControlKey(qname) == v4l2ControlKey(name)) return true;
            names += (names.empty() ? "'" : ", '") + std::string(qname) + "'";
        }
        q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
    }
    return false;
}

uint64_t monotonicNowNs() {
    timespec ts{};
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return uint64_t(ts.tv_sec) * 1'000'000'000ull + uint64_t(ts.tv_nsec);
}

}  // namespace

std::string v4l2ControlKey(std::string_view name) {
    // Comparing these forms accepts both the driver's name and v4l2-ctl's, in any case.
    std::string key;
    for (char ch : name) {
        if (std::isalnum(uint8_t(ch)))
            key += char(std::tolower(uint8_t(ch)));
        else if (!key.empty() && key.back() != '_')
            key += '_';
    }
    while (!key.empty() && key.back() == '_') key.pop_back();
    return key;
}

V4L2Device::Mapping::Mapping(Mapping&& o) noexcept
    : data(std::exchange(o.data, nullptr)), length(std::exchange(o.length, 0)) {}

V4L2Device::Mapping::~Mapping() {
    if (data) ::munmap(data, length);
}

V4L2Device::V4L2Device(std::string path) : path_(std::move(path)) {}

V4L2Device::~V4L2Device() { stop(); }

std::string V4L2Device::listFormats(int fd) {
    std::string out;
    for (uint32_t i = 0;; ++i) {
        v4l2_fmtdesc desc{};
        desc.index = i;
        desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        if (xioctl(fd, VIDIOC_ENUM_FMT, &desc) < 0) break;
        out += (out.empty() ? "" : ", ") + fourccToString(desc.pixelformat);
    }
    return out.empty() ? "none" : out;
}

Result<std::unique_ptr<V4L2Device>> V4L2Device::create(const V4L2Config& config) {
    std::unique_ptr<V4L2Device> dev(new V4L2Device(config.device));
    dev->keepCaptured_ = config.keepCaptured;
    // Non-blocking so DQBUF never hangs: readiness comes from poll() with a timeout.
    dev->fd_.reset(::open(config.device.c_str(), O_RDWR | O_NONBLOCK | O_CLOEXEC));
    if (!dev->fd_.isValid()) {
        const int err = errno;
        if (err == ENOENT || err == ENODEV || err == ENXIO)
            return makeError(
                "camera {}: no such device (unplugged? `ls /dev/video*` lists the "
                "cameras present)",
                config.device);
        if (err == EACCES || err == EPERM)
            return makeError(
                "camera {}: permission denied (add the service user to the "
                "'video' group)",
                config.device);
        if (err == EBUSY)
            return makeError("camera {}: busy (another program is streaming from it)",
                             config.device);
        return makeError("camera {}: cannot open: {}", config.device, std::strerror(err));
    }
    if (Status s = dev->configure(config); !s) return s.error();
    for (const auto& [control, value] : config.controls)
        if (Status s = dev->setControl(control, value); !s)
            return makeError(
                "camera {}: control '{}' = {} not applied ({}); its pictures would not be what "
                "the config's radiometry promises",
                config.device, control, value, s.message());
    if (config.bracket)
        if (Status s = dev->setUpBracket(*config.bracket, config.controls); !s) return s.error();
    return dev;
}

Status V4L2Device::setUpBracket(const ExposureBracketConfig& bracket,
                                const std::vector<std::pair<std::string, int32_t>>& controls) {
    // Queried after the config's controls were set: whether an automatic mode still owns the
    // control (INACTIVE) depends on them.
    v4l2_query_ext_ctrl q{};
    std::string names;
    if (!findControl(fd_.get(), bracket.control, q, names))
        return makeError(
            "camera {} ({}): the bracket cycles '{}', but the camera has no such control (it has: "
            "{}); name one that scales the light linearly in [cameras.fisheye.bracket] control",
            path_, card_, bracket.control, names.empty() ? "none" : names);
    if (q.type != V4L2_CTRL_TYPE_INTEGER ||
        (q.flags & (V4L2_CTRL_FLAG_READ_ONLY | V4L2_CTRL_FLAG_DISABLED)))
        return makeError(
            "camera {} ({}): '{}' is not a settable integer control; it cannot be "
            "bracketed",
            path_, card_, q.name);
    if (q.flags & V4L2_CTRL_FLAG_INACTIVE)
        return makeError(
            "camera {} ({}): '{}' is inactive: an automatic mode still sets it, so the bracket's "
            "exposures would not be what the frames are labelled; put the camera in manual mode "
            "in its controls first (e.g. auto_exposure = 1, manual; `v4l2-ctl -d {} -l` shows "
            "which control owns it)",
            path_, card_, q.name, path_);
    std::optional<int64_t> base;
    for (const auto& [name, value] : controls)
        if (v4l2ControlKey(name) == v4l2ControlKey(bracket.control)) base = value;
    if (!base)
        return makeError(
            "camera {}: the bracket cycles '{}' from its configured value, but the camera's "
            "controls do not set it; add it (the exposure the radiometry was calibrated at)",
            path_, bracket.control);
    Result<std::vector<int64_t>> values = planExposureSteps(
        bracket.stops, *base, ControlRange{q.minimum, q.maximum, int64_t(q.step)}, path_, q.name);
    if (!values) return values.error();
    bracketControlId_ = q.id;
    bracketControlName_ = q.name;
    bracketValues_ = std::move(*values);
    bracketStops_ = bracket.stops;
    cycle_.emplace(bracket.stops.size(), bracket.framesPerStep);
    std::string steps;
    for (size_t i = 0; i < bracketValues_.size(); ++i)
        steps += fmt::format("{}{} ({:+g})", i ? ", " : "", bracketValues_[i], bracketStops_[i]);
    logInfo("camera {}: bracketing '{}' through {}, each held {} frames", path_, q.name, steps,
            std::clamp(bracket.framesPerStep, 1, kMaxFramesPerStep));
    return {};
}

Status V4L2Device::setBracketStep(size_t step) {
    v4l2_control c{bracketControlId_, int32_t(bracketValues_[step])};
    if (int r = xioctl(fd_.get(), VIDIOC_S_CTRL, &c); r < 0)
        return isGone(-r) ? Status(vanished("S_CTRL", -r))
                          : Status(makeError("camera {}: setting '{}' to {} for the bracket "
                                             "failed: {}",
                                             path_, bracketControlName_, bracketValues_[step],
                                             std::strerror(-r)));
    return {};
}

Status V4L2Device::configure(const V4L2Config& config) {
    const int fd = fd_.get();
    v4l2_capability cap{};
    if (int r = xioctl(fd, VIDIOC_QUERYCAP, &cap); r < 0)
        return makeError("camera {}: not a V4L2 device ({})", path_, std::strerror(-r));
    card_ = reinterpret_cast<const char*>(cap.card);
    // device_caps describes this node; capabilities the whole driver (several nodes).
    const uint32_t caps =
        (cap.capabilities & V4L2_CAP_DEVICE_CAPS) ? cap.device_caps : cap.capabilities;
    if (!(caps & V4L2_CAP_VIDEO_CAPTURE)) {
        if (caps & V4L2_CAP_VIDEO_CAPTURE_MPLANE)
            return makeError(
                "camera {} ({}): multi-planar capture is not supported; use a "
                "single-planar node or the libcamera source",
                path_, card_);
        return makeError(
            "camera {} ({}): not a video capture device (a metadata or output "
            "node? try another /dev/videoN)",
            path_, card_);
    }
    if (!(caps & V4L2_CAP_STREAMING))
        return makeError("camera {} ({}): does not support streaming I/O", path_, card_);

    const uint32_t fourcc = config.fourcc ? config.fourcc : V4L2_PIX_FMT_YUYV;
    if (!isSupportedFormat(fourcc))
        return makeError("camera {}: pixel format {} cannot be converted to RGB (supported: {})",
                         path_, fourccToString(fourcc), supportedFormatList());
    bool offered = false;
    for (uint32_t i = 0; !offered; ++i) {
        v4l2_fmtdesc desc{};
        desc.index = i;
        desc.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        if (xioctl(fd, VIDIOC_ENUM_FMT, &desc) < 0) break;
        offered = desc.pixelformat == fourcc;
    }
    if (!offered)
        return makeError("camera {} ({}): does not offer pixel format {}; it offers: {}", path_,
                         card_, fourccToString(fourcc), listFormats(fd));

    v4l2_format fmt{};
    fmt.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    fmt.fmt.pix.width = config.width;
    fmt.fmt.pix.height = config.height;
    fmt.fmt.pix.pixelformat = fourcc;
    fmt.fmt.pix.field = V4L2_FIELD_NONE;
    if (int r = xioctl(fd, VIDIOC_S_FMT, &fmt); r < 0)
        return makeError("camera {}: setting {} {}x{} failed: {}", path_, fourccToString(fourcc),
                         config.width, config.height, std::strerror(-r));
    // S_FMT adjusts rather than fails; calibration and scene setup assume the configured size,
    // so a different one is an error, not a silent change.
    if (fmt.fmt.pix.pixelformat != fourcc)
        return makeError("camera {}: asked for {}, the driver chose {}", path_,
                         fourccToString(fourcc), fourccToString(fmt.fmt.pix.pixelformat));
    if (fmt.fmt.pix.width != config.width || fmt.fmt.pix.height != config.height)
        return makeError(
            "camera {}: {} {}x{} is not available (the driver offers {}x{}); set "
            "the camera's width/height in the config to a supported size",
            path_, fourccToString(fourcc), config.width, config.height, fmt.fmt.pix.width,
            fmt.fmt.pix.height);
    if (fmt.fmt.pix.field != V4L2_FIELD_NONE && fmt.fmt.pix.field != V4L2_FIELD_ANY)
        return makeError("camera {}: interlaced video is not supported", path_);
    width_ = fmt.fmt.pix.width;
    height_ = fmt.fmt.pix.height;
    fourcc_ = fourcc;
    stride_ = fmt.fmt.pix.bytesperline;

    v4l2_streamparm parm{};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (config.fps > 0) {
        if (xioctl(fd, VIDIOC_G_PARM, &parm) == 0 &&
            (parm.parm.capture.capability & V4L2_CAP_TIMEPERFRAME)) {
            // The interval as a fraction with enough resolution for rates like 29.97.
            parm.parm.capture.timeperframe.numerator = 1000;
            parm.parm.capture.timeperframe.denominator = uint32_t(std::lround(config.fps * 1000));
            if (int r = xioctl(fd, VIDIOC_S_PARM, &parm); r < 0)
                return makeError("camera {}: setting {} fps failed: {}", path_, config.fps,
                                 std::strerror(-r));
        } else {
            logWarning("camera {}: the driver does not set frame rates; using its default", path_);
        }
    }
    parm = {};
    parm.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (xioctl(fd, VIDIOC_G_PARM, &parm) == 0 && parm.parm.capture.timeperframe.numerator)
        fps_ = double(parm.parm.capture.timeperframe.denominator) /
               parm.parm.capture.timeperframe.numerator;
    if (config.fps > 0 && fps_ > 0 && std::abs(fps_ - config.fps) > 0.01 * config.fps)
        logWarning("camera {}: asked for {} fps, the driver runs {:.3g} fps at {}x{}", path_,
                   config.fps, fps_, width_, height_);

    return allocateBuffers(std::max(config.bufferCount, 2u));
}

Status V4L2Device::allocateBuffers(uint32_t count) {
    const int fd = fd_.get();
    v4l2_requestbuffers req{};
    req.count = count;
    req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    if (int r = xioctl(fd, VIDIOC_REQBUFS, &req); r < 0)
        return makeError("camera {}: cannot allocate buffers: {}", path_, std::strerror(-r));
    if (req.count < 2)
        return makeError("camera {}: the driver gave {} buffer(s), streaming needs 2", path_,
                         req.count);
    buffers_.reserve(req.count);
    for (uint32_t i = 0; i < req.count; ++i) {
        v4l2_buffer buf{};
        buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
        buf.memory = V4L2_MEMORY_MMAP;
        buf.index = i;
        if (int r = xioctl(fd, VIDIOC_QUERYBUF, &buf); r < 0)
            return makeError("camera {}: querying buffer {} failed: {}", path_, i,
                             std::strerror(-r));
        void* data = ::mmap(nullptr, buf.length, PROT_READ, MAP_SHARED, fd, buf.m.offset);
        if (data == MAP_FAILED)
            return makeError("camera {}: mapping buffer {} failed: {}", path_, i,
                             std::strerror(errno));
        buffers_.emplace_back(data, buf.length);
    }
    return {};
}

Status V4L2Device::queueBuffer(uint32_t index) {
    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    buf.index = index;
    if (int r = xioctl(fd_.get(), VIDIOC_QBUF, &buf); r < 0)
        return isGone(-r) ? vanished("QBUF", -r)
                          : makeError("camera {}: queueing buffer {} failed: {}", path_, index,
                                      std::strerror(-r));
    return {};
}

Error V4L2Device::vanished(const char* during, int err) const {
    return makeError("camera {} ({}): device vanished ({} during {}); unplugged?", path_, card_,
                     std::strerror(err), during);
}

Status V4L2Device::start() {
    if (streaming_) return {};
    if (cycle_)
        if (Status s = setBracketStep(cycle_->start(monotonicNowNs())); !s) return s;
    for (uint32_t i = 0; i < buffers_.size(); ++i)
        if (Status s = queueBuffer(i); !s) return s;
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    if (int r = xioctl(fd_.get(), VIDIOC_STREAMON, &type); r < 0)
        return isGone(-r) ? Status(vanished("STREAMON", -r))
                          : Status(makeError("camera {}: cannot start streaming: {}", path_,
                                             std::strerror(-r)));
    streaming_ = true;
    return {};
}

void V4L2Device::stop() {
    if (!streaming_) return;
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    (void)xioctl(fd_.get(), VIDIOC_STREAMOFF, &type);
    streaming_ = false;
}

Result<bool> V4L2Device::read(int timeoutMs, Frame& frame) {
    if (!streaming_) return makeError("camera {}: read before start()", path_);
    pollfd pfd{fd_.get(), POLLIN, 0};
    int n;
    do {
        n = ::poll(&pfd, 1, timeoutMs);
    } while (n < 0 && errno == EINTR);
    if (n < 0) return makeError("camera {}: poll failed: {}", path_, std::strerror(errno));
    if (n == 0) return false;
    // An unregistered video node reports POLLERR|POLLHUP; with all our buffers queued, a live
    // device never does, so this is the unplug signal.
    if (pfd.revents & (POLLERR | POLLHUP | POLLNVAL)) return vanished("poll", ENODEV);

    v4l2_buffer buf{};
    buf.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    buf.memory = V4L2_MEMORY_MMAP;
    if (int r = xioctl(fd_.get(), VIDIOC_DQBUF, &buf); r < 0) {
        if (r == -EAGAIN) return false;
        if (isGone(-r)) return vanished("DQBUF", -r);
        return makeError("camera {}: dequeueing a frame failed: {}", path_, std::strerror(-r));
    }
    if (buf.index >= buffers_.size())
        return makeError("camera {}: driver returned unknown buffer {}", path_, buf.index);
    const uint64_t timestampNs =
        uint64_t(buf.timestamp.tv_sec) * 1000000000ull + uint64_t(buf.timestamp.tv_usec) * 1000ull;

    // Bracketing: every dequeued frame, corrupt or not, takes its place in the cycle; the next
    // step's control is set as early as possible, and a frame still settling is given back
    // unconverted (withheld: it was taken while the control landed).
    std::optional<float> exposureStops;
    if (cycle_) {
        const bool monotonic =
            (buf.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK) == V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC;
        const uint64_t restartsBefore = cycle_->restarts();
        const ExposureCycle::Decision d =
            cycle_->onFrame(buf.sequence, monotonic ? timestampNs : 0, monotonicNowNs());
        // Logged at 1, 10, 100, ... restarts: a driver whose sequence never counts up one by one
        // would otherwise bracket nothing, silently.
        const uint64_t restarts = cycle_->restarts();
        if (restarts != restartsBefore &&
            (restarts == 1 || restarts == 10 || restarts == 100 || restarts % 1000 == 0))
            logWarning(
                "camera {}: frame {} does not follow the last one: the exposure bracket starts "
                "over ({} times so far; frames the driver dropped)",
                path_, buf.sequence, restarts);
        if (d.set) {
            if (Status s = setBracketStep(*d.set); !s) {
                (void)queueBuffer(buf.index);
                return s.error();
            }
        }
        if (!d.label) {
            if (Status s = queueBuffer(buf.index); !s) return s.error();
            return false;
        }
        exposureStops = bracketStops_[*d.label];
    }

    bool good = !(buf.flags & V4L2_BUF_FLAG_ERROR);
    if (!good && badFrames_ < 3)
        logWarning("camera {}: the driver flagged frame {} as corrupt; skipped", path_,
                   buf.sequence);
    if (good) {
        const Mapping& m = buffers_[buf.index];
        const size_t used = std::min<size_t>(buf.bytesused, m.length);
        const std::span<const uint8_t> data{static_cast<const uint8_t*>(m.data), used};
        Status s = convertToRgb(fourcc_, data, width_, height_, stride_, frame.rgb);
        // While a take rolls, the frame as it came (a copy: the buffer goes back).
        if (s && keepCaptured_ && keepCaptured_->load(std::memory_order_relaxed)) {
            frame.captured = std::make_shared<const std::vector<uint8_t>>(
                packedFrameBytes(fourcc_, data, width_, height_, stride_));
            frame.capturedFourcc = fourcc_;
        }
        if (!s) {
            // Garbage from the camera costs one frame, not the stream; log the first few only.
            if (badFrames_ < 3)
                logWarning("camera {}: frame {} skipped: {}", path_, buf.sequence, s.message());
            good = false;
        }
    }
    if (!good) ++badFrames_;
    // Requeue only after conversion: until then the driver must not overwrite the pixels.
    if (Status s = queueBuffer(buf.index); !s) return s.error();
    if (!good) return false;

    frame.width = width_;
    frame.height = height_;
    // vivid and UVC stamp with CLOCK_MONOTONIC (V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC).
    frame.timestampNs = timestampNs;
    frame.deviceSequence = buf.sequence;
    frame.exposureStops = exposureStops;
    return true;
}

Status V4L2Device::setControl(std::string_view name, int32_t value) {
    v4l2_query_ext_ctrl q{};
    std::string names;
    if (!findControl(fd_.get(), name, q, names))
        return makeError("camera {}: no control named '{}' (it has: {})", path_, name,
                         names.empty() ? "none" : names);
    if (value < q.minimum || value > q.maximum)
        return makeError("camera {}: control '{}' = {} is out of range [{}, {}]", path_, q.name,
                         value, q.minimum, q.maximum);
    v4l2_control c{q.id, value};
    if (int r = xioctl(fd_.get(), VIDIOC_S_CTRL, &c); r < 0)
        return makeError("camera {}: setting '{}' to {} failed: {}", path_, q.name, value,
                         std::strerror(-r));
    return {};
}

}  // namespace previs
