#include "capture/libcamera_camera.h"

#include <libcamera/libcamera.h>
#include <linux/dma-buf.h>
#include <linux/videodev2.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <span>
#include <utility>

#include "base/log.h"
#include "capture/exposure_bracket.h"
#include "capture/pixel_format.h"

namespace previs {

namespace lc = libcamera;

namespace {

bool equalsIgnoreCase(std::string_view a, std::string_view b) {
    return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
               return std::tolower(uint8_t(x)) == std::tolower(uint8_t(y));
           });
}

// "0 'platform/vimc.0 Sensor B', 1 '...'": the ids and indexes LibcameraConfig::camera takes.
std::string describeCameras(const std::vector<std::string>& ids) {
    std::string out;
    for (size_t i = 0; i < ids.size(); ++i)
        out += fmt::format("{}{} '{}'", i ? ", " : "", i, ids[i]);
    return out;
}

std::string cameraLabel(const std::string& wanted) {
    return wanted.empty() ? "first libcamera camera" : fmt::format("libcamera camera '{}'", wanted);
}

struct FormatMapping {
    lc::PixelFormat libcamera;
    uint32_t v4l2;
};

// The libcamera formats convertToRgb handles. YUV and MJPEG share their fourcc with V4L2; the
// RGB ones are named differently (header comment), XRGB8888 and XBGR8888 only by coincidence
// alike.
const FormatMapping kFormatMappings[] = {
    {lc::formats::BGR888, V4L2_PIX_FMT_RGB24},    {lc::formats::RGB888, V4L2_PIX_FMT_BGR24},
    {lc::formats::XRGB8888, V4L2_PIX_FMT_XBGR32}, {lc::formats::XBGR8888, V4L2_PIX_FMT_RGBX32},
    {lc::formats::YUYV, V4L2_PIX_FMT_YUYV},       {lc::formats::YVYU, V4L2_PIX_FMT_YVYU},
    {lc::formats::UYVY, V4L2_PIX_FMT_UYVY},       {lc::formats::NV12, V4L2_PIX_FMT_NV12},
    {lc::formats::NV21, V4L2_PIX_FMT_NV21},       {lc::formats::YUV420, V4L2_PIX_FMT_YUV420},
    {lc::formats::MJPEG, V4L2_PIX_FMT_MJPEG},     {lc::formats::R8, V4L2_PIX_FMT_GREY},
};

std::string convertibleFormatList() {
    std::string out;
    for (const FormatMapping& m : kFormatMappings)
        out += (out.empty() ? "" : ", ") + m.libcamera.toString();
    return out;
}

// libcamera allows one CameraManager per process (a second one aborts): every camera and
// every reopen shares this one. It stops when the last camera using it is gone, so a camera
// that was unplugged is looked for by a fresh enumeration on the next open.
Result<std::shared_ptr<lc::CameraManager>> sharedCameraManager() {
    static std::mutex mutex;
    static std::weak_ptr<lc::CameraManager> current;
    std::lock_guard lock(mutex);
    if (std::shared_ptr<lc::CameraManager> manager = current.lock()) return manager;
    auto manager = std::make_unique<lc::CameraManager>();
    if (int r = manager->start(); r < 0)
        return makeError("libcamera: cannot start the camera manager: {}", std::strerror(-r));
    // The deleter takes the lock, so a new manager is not built before the old one has gone.
    std::shared_ptr<lc::CameraManager> shared(manager.release(), [](lc::CameraManager* m) {
        std::lock_guard deleteLock(mutex);
        m->stop();
        delete m;
    });
    current = shared;
    return shared;
}

// Brackets CPU reads of a dmabuf: on SoCs without coherent caches (the Raspberry Pi) the CPU
// would otherwise read stale lines the ISP has since overwritten. Drivers without cache
// maintenance accept it as a no-op; errors change nothing about the pixels, so they are ignored.
void syncDmabuf(const std::vector<int>& fds, uint64_t flags) {
    for (int fd : fds) {
        dma_buf_sync sync{flags | DMA_BUF_SYNC_READ};
        int r;
        do {
            r = ::ioctl(fd, DMA_BUF_IOCTL_SYNC, &sync);
        } while (r < 0 && errno == EINTR);
    }
}

// The sysfs entries (/sys/dev/char/MAJOR:MINOR) of the camera's video nodes, found through the
// device numbers libcamera maps to each camera. The kernel removes them the moment the device
// is unregistered, before udev tells libcamera.
std::vector<std::string> videoNodesOf(lc::CameraManager& manager, const lc::Camera& camera) {
    std::vector<std::string> nodes;
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator("/sys/class/video4linux", ec)) {
        std::ifstream devFile(entry.path() / "dev");
        unsigned major = 0, minor = 0;
        char colon = 0;
        if (!(devFile >> major >> colon >> minor) || colon != ':') continue;
        if (manager.get(makedev(major, minor)).get() == &camera)
            nodes.push_back(fmt::format("/sys/dev/char/{}:{}", major, minor));
    }
    return nodes;
}

}  // namespace

// Named, not anonymous: LibcameraCamera::State (external linkage) holds these, which GCC
// rejects (-Wsubobject-linkage) once this file is compiled inside a unity build's translation
// unit.
namespace libcamera_detail {

// A whole dmabuf mapped read-only, unmapped on destruction.
class DmabufMapping {
public:
    DmabufMapping(const uint8_t* data, size_t length) : data_(data), length_(length) {}
    DmabufMapping(DmabufMapping&& o) noexcept
        : data_(std::exchange(o.data_, nullptr)), length_(std::exchange(o.length_, 0)) {}
    DmabufMapping& operator=(DmabufMapping&&) = delete;
    DmabufMapping(const DmabufMapping&) = delete;
    ~DmabufMapping() {
        if (data_) ::munmap(const_cast<uint8_t*>(data_), length_);
    }
    const uint8_t* data() const { return data_; }
    size_t length() const { return length_; }

private:
    const uint8_t* data_;
    size_t length_;
};

// Completed requests handed from libcamera's thread to read(). Owned jointly with the signal
// handlers, so a signal delivered while the camera is torn down never touches freed memory.
struct Inbox {
    std::mutex mutex;
    std::condition_variable ready;
    std::deque<lc::Request*> completed;
    bool stopping = false;  // stop() cancels requests in flight: expected, not a failure
    bool disconnected = false;
    std::string failure;
};

// One frame buffer's planes as mapped memory.
struct MappedBuffer {
    std::vector<std::span<const uint8_t>> planes;
    std::vector<int> fds;    // the distinct dmabufs behind the planes, for syncDmabuf
    bool contiguous = true;  // plane i+1 follows plane i in one dmabuf: no copy needed
};

}  // namespace libcamera_detail

// Members are destroyed in reverse order, which is also the order libcamera needs: requests
// before the buffers they name, mappings before the allocator that owns the dmabufs, the
// allocator before the camera is released, the camera before the manager stops.
struct LibcameraCamera::State {
    std::shared_ptr<lc::CameraManager> manager;
    std::shared_ptr<lc::Camera> camera;
    bool acquired = false;
    lc::ControlList startControls;
    std::unique_ptr<lc::FrameBufferAllocator> allocator;
    std::vector<libcamera_detail::DmabufMapping> mappings;
    std::map<const lc::FrameBuffer*, libcamera_detail::MappedBuffer> buffers;
    std::vector<std::unique_ptr<lc::Request>> requests;
    std::shared_ptr<libcamera_detail::Inbox> inbox = std::make_shared<libcamera_detail::Inbox>();
    lc::Stream* stream = nullptr;

    std::string id;
    std::vector<std::string> videoNodes;
    std::string formatName;
    uint32_t v4l2Fourcc = 0;
    uint32_t width = 0;
    uint32_t height = 0;
    uint32_t stride = 0;
    double fps = 0;
    bool running = false;
    bool connected = false;  // our handlers are attached to the camera's signals
    const std::atomic<bool>* keepCaptured = nullptr;  // LibcameraConfig::keepCaptured
    uint64_t badFrames = 0;
    std::vector<uint8_t> scratch;  // planes gathered for conversion when not contiguous
    // Bracketing (LibcameraConfig::bracketStops): each step's exposure time, the fixed gain, the
    // base the labels are measured from, and the step the next queued request takes.
    std::vector<float> bracketStops;
    std::vector<int32_t> bracketExposureUs;
    float bracketGain = 1.0f;
    int32_t baseExposureUs = 0;
    size_t nextStep = 0;

    ~State();
    Status open(const LibcameraConfig& config);
    Status configure(const LibcameraConfig& config);
    Status setControls(const LibcameraConfig& config);
    Status setUpBracket(const LibcameraConfig& config);
    // Puts the next step's exposure into a request about to be queued.
    void setBracketControls(lc::Request* request);
    Status allocateBuffers();
    void connectSignals();
    Status start();
    void stop();
    Result<bool> read(int timeoutMs, Frame& frame);
    Status requeue(lc::Request* request);
    Error disconnectedError() const;
    bool deviceGone() const;
    std::string controlNames() const;
    template <typename T>
    Status checkRange(const lc::ControlId& control, T value, const char* what) const;
};

LibcameraCamera::State::~State() {
    stop();
    if (connected) {
        camera->requestCompleted.disconnect(inbox.get());
        camera->disconnected.disconnect(inbox.get());
    }
    requests.clear();
    buffers.clear();
    mappings.clear();
    allocator.reset();
    if (acquired) camera->release();
    camera.reset();
    manager.reset();
}

Status LibcameraCamera::State::open(const LibcameraConfig& config) {
    Result<std::shared_ptr<lc::CameraManager>> shared = sharedCameraManager();
    if (!shared) return shared.error();
    manager = std::move(*shared);

    const std::vector<std::shared_ptr<lc::Camera>> cameras = manager->cameras();
    std::vector<std::string> ids;
    for (const std::shared_ptr<lc::Camera>& c : cameras) ids.push_back(c->id());
    Result<size_t> index = selectLibcameraCamera(config.camera, ids);
    if (!index) return index.error();
    camera = cameras[*index];
    id = camera->id();

    if (int r = camera->acquire(); r < 0) {
        if (r == -EBUSY)
            return makeError(
                "libcamera camera '{}': in use (by another program, or by another camera in "
                "the config naming the same one)",
                id);
        return makeError("libcamera camera '{}': cannot acquire it: {}", id, std::strerror(-r));
    }
    acquired = true;
    videoNodes = videoNodesOf(*manager, *camera);
    if (Status s = configure(config); !s) return s;
    if (Status s = setControls(config); !s) return s;
    if (Status s = setUpBracket(config); !s) return s;
    if (Status s = allocateBuffers(); !s) return s;
    connectSignals();
    logInfo("libcamera camera '{}': {} {}x{} (stride {}), {} buffers{}", id, formatName, width,
            height, stride, requests.size(), fps > 0 ? fmt::format(", {} fps", fps) : "");
    return {};
}

Status LibcameraCamera::State::configure(const LibcameraConfig& config) {
    // Viewfinder: the ISP's processed output with the shortest latency (an AR preview needs
    // little delay more than it needs a recording's quality).
    std::unique_ptr<lc::CameraConfiguration> cameraConfig =
        camera->generateConfiguration({lc::StreamRole::Viewfinder});
    if (!cameraConfig || cameraConfig->empty())
        return makeError("libcamera camera '{}': offers no viewfinder stream", id);
    lc::StreamConfiguration& streamConfig = cameraConfig->at(0);

    const std::vector<lc::PixelFormat> formats = streamConfig.formats().pixelformats();
    std::vector<OfferedFormat> offered;
    size_t preferred = 0;
    for (size_t i = 0; i < formats.size(); ++i) {
        offered.push_back({formats[i].toString(),
                           v4l2FourccFromLibcamera(formats[i].fourcc(), formats[i].modifier())});
        if (formats[i] == streamConfig.pixelFormat) preferred = i;
    }
    Result<size_t> chosen = selectLibcameraFormat(id, config.pixelFormat, offered, preferred);
    if (!chosen) return chosen.error();
    const lc::PixelFormat format = formats[*chosen];
    const lc::Size size(config.width, config.height);
    streamConfig.pixelFormat = format;
    streamConfig.size = size;
    if (config.bufferCount) streamConfig.bufferCount = config.bufferCount;

    const lc::SizeRange range = streamConfig.formats().range(format);
    if (cameraConfig->validate() == lc::CameraConfiguration::Invalid)
        return makeError("libcamera camera '{}': rejects {} {}x{} (it offers {} to {})", id,
                         format.toString(), config.width, config.height, range.min.toString(),
                         range.max.toString());
    if (streamConfig.pixelFormat != format)
        return makeError("libcamera camera '{}': does not offer {} at {}x{} (it would give {})", id,
                         format.toString(), config.width, config.height,
                         streamConfig.pixelFormat.toString());
    // validate() adjusts rather than fails; calibration and scene setup assume the configured
    // size, so a different one is an error, not a silent change (as for V4L2).
    if (streamConfig.size != size)
        return makeError(
            "libcamera camera '{}': {} {}x{} is not available (the nearest it offers is {}, "
            "within {} to {}); set the camera's width/height in the config to a supported size",
            id, format.toString(), config.width, config.height, streamConfig.size.toString(),
            range.min.toString(), range.max.toString());
    if (int r = camera->configure(cameraConfig.get()); r < 0)
        return makeError("libcamera camera '{}': configuring {} {}x{} failed: {}", id,
                         format.toString(), config.width, config.height, std::strerror(-r));

    stream = streamConfig.stream();
    formatName = format.toString();
    v4l2Fourcc = offered[*chosen].v4l2Fourcc;
    width = streamConfig.size.width;
    height = streamConfig.size.height;
    stride = streamConfig.stride;
    return {};
}

std::string LibcameraCamera::State::controlNames() const {
    std::vector<std::string> names;
    for (const auto& [control, info] : camera->controls()) names.push_back(control->name());
    std::sort(names.begin(), names.end());
    std::string out;
    for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
    return out.empty() ? "none" : out;
}

// Checks that the camera has `control` and, when it states a range of T, that `value` is in it.
template <typename T>
Status LibcameraCamera::State::checkRange(const lc::ControlId& control, T value,
                                          const char* what) const {
    const lc::ControlInfoMap& infos = camera->controls();
    const auto it = infos.find(&control);
    if (it == infos.end())
        return makeError(
            "libcamera camera '{}': has no {} control, so {} cannot be set (it has: {}); "
            "remove it from the config",
            id, control.name(), what, controlNames());
    const lc::ControlInfo& info = it->second;
    constexpr lc::ControlType type = lc::details::control_type<T>::value;
    if (info.min().type() != type || info.max().type() != type || info.min().isArray() ||
        info.max().isArray())
        return {};
    const T lo = info.min().get<T>();
    const T hi = info.max().get<T>();
    if (value < lo || value > hi)
        return makeError("libcamera camera '{}': {} = {} is out of range [{}, {}]", id, what, value,
                         lo, hi);
    return {};
}

Status LibcameraCamera::State::setControls(const LibcameraConfig& config) {
    startControls = lc::ControlList(camera->controls());
    const lc::ControlInfoMap& infos = camera->controls();
    const bool hasAe = infos.find(&lc::controls::AeEnable) != infos.end();
    const bool hasAwb = infos.find(&lc::controls::AwbEnable) != infos.end();

    if (config.fps > 0) {
        if (infos.find(&lc::controls::FrameDurationLimits) == infos.end()) {
            logWarning(
                "libcamera camera '{}': has no FrameDurationLimits control; it runs at its own "
                "frame rate, not {} fps",
                id, config.fps);
        } else {
            const int64_t durationUs = std::llround(1e6 / config.fps);
            Status s = checkRange<int64_t>(lc::controls::FrameDurationLimits, durationUs,
                                           "the frame duration (µs) for the configured fps");
            if (!s) return s;
            // Both limits equal: a fixed rate, so the exposure cannot stretch the frame.
            const std::array<int64_t, 2> limits = {durationUs, durationUs};
            startControls.set(lc::controls::FrameDurationLimits,
                              lc::Span<const int64_t, 2>(limits.data(), 2));
            fps = config.fps;
        }
    }
    if (config.exposureUs) {
        if (Status s = checkRange<int32_t>(lc::controls::ExposureTime, *config.exposureUs,
                                           "the exposure time (µs)");
            !s)
            return s;
        startControls.set(lc::controls::ExposureTime, *config.exposureUs);
    }
    if (config.analogueGain) {
        if (Status s = checkRange<float>(lc::controls::AnalogueGain, *config.analogueGain,
                                         "the analogue gain");
            !s)
            return s;
        startControls.set(lc::controls::AnalogueGain, *config.analogueGain);
    }
    if ((config.exposureUs || config.analogueGain) && hasAe)
        startControls.set(lc::controls::AeEnable, false);
    if (config.colourGains) {
        for (float gain : *config.colourGains)
            if (Status s = checkRange<float>(lc::controls::ColourGains, gain, "a colour gain"); !s)
                return s;
        startControls.set(lc::controls::ColourGains,
                          lc::Span<const float, 2>(config.colourGains->data(), 2));
        if (hasAwb) startControls.set(lc::controls::AwbEnable, false);
    }
    return {};
}

Status LibcameraCamera::State::setUpBracket(const LibcameraConfig& config) {
    if (config.bracketStops.empty()) return {};
    if (!config.exposureUs || !config.analogueGain)
        return makeError(
            "libcamera camera '{}': bracketing needs the base exposure_us and analogue_gain in "
            "its controls (the exposure its radiometry was calibrated at)",
            id);
    baseExposureUs = *config.exposureUs;
    bracketGain = *config.analogueGain;
    bracketExposureUs.clear();
    std::string steps;
    for (float stop : config.bracketStops) {
        const double ideal = double(baseExposureUs) * std::exp2(double(stop));
        const int64_t us = std::llround(ideal);
        if (us < 1 || us > INT32_MAX ||
            std::abs(std::log2(double(us) / baseExposureUs) - stop) > kMaxStepErrorStops)
            return makeError(
                "libcamera camera '{}': bracket stop {} needs an exposure of {:.4g} µs ({} µs × "
                "2^{}), which whole microseconds do not reach; raise exposure_us or narrow the "
                "bracket",
                id, stop, ideal, baseExposureUs, stop);
        const std::string what = fmt::format("the exposure time (µs) of bracket stop {}", stop);
        if (Status s = checkRange<int32_t>(lc::controls::ExposureTime, int32_t(us), what.c_str());
            !s)
            return s;
        bracketExposureUs.push_back(int32_t(us));
        steps += fmt::format("{}{} µs ({:+g})", steps.empty() ? "" : ", ", us, stop);
    }
    bracketStops = config.bracketStops;
    logInfo(
        "libcamera camera '{}': bracketing through {} at analogue gain {}, each frame "
        "labelled from its metadata",
        id, steps, bracketGain);
    return {};
}

void LibcameraCamera::State::setBracketControls(lc::Request* request) {
    if (bracketStops.empty()) return;
    // Per request: libcamera applies a request's controls to its own frame where the pipeline
    // can (and reports in the metadata what it did where it cannot).
    request->controls().set(lc::controls::ExposureTime, bracketExposureUs[nextStep]);
    request->controls().set(lc::controls::AnalogueGain, bracketGain);
    nextStep = (nextStep + 1) % bracketStops.size();
}

Status LibcameraCamera::State::allocateBuffers() {
    allocator = std::make_unique<lc::FrameBufferAllocator>(camera);
    if (int r = allocator->allocate(stream); r < 0)
        return makeError("libcamera camera '{}': cannot allocate buffers: {}", id,
                         std::strerror(-r));
    std::map<int, size_t> mappingOfFd;
    for (const std::unique_ptr<lc::FrameBuffer>& buffer : allocator->buffers(stream)) {
        libcamera_detail::MappedBuffer mapped;
        const lc::FrameBuffer::Plane* previous = nullptr;
        for (const lc::FrameBuffer::Plane& plane : buffer->planes()) {
            const int fd = plane.fd.get();
            auto found = mappingOfFd.find(fd);
            if (found == mappingOfFd.end()) {
                // A dmabuf's size is its seek end; map all of it, planes are offsets into it.
                const off_t length = ::lseek(fd, 0, SEEK_END);
                if (length <= 0)
                    return makeError("libcamera camera '{}': cannot size a frame buffer: {}", id,
                                     std::strerror(errno));
                void* data = ::mmap(nullptr, size_t(length), PROT_READ, MAP_SHARED, fd, 0);
                if (data == MAP_FAILED)
                    return makeError("libcamera camera '{}': cannot map a frame buffer: {}", id,
                                     std::strerror(errno));
                mappings.emplace_back(static_cast<const uint8_t*>(data), size_t(length));
                found = mappingOfFd.emplace(fd, mappings.size() - 1).first;
                mapped.fds.push_back(fd);
            }
            const libcamera_detail::DmabufMapping& m = mappings[found->second];
            if (size_t(plane.offset) + plane.length > m.length())
                return makeError("libcamera camera '{}': a buffer plane lies outside its dmabuf",
                                 id);
            mapped.planes.emplace_back(m.data() + plane.offset, plane.length);
            if (previous &&
                (previous->fd.get() != fd || previous->offset + previous->length != plane.offset))
                mapped.contiguous = false;
            previous = &plane;
        }
        std::unique_ptr<lc::Request> request = camera->createRequest();
        if (!request)
            return makeError("libcamera camera '{}': cannot create a capture request", id);
        if (int r = request->addBuffer(stream, buffer.get()); r < 0)
            return makeError("libcamera camera '{}': cannot attach a buffer to a request: {}", id,
                             std::strerror(-r));
        buffers.emplace(buffer.get(), std::move(mapped));
        requests.push_back(std::move(request));
    }
    if (requests.empty())
        return makeError("libcamera camera '{}': the pipeline allocated no buffers", id);
    return {};
}

void LibcameraCamera::State::connectSignals() {
    // The handlers run on libcamera's thread and only hand over: conversion happens in read().
    camera->requestCompleted.connect(inbox.get(), [box = inbox](lc::Request* request) {
        {
            std::lock_guard lock(box->mutex);
            if (request->status() == lc::Request::RequestCancelled) {
                if (!box->stopping && box->failure.empty())
                    box->failure = "libcamera cancelled a capture request while streaming";
            } else {
                box->completed.push_back(request);
            }
        }
        box->ready.notify_one();
    });
    camera->disconnected.connect(inbox.get(), [box = inbox]() {
        {
            std::lock_guard lock(box->mutex);
            box->disconnected = true;
        }
        box->ready.notify_one();
    });
    connected = true;
}

Error LibcameraCamera::State::disconnectedError() const {
    return makeError("libcamera camera '{}': disconnected (unplugged, or its driver went away)",
                     id);
}

Status LibcameraCamera::State::start() {
    if (running) return {};
    {
        std::lock_guard lock(inbox->mutex);
        if (inbox->disconnected) return disconnectedError();
        inbox->stopping = false;
        inbox->completed.clear();
        inbox->failure.clear();
    }
    if (int r = camera->start(&startControls); r < 0) {
        if (r == -ENODEV) return disconnectedError();
        return makeError("libcamera camera '{}': cannot start: {}", id, std::strerror(-r));
    }
    running = true;
    nextStep = 0;
    for (size_t i = 0; i < requests.size(); ++i) {
        lc::Request* request = requests[i].get();
        request->reuse(lc::Request::ReuseBuffers);
        // Some pipelines (vimc) ignore the controls given to start(); the first request
        // carries them as well.
        if (i == 0) request->controls().merge(startControls);
        setBracketControls(request);
        if (int r = camera->queueRequest(request); r < 0) {
            stop();
            return makeError("libcamera camera '{}': cannot queue a request: {}", id,
                             std::strerror(-r));
        }
    }
    return {};
}

bool LibcameraCamera::State::deviceGone() const {
    return std::any_of(videoNodes.begin(), videoNodes.end(),
                       [](const std::string& node) { return !std::filesystem::exists(node); });
}

void LibcameraCamera::State::stop() {
    if (!running) return;
    {
        std::lock_guard lock(inbox->mutex);
        inbox->stopping = true;
    }
    // libcamera 0.0.3 cannot stop a camera whose device was removed while streaming: STREAMOFF
    // fails, the queued requests never come back and an assertion aborts the process. Not
    // stopping is no way out: the running IPA thread terminates the process when the camera
    // is freed, and its dead video node keeps libcamera's event loop spinning. So the process
    // ends here, and the message says why (docs/libcamera.md).
    if (deviceGone())
        logError(
            "libcamera camera '{}': stopping a camera whose device was removed; libcamera {} "
            "cannot and aborts: restart previs when the camera is back (systemd does)",
            id, lc::CameraManager::version());
    // Blocks until every queued request has come back (cancelled); a camera already
    // disconnected returns at once.
    camera->stop();
    std::lock_guard lock(inbox->mutex);
    inbox->completed.clear();
    running = false;
}

Status LibcameraCamera::State::requeue(lc::Request* request) {
    request->reuse(lc::Request::ReuseBuffers);
    setBracketControls(request);
    if (int r = camera->queueRequest(request); r < 0) {
        if (r == -ENODEV) return disconnectedError();
        return makeError("libcamera camera '{}': cannot requeue a request: {}", id,
                         std::strerror(-r));
    }
    return {};
}

Result<bool> LibcameraCamera::State::read(int timeoutMs, Frame& frame) {
    if (!running) return makeError("libcamera camera '{}': read before start()", id);
    lc::Request* request = nullptr;
    {
        std::unique_lock lock(inbox->mutex);
        inbox->ready.wait_for(lock, std::chrono::milliseconds(std::max(timeoutMs, 0)), [&] {
            return !inbox->completed.empty() || inbox->disconnected || !inbox->failure.empty();
        });
        if (inbox->disconnected) return disconnectedError();
        if (!inbox->failure.empty())
            return makeError("libcamera camera '{}': {}", id, inbox->failure);
        if (!inbox->completed.empty()) {
            request = inbox->completed.front();
            inbox->completed.pop_front();
        }
    }
    if (!request) {
        // libcamera 0.0.3 does not notice a removed device (no disconnected signal, no failed
        // request: frames just stop), so a quiet camera's video nodes are checked.
        if (deviceGone()) return disconnectedError();
        return false;
    }

    lc::FrameBuffer* buffer = request->findBuffer(stream);
    const auto mapped = buffer ? buffers.find(buffer) : buffers.end();
    if (mapped == buffers.end())
        return makeError("libcamera camera '{}': a request came back without its buffer", id);
    const lc::FrameMetadata& metadata = buffer->metadata();
    bool good = metadata.status == lc::FrameMetadata::FrameSuccess;
    if (!good && badFrames < 3)
        logWarning("libcamera camera '{}': frame {} came back with an error; skipped", id,
                   metadata.sequence);
    if (good) {
        const libcamera_detail::MappedBuffer& planes = mapped->second;
        const lc::Span<const lc::FrameMetadata::Plane> used = metadata.planes();
        auto bytesUsed = [&](size_t i) {
            return i < used.size() ? std::min<size_t>(used[i].bytesused, planes.planes[i].size())
                                   : planes.planes[i].size();
        };
        syncDmabuf(planes.fds, DMA_BUF_SYNC_START);
        std::span<const uint8_t> data;
        if (planes.contiguous) {
            const size_t last = planes.planes.size() - 1;
            data = {planes.planes[0].data(),
                    size_t(planes.planes[last].data() - planes.planes[0].data()) + bytesUsed(last)};
        } else {
            scratch.clear();
            for (size_t i = 0; i < planes.planes.size(); ++i)
                scratch.insert(scratch.end(), planes.planes[i].begin(),
                               planes.planes[i].begin() + ptrdiff_t(bytesUsed(i)));
            data = scratch;
        }
        Status s = convertToRgb(v4l2Fourcc, data, width, height, stride, frame.rgb);
        if (s && keepCaptured && keepCaptured->load(std::memory_order_relaxed)) {
            frame.captured = std::make_shared<const std::vector<uint8_t>>(
                packedFrameBytes(v4l2Fourcc, data, width, height, stride));
            frame.capturedFourcc = v4l2Fourcc;
        }
        syncDmabuf(planes.fds, DMA_BUF_SYNC_END);
        if (!s) {
            // Garbage from the camera costs one frame, not the stream; log the first few only.
            if (badFrames < 3)
                logWarning("libcamera camera '{}': frame {} skipped: {}", id, metadata.sequence,
                           s.message());
            good = false;
        }
    }
    if (!good) ++badFrames;
    frame.width = width;
    frame.height = height;
    // SensorTimestamp (start of exposure) where the pipeline reports it, else the V4L2 buffer's
    // timestamp; both CLOCK_MONOTONIC, the clock of V4L2Device's frames.
    frame.timestampNs = uint64_t(request->metadata()
                                     .get(lc::controls::SensorTimestamp)
                                     .value_or(int64_t(metadata.timestamp)));
    frame.deviceSequence = metadata.sequence;
    if (!bracketStops.empty()) {
        // What the sensor did, not what was asked: a pipeline whose controls land late labels
        // each frame with the exposure it really had.
        const lc::ControlList& reported = request->metadata();
        std::optional<double> exposureUs, gain;
        if (const auto e = reported.get(lc::controls::ExposureTime)) exposureUs = double(*e);
        if (const auto g = reported.get(lc::controls::AnalogueGain)) gain = double(*g);
        frame.exposureStops =
            exposureStopsFromMetadata(bracketStops, exposureUs, gain, baseExposureUs, bracketGain);
    }
    // Requeued only after conversion: until then the camera must not overwrite the pixels.
    if (Status s = requeue(request); !s) return s.error();
    return good;
}

LibcameraCamera::LibcameraCamera(std::unique_ptr<State> state) : state_(std::move(state)) {}

LibcameraCamera::~LibcameraCamera() = default;

Result<std::unique_ptr<LibcameraCamera>> LibcameraCamera::create(const LibcameraConfig& config) {
    auto state = std::make_unique<State>();
    state->keepCaptured = config.keepCaptured;
    if (Status s = state->open(config); !s) return s.error();
    return std::unique_ptr<LibcameraCamera>(new LibcameraCamera(std::move(state)));
}

Status LibcameraCamera::start() { return state_->start(); }
void LibcameraCamera::stop() { state_->stop(); }
Result<bool> LibcameraCamera::read(int timeoutMs, Frame& frame) {
    return state_->read(timeoutMs, frame);
}
uint64_t LibcameraCamera::badFrames() const { return state_->badFrames; }
const std::string& LibcameraCamera::id() const { return state_->id; }
uint32_t LibcameraCamera::width() const { return state_->width; }
uint32_t LibcameraCamera::height() const { return state_->height; }
const std::string& LibcameraCamera::pixelFormat() const { return state_->formatName; }
double LibcameraCamera::fps() const { return state_->fps; }

Result<std::vector<LibcameraCameraInfo>> listLibcameraCameras() {
    Result<std::shared_ptr<lc::CameraManager>> manager = sharedCameraManager();
    if (!manager) return manager.error();
    std::vector<LibcameraCameraInfo> out;
    for (const std::shared_ptr<lc::Camera>& camera : (*manager)->cameras())
        out.push_back({camera->id(),
                       camera->properties().get(lc::properties::Model).value_or(std::string())});
    return out;
}

FrameReaderFactory makeLibcameraReaderFactory(LibcameraConfig config) {
    return [config = std::move(config)]() -> Result<std::unique_ptr<FrameReader>> {
        auto camera = LibcameraCamera::create(config);
        if (!camera) return camera.error();
        return std::unique_ptr<FrameReader>(std::move(*camera));
    };
}

std::unique_ptr<CameraSource> makeLibcameraSource(LibcameraConfig config, CaptureOptions options) {
    return std::make_unique<CaptureThread>(makeLibcameraReaderFactory(std::move(config)),
                                           std::move(options));
}

Result<size_t> selectLibcameraCamera(const std::string& wanted,
                                     const std::vector<std::string>& ids) {
    if (ids.empty())
        return makeError(
            "{}: libcamera found no cameras; check that the camera is connected, its driver "
            "loaded and udev running (`cam -l` lists the cameras libcamera sees)",
            cameraLabel(wanted));
    if (wanted.empty()) return size_t(0);
    for (size_t i = 0; i < ids.size(); ++i)
        if (ids[i] == wanted) return i;
    const bool isIndex =
        wanted.size() <= 6 &&
        std::all_of(wanted.begin(), wanted.end(), [](char c) { return std::isdigit(uint8_t(c)); });
    if (isIndex && std::stoul(wanted) < ids.size()) return size_t(std::stoul(wanted));
    std::vector<size_t> matches;
    for (size_t i = 0; i < ids.size(); ++i)
        if (!isIndex && ids[i].find(wanted) != std::string::npos) matches.push_back(i);
    if (matches.size() == 1) return matches[0];
    if (matches.size() > 1)
        return makeError("{}: matches several cameras ({}); give more of the id",
                         cameraLabel(wanted), describeCameras(ids));
    return makeError(
        "{}: no such camera (libcamera sees {}); set the camera to one of these ids or "
        "indexes",
        cameraLabel(wanted), describeCameras(ids));
}

uint32_t v4l2FourccFromLibcamera(uint32_t fourcc, uint64_t modifier) {
    // A modifier means a vendor layout (tiled, compressed) convertToRgb does not read.
    if (modifier != 0) return 0;
    for (const FormatMapping& m : kFormatMappings)
        if (m.libcamera.fourcc() == fourcc) return m.v4l2;
    return 0;
}

Result<size_t> selectLibcameraFormat(const std::string& cameraId, const std::string& wanted,
                                     const std::vector<OfferedFormat>& offered, size_t preferred) {
    std::string names;
    for (const OfferedFormat& f : offered) names += (names.empty() ? "" : ", ") + f.name;
    if (names.empty()) names = "none";
    if (wanted.empty()) {
        if (preferred < offered.size() && offered[preferred].v4l2Fourcc) return preferred;
        for (size_t i = 0; i < offered.size(); ++i)
            if (offered[i].v4l2Fourcc) return i;
        return makeError(
            "libcamera camera '{}': none of its pixel formats ({}) can be converted to RGB "
            "(previs converts {})",
            cameraId, names, convertibleFormatList());
    }
    for (size_t i = 0; i < offered.size(); ++i) {
        if (!equalsIgnoreCase(offered[i].name, wanted)) continue;
        if (!offered[i].v4l2Fourcc)
            return makeError(
                "libcamera camera '{}': pixel format {} cannot be converted to RGB (previs "
                "converts {}); choose another or leave the format empty",
                cameraId, offered[i].name, convertibleFormatList());
        return i;
    }
    return makeError("libcamera camera '{}': does not offer pixel format {}; it offers: {}",
                     cameraId, wanted, names);
}

}  // namespace previs
