#include "display/kms_output.h"

#include <drm_fourcc.h>
#include <fcntl.h>
#include <poll.h>
#include <sys/mman.h>
#include <xf86drm.h>
#include <xf86drmMode.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <vector>

#include "base/log.h"
#include "base/unique_fd.h"
#include "display/compose.h"
#include "display/drm_util.h"

namespace previs {

namespace {

using Clock = std::chrono::steady_clock;

// A lost display is looked for again this often (opening probes connectors: not every frame).
constexpr auto kRetryPeriod = std::chrono::seconds(2);
// A disconnect is noticed within this time (one cheap connector query).
constexpr auto kConnectorCheckPeriod = std::chrono::seconds(1);
// Longest wait for the previous flip's vblank event: six periods at 60 Hz, so a slow vblank
// does not stall the display thread (DESIGN.md §6: slow consumers drop, never block).
constexpr int kFlipWaitMs = 100;

std::string modeName(const drmModeModeInfo& m) {
    return fmt::format("{}x{}@{}", m.hdisplay, m.vdisplay, m.vrefresh);
}

}  // namespace

// Named, not anonymous: KmsDevice (external linkage) holds these, which GCC rejects
// (-Wsubobject-linkage) once this file is compiled inside a unity build's translation unit.
namespace kms_detail {

// One XRGB8888 dumb buffer with its framebuffer and CPU mapping; released in reverse order.
class DumbBuffer {
public:
    static Result<std::unique_ptr<DumbBuffer>> create(int fd, uint32_t width, uint32_t height) {
        std::unique_ptr<DumbBuffer> b(new DumbBuffer(fd));
        drm_mode_create_dumb create = {};
        create.width = width;
        create.height = height;
        create.bpp = 32;
        if (drmIoctl(fd, DRM_IOCTL_MODE_CREATE_DUMB, &create) != 0)
            return makeError("cannot allocate a {}x{} dumb buffer ({})", width, height,
                             std::strerror(errno));
        b->handle_ = create.handle;
        b->pitch_ = create.pitch;
        b->size_ = create.size;
        b->width_ = width;
        b->height_ = height;
        const uint32_t handles[4] = {b->handle_};
        const uint32_t pitches[4] = {b->pitch_};
        const uint32_t offsets[4] = {0};
        if (drmModeAddFB2(fd, width, height, DRM_FORMAT_XRGB8888, handles, pitches, offsets,
                          &b->fbId_, 0) != 0)
            return makeError("cannot add an XRGB8888 framebuffer ({})", std::strerror(errno));
        drm_mode_map_dumb map = {};
        map.handle = b->handle_;
        if (drmIoctl(fd, DRM_IOCTL_MODE_MAP_DUMB, &map) != 0)
            return makeError("cannot map a dumb buffer ({})", std::strerror(errno));
        void* p = mmap(nullptr, b->size_, PROT_READ | PROT_WRITE, MAP_SHARED, fd, map.offset);
        if (p == MAP_FAILED)
            return makeError("cannot mmap a dumb buffer ({})", std::strerror(errno));
        b->map_ = static_cast<uint32_t*>(p);
        std::memset(b->map_, 0, b->size_);
        return b;
    }

    ~DumbBuffer() {
        if (map_) munmap(map_, size_);
        if (fbId_) drmModeRmFB(fd_, fbId_);
        if (handle_) {
            drm_mode_destroy_dumb destroy = {};
            destroy.handle = handle_;
            drmIoctl(fd_, DRM_IOCTL_MODE_DESTROY_DUMB, &destroy);
        }
    }
    DumbBuffer(const DumbBuffer&) = delete;
    DumbBuffer& operator=(const DumbBuffer&) = delete;

    uint32_t fbId() const { return fbId_; }
    uint32_t pitch() const { return pitch_; }
    uint32_t* pixels() { return map_; }

private:
    explicit DumbBuffer(int fd) : fd_(fd) {}
    int fd_;
    uint32_t handle_ = 0;
    uint32_t pitch_ = 0;
    uint64_t size_ = 0;
    uint32_t width_ = 0;
    uint32_t height_ = 0;
    uint32_t fbId_ = 0;
    uint32_t* map_ = nullptr;
};

// A mode property blob (atomic MODE_ID).
class PropertyBlob {
public:
    PropertyBlob(int fd, uint32_t id) : fd_(fd), id_(id) {}
    ~PropertyBlob() { drmModeDestroyPropertyBlob(fd_, id_); }
    PropertyBlob(const PropertyBlob&) = delete;
    PropertyBlob& operator=(const PropertyBlob&) = delete;
    uint32_t id() const { return id_; }

private:
    int fd_;
    uint32_t id_;
};

}  // namespace kms_detail

namespace {

// Property id by name on a KMS object; 0 if it has none.
uint32_t findProperty(int fd, uint32_t object, uint32_t type, const char* name,
                      uint64_t* value = nullptr) {
    drm::ObjectPropertiesPtr props(drmModeObjectGetProperties(fd, object, type));
    for (uint32_t i = 0; props && i < props->count_props; ++i) {
        drm::PropertyPtr prop(drmModeGetProperty(fd, props->props[i]));
        if (prop && std::strcmp(prop->name, name) == 0) {
            if (value) *value = props->prop_values[i];
            return prop->prop_id;
        }
    }
    return 0;
}

std::vector<std::string> listCards() {
    std::vector<std::string> cards;
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator("/dev/dri", ec)) {
        const std::string name = entry.path().filename().string();
        if (name.rfind("card", 0) == 0) cards.push_back(entry.path().string());
    }
    // card2 before card10.
    std::sort(cards.begin(), cards.end(), [](const std::string& a, const std::string& b) {
        return a.size() != b.size() ? a.size() < b.size() : a < b;
    });
    return cards;
}

}  // namespace

bool parseModeString(const std::string& text, uint32_t* width, uint32_t* height, uint32_t* hz) {
    unsigned w = 0, h = 0, r = 0;
    int used = 0;
    const char* s = text.c_str();
    if (std::sscanf(s, "%5ux%5u%n", &w, &h, &used) != 2) return false;
    if (s[used] == '@') {
        int more = 0;
        if (std::sscanf(s + used + 1, "%4u%n", &r, &more) != 1 || r == 0) return false;
        used += 1 + more;
    }
    if (s[used] != '\0' || w == 0 || h == 0 || !std::isdigit(static_cast<unsigned char>(s[0])))
        return false;
    *width = w;
    *height = h;
    *hz = r;
    return true;
}

// One opened display: the card's fd (DRM master), the chosen connector, CRTC, primary plane
// and mode, and the two buffers. Declared in release order: buffers and blob before the fd.
// Where a device reports completed flips (the output's counters outlive its devices).
struct FlipCounters {
    std::atomic<uint64_t>* flips;
    std::atomic<uint32_t>* lastVblank;
};

class KmsDevice {
public:
    enum class Failure { None, Unavailable, NoSuchConnector, UserError };
    struct Opened {
        std::unique_ptr<KmsDevice> device;
        Failure failure = Failure::None;
        std::string message;
    };

    static Opened open(const std::string& path, const OutputSettings& settings,
                       std::vector<std::string>* connectorsSeen, FlipCounters counters);
    ~KmsDevice() { waitFlip(kFlipWaitMs); }

    // Draws and queues a flip. 0, -ETIMEDOUT (previous flip still pending: frame dropped) or
    // -errno of the failed commit.
    int present(const DisplayFrame& frame);
    // 0 when no flip is pending, -ETIMEDOUT, or -errno of a failed poll.
    int waitFlip(int timeoutMs);
    bool connected() const {
        drm::ConnectorPtr c(drmModeGetConnectorCurrent(fd_.get(), connectorId_));
        return c && c->connection == DRM_MODE_CONNECTED;
    }

    const drmModeModeInfo& mode() const { return mode_; }
    std::string describe() const {
        return fmt::format("{} {} {} ({})", path_, connector_, modeName(mode_),
                           atomic_ ? "atomic" : "legacy");
    }
    const std::string& connectorName() const { return connector_; }

private:
    KmsDevice(UniqueFD fd, std::string path, FlipCounters counters)
        : fd_(std::move(fd)), path_(std::move(path)), counters_(counters) {}
    Opened fail(Failure f, std::string message) { return {nullptr, f, std::move(message)}; }
    bool findAtomicProperties();
    int modeset();
    static void onFlip(int fd, unsigned sequence, unsigned sec, unsigned usec, void* data);

    UniqueFD fd_;
    std::string path_;
    FlipCounters counters_;
    std::string connector_;
    uint32_t connectorId_ = 0;
    uint32_t crtcId_ = 0;
    uint32_t crtcIndex_ = 0;
    uint32_t planeId_ = 0;
    drmModeModeInfo mode_ = {};
    bool atomic_ = false;
    struct {
        uint32_t crtcModeId, crtcActive, connCrtcId, planeFbId, planeCrtcId;
        uint32_t srcX, srcY, srcW, srcH, crtcX, crtcY, crtcW, crtcH;
    } prop_ = {};
    std::unique_ptr<kms_detail::PropertyBlob> modeBlob_;
    std::unique_ptr<kms_detail::DumbBuffer> buffers_[2];
    int front_ = 0;           // the buffer being scanned out
    int pendingBuffer_ = -1;  // the buffer a queued flip will show, -1 = none
};

KmsDevice::Opened KmsDevice::open(const std::string& path, const OutputSettings& settings,
                                  std::vector<std::string>* connectorsSeen, FlipCounters counters) {
    UniqueFD fd(::open(path.c_str(), O_RDWR | O_CLOEXEC));
    if (!fd.isValid()) {
        const int err = errno;
        return {nullptr, Failure::Unavailable,
                fmt::format("{}: cannot open ({}): connect a display or set [output] card", path,
                            std::strerror(err))};
    }
    std::unique_ptr<KmsDevice> d(new KmsDevice(std::move(fd), path, counters));
    const int dfd = d->fd_.get();

    // Universal planes are what atomic commits address; without either, the legacy API.
    const bool universal = drmSetClientCap(dfd, DRM_CLIENT_CAP_UNIVERSAL_PLANES, 1) == 0;
    d->atomic_ =
        !settings.forceLegacy && universal && drmSetClientCap(dfd, DRM_CLIENT_CAP_ATOMIC, 1) == 0;

    drm::ResourcesPtr res(drmModeGetResources(dfd));
    if (!res || res->count_crtcs == 0)
        return d->fail(Failure::Unavailable,
                       fmt::format("{}: not a KMS display device: set [output] card", path));

    drm::ConnectorPtr conn;
    bool namedButDisconnected = false;
    for (int i = 0; i < res->count_connectors; ++i) {
        drm::ConnectorPtr c(drmModeGetConnector(dfd, res->connectors[i]));
        if (!c) continue;
        const std::string name = drm::connectorName(*c);
        const bool isConnected = c->connection == DRM_MODE_CONNECTED;
        connectorsSeen->push_back(name + (isConnected ? "" : " (disconnected)"));
        if (conn) continue;
        if (settings.connector.empty() ? isConnected : name == settings.connector) {
            if (isConnected && c->count_modes > 0)
                conn = std::move(c);
            else
                namedButDisconnected = true;
        }
    }
    if (!conn) {
        if (namedButDisconnected)
            return d->fail(Failure::Unavailable,
                           fmt::format("{}: connector {} has no display connected: connect one",
                                       path, settings.connector));
        if (!settings.connector.empty()) return d->fail(Failure::NoSuchConnector, "");
        return d->fail(Failure::Unavailable,
                       fmt::format("{}: no connector has a display connected: connect one", path));
    }
    d->connector_ = drm::connectorName(*conn);
    d->connectorId_ = conn->connector_id;

    // The mode: the configured size (and rate), else the preferred one, else the first listed.
    const drmModeModeInfo* mode = nullptr;
    if (settings.mode.empty()) {
        for (int i = 0; i < conn->count_modes && !mode; ++i)
            if (conn->modes[i].type & DRM_MODE_TYPE_PREFERRED) mode = &conn->modes[i];
        if (!mode) mode = &conn->modes[0];
    } else {
        uint32_t w = 0, h = 0, hz = 0;
        parseModeString(settings.mode, &w, &h, &hz);  // validated by KmsOutput::create
        for (int i = 0; i < conn->count_modes && !mode; ++i) {
            const drmModeModeInfo& m = conn->modes[i];
            if (m.hdisplay == w && m.vdisplay == h && (hz == 0 || m.vrefresh == hz)) mode = &m;
        }
        if (!mode) {
            std::vector<std::string> names;
            for (int i = 0; i < conn->count_modes; ++i) {
                std::string n = modeName(conn->modes[i]);
                if (std::find(names.begin(), names.end(), n) == names.end()) names.push_back(n);
            }
            return d->fail(Failure::UserError,
                           fmt::format("{} {}: no mode \"{}\"; set [output] mode to one of: {}",
                                       path, d->connector_, settings.mode, fmt::join(names, ", ")));
        }
    }
    d->mode_ = *mode;

    // The CRTC: the one already driving the connector, else the first its encoders can use.
    int crtcIndex = -1;
    if (conn->encoder_id) {
        drm::EncoderPtr enc(drmModeGetEncoder(dfd, conn->encoder_id));
        for (int i = 0; enc && enc->crtc_id && i < res->count_crtcs; ++i)
            if (res->crtcs[i] == enc->crtc_id) crtcIndex = i;
    }
    for (int e = 0; e < conn->count_encoders && crtcIndex < 0; ++e) {
        drm::EncoderPtr enc(drmModeGetEncoder(dfd, conn->encoders[e]));
        for (int i = 0; enc && i < res->count_crtcs && crtcIndex < 0; ++i)
            if (enc->possible_crtcs & (1u << i)) crtcIndex = i;
    }
    if (crtcIndex < 0)
        return d->fail(Failure::Unavailable,
                       fmt::format("{} {}: no CRTC can drive this connector", path, d->connector_));
    d->crtcIndex_ = static_cast<uint32_t>(crtcIndex);
    d->crtcId_ = res->crtcs[crtcIndex];

    // Only the master may modeset; the first opener usually is one already.
    drmSetMaster(dfd);
    if (!drmIsMaster(dfd))
        return d->fail(Failure::Unavailable,
                       fmt::format("{}: another process is DRM master (a desktop session or "
                                   "another previsd?): stop it",
                                   path));

    if (d->atomic_ && !d->findAtomicProperties()) {
        logDebug("display: {}: no primary plane properties, using the legacy API", path);
        d->atomic_ = false;
    }

    for (auto& buffer : d->buffers_) {
        auto b = kms_detail::DumbBuffer::create(dfd, d->mode_.hdisplay, d->mode_.vdisplay);
        if (!b) return d->fail(Failure::Unavailable, fmt::format("{}: {}", path, b.message()));
        buffer = std::move(*b);
    }
    if (int err = d->modeset(); err < 0)
        return d->fail(Failure::Unavailable,
                       fmt::format("{} {}: modeset to {} failed ({})", path, d->connector_,
                                   modeName(d->mode_), std::strerror(-err)));
    return {std::move(d), Failure::None, ""};
}

bool KmsDevice::findAtomicProperties() {
    const int fd = fd_.get();
    drm::PlaneResourcesPtr planes(drmModeGetPlaneResources(fd));
    for (uint32_t i = 0; planes && i < planes->count_planes && !planeId_; ++i) {
        drm::PlanePtr plane(drmModeGetPlane(fd, planes->planes[i]));
        if (!plane || !(plane->possible_crtcs & (1u << crtcIndex_))) continue;
        uint64_t type = 0;
        if (findProperty(fd, plane->plane_id, DRM_MODE_OBJECT_PLANE, "type", &type) &&
            type == DRM_PLANE_TYPE_PRIMARY)
            planeId_ = plane->plane_id;
    }
    if (!planeId_) return false;
    auto crtcProp = [&](const char* n) {
        return findProperty(fd, crtcId_, DRM_MODE_OBJECT_CRTC, n);
    };
    auto planeProp = [&](const char* n) {
        return findProperty(fd, planeId_, DRM_MODE_OBJECT_PLANE, n);
    };
    prop_.crtcModeId = crtcProp("MODE_ID");
    prop_.crtcActive = crtcProp("ACTIVE");
    prop_.connCrtcId = findProperty(fd, connectorId_, DRM_MODE_OBJECT_CONNECTOR, "CRTC_ID");
    prop_.planeFbId = planeProp("FB_ID");
    prop_.planeCrtcId = planeProp("CRTC_ID");
    prop_.srcX = planeProp("SRC_X");
    prop_.srcY = planeProp("SRC_Y");
    prop_.srcW = planeProp("SRC_W");
    prop_.srcH = planeProp("SRC_H");
    prop_.crtcX = planeProp("CRTC_X");
    prop_.crtcY = planeProp("CRTC_Y");
    prop_.crtcW = planeProp("CRTC_W");
    prop_.crtcH = planeProp("CRTC_H");
    const uint32_t all[] = {prop_.crtcModeId,  prop_.crtcActive, prop_.connCrtcId, prop_.planeFbId,
                            prop_.planeCrtcId, prop_.srcX,       prop_.srcY,       prop_.srcW,
                            prop_.srcH,        prop_.crtcX,      prop_.crtcY,      prop_.crtcW,
                            prop_.crtcH};
    return std::all_of(std::begin(all), std::end(all), [](uint32_t id) { return id != 0; });
}

int KmsDevice::modeset() {
    const int fd = fd_.get();
    const uint32_t fb = buffers_[0]->fbId();
    front_ = 0;
    if (atomic_) {
        uint32_t blobId = 0;
        if (drmModeCreatePropertyBlob(fd, &mode_, sizeof(mode_), &blobId) == 0) {
            modeBlob_ = std::make_unique<kms_detail::PropertyBlob>(fd, blobId);
            drm::AtomicReqPtr req(drmModeAtomicAlloc());
            const uint32_t w = mode_.hdisplay, h = mode_.vdisplay;
            drmModeAtomicAddProperty(req.get(), crtcId_, prop_.crtcModeId, blobId);
            drmModeAtomicAddProperty(req.get(), crtcId_, prop_.crtcActive, 1);
            drmModeAtomicAddProperty(req.get(), connectorId_, prop_.connCrtcId, crtcId_);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.planeFbId, fb);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.planeCrtcId, crtcId_);
            // SRC_* are 16.16 fixed point.
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.srcX, 0);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.srcY, 0);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.srcW, uint64_t(w) << 16);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.srcH, uint64_t(h) << 16);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.crtcX, 0);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.crtcY, 0);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.crtcW, w);
            drmModeAtomicAddProperty(req.get(), planeId_, prop_.crtcH, h);
            if (drmModeAtomicCommit(fd, req.get(), DRM_MODE_ATOMIC_ALLOW_MODESET, nullptr) == 0)
                return 0;
            logDebug("display: {}: atomic modeset failed ({}), trying the legacy API", path_,
                     std::strerror(errno));
        }
        modeBlob_.reset();
        atomic_ = false;
    }
    uint32_t connectorId = connectorId_;
    if (drmModeSetCrtc(fd, crtcId_, fb, 0, 0, &connectorId, 1, &mode_) != 0) return -errno;
    return 0;
}

void KmsDevice::onFlip(int, unsigned sequence, unsigned, unsigned, void* data) {
    auto* d = static_cast<KmsDevice*>(data);
    if (d->pendingBuffer_ >= 0) d->front_ = d->pendingBuffer_;
    d->pendingBuffer_ = -1;
    d->counters_.lastVblank->store(sequence);
    d->counters_.flips->fetch_add(1);
}

int KmsDevice::waitFlip(int timeoutMs) {
    const auto deadline = Clock::now() + std::chrono::milliseconds(timeoutMs);
    drmEventContext events = {};
    events.version = 2;
    events.page_flip_handler = &KmsDevice::onFlip;
    while (pendingBuffer_ >= 0) {
        const auto left =
            std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
        if (left.count() <= 0) return -ETIMEDOUT;
        pollfd p = {fd_.get(), POLLIN, 0};
        const int n = poll(&p, 1, static_cast<int>(left.count()));
        if (n < 0 && errno == EINTR) continue;
        if (n < 0) return -errno;
        if (n == 0) return -ETIMEDOUT;
        if (p.revents & (POLLERR | POLLHUP | POLLNVAL)) return -ENODEV;
        if (drmHandleEvent(fd_.get(), &events) != 0) return -EIO;
    }
    return 0;
}

int KmsDevice::present(const DisplayFrame& frame) {
    if (int err = waitFlip(kFlipWaitMs); err < 0) return err;
    const int back = 1 - front_;
    kms_detail::DumbBuffer& buffer = *buffers_[back];
    composeFrame(frame, mode_.hdisplay, mode_.vdisplay, buffer.pixels(), buffer.pitch());
    int ret;
    if (atomic_) {
        drm::AtomicReqPtr req(drmModeAtomicAlloc());
        drmModeAtomicAddProperty(req.get(), planeId_, prop_.planeFbId, buffer.fbId());
        ret = drmModeAtomicCommit(fd_.get(), req.get(),
                                  DRM_MODE_PAGE_FLIP_EVENT | DRM_MODE_ATOMIC_NONBLOCK, this);
    } else {
        ret = drmModePageFlip(fd_.get(), crtcId_, buffer.fbId(), DRM_MODE_PAGE_FLIP_EVENT, this);
    }
    if (ret != 0) return errno ? -errno : -EIO;
    pendingBuffer_ = back;
    return 0;
}

KmsOutput::KmsOutput(const OutputSettings& settings) : settings_(settings) {}

KmsOutput::~KmsOutput() = default;

Result<std::unique_ptr<KmsOutput>> KmsOutput::create(const OutputSettings& settings) {
    uint32_t w = 0, h = 0, hz = 0;
    if (!settings.mode.empty() && !parseModeString(settings.mode, &w, &h, &hz))
        return makeError(
            "[output] mode \"{}\": expected \"WIDTHxHEIGHT\" or "
            "\"WIDTHxHEIGHT@HZ\" (e.g. \"1920x1080@60\"), or leave it out for the "
            "display's preferred mode",
            settings.mode);
    std::unique_ptr<KmsOutput> out(new KmsOutput(settings));
    out->lastAttempt_ = Clock::now();
    out->lastConnectorCheck_ = out->lastAttempt_;

    const std::vector<std::string> cards =
        settings.card.empty() ? listCards() : std::vector{drm::cardPath(settings.card)};
    std::string lastProblem =
        settings.card.empty() ? "no DRM device (/dev/dri/card*): connect a display" : "";
    std::vector<std::string> connectors;
    bool sawNoSuchConnector = false;
    bool sawUnavailable = false;
    for (const std::string& path : cards) {
        std::vector<std::string> seen;
        auto opened =
            KmsDevice::open(path, settings, &seen, {&out->flipsCompleted_, &out->lastVblank_});
        if (opened.device) {
            out->device_ = std::move(opened.device);
            out->lost_ = false;
            logInfo("display: {}", out->device_->describe());
            return out;
        }
        if (opened.failure == KmsDevice::Failure::UserError) return Error{opened.message};
        if (opened.failure == KmsDevice::Failure::NoSuchConnector) {
            sawNoSuchConnector = true;
            for (auto& s : seen) connectors.push_back(fmt::format("{} on {}", s, path));
        } else {
            sawUnavailable = true;
            lastProblem = opened.message;
        }
    }
    // A connector name that no present card has is a typo, not an unplugged monitor (unless a
    // card that might have it could not be looked at).
    if (sawNoSuchConnector && !sawUnavailable)
        return makeError("[output] connector \"{}\": no such connector; available: {}",
                         settings.connector, fmt::join(connectors, ", "));
    logWarning("display: {}; showing nothing, retrying every {} s", lastProblem,
               std::chrono::duration_cast<std::chrono::seconds>(kRetryPeriod).count());
    return out;
}

void KmsOutput::markLost(const std::string& why) {
    logWarning("display: {}; showing nothing, retrying every {} s", why,
               std::chrono::duration_cast<std::chrono::seconds>(kRetryPeriod).count());
    device_.reset();
    lost_ = true;
    lastAttempt_ = Clock::now();
}

void KmsOutput::retryOpen() {
    const auto now = Clock::now();
    if (now - lastAttempt_ < kRetryPeriod) return;
    lastAttempt_ = now;
    const std::vector<std::string> cards =
        settings_.card.empty() ? listCards() : std::vector{drm::cardPath(settings_.card)};
    for (const std::string& path : cards) {
        std::vector<std::string> seen;
        auto opened = KmsDevice::open(path, settings_, &seen, {&flipsCompleted_, &lastVblank_});
        if (opened.device) {
            device_ = std::move(opened.device);
            lost_ = false;
            lastConnectorCheck_ = now;
            logInfo("display: back on {}", device_->describe());
            return;
        }
        // A monitor plugged in later that lacks the configured mode or connector is the
        // user's to fix: say so once per distinct reason, not only at debug level.
        if (opened.failure == KmsDevice::Failure::UserError ||
            opened.failure == KmsDevice::Failure::NoSuchConnector) {
            const std::string why = opened.message.empty() ? fmt::format("{}: no connector '{}'",
                                                                         path, settings_.connector)
                                                           : opened.message;
            if (why != lastRetryWarning_) logWarning("display: {}", why);
            lastRetryWarning_ = why;
        } else {
            logDebug("display: retry {}: {}", path, opened.message);
        }
    }
}

Status KmsOutput::show(const DisplayFrame& frame) {
    if (!device_) {
        retryOpen();
        if (!device_) return {};
    }
    const auto now = Clock::now();
    if (now - lastConnectorCheck_ >= kConnectorCheckPeriod) {
        lastConnectorCheck_ = now;
        if (!device_->connected()) {
            markLost(fmt::format("{}: display disconnected: reconnect it", device_->describe()));
            return {};
        }
    }
    const int err = device_->present(frame);
    lastDropped_ = err == -ETIMEDOUT;
    if (err == -ETIMEDOUT) {
        framesDropped_.fetch_add(1);
        return {};
    }
    if (err == -ENODEV || err == -ENOENT || err == -EACCES || err == -EPERM) {
        markLost(fmt::format("{}: page flip failed ({}): display gone or no longer ours",
                             device_->describe(), std::strerror(-err)));
        return {};
    }
    if (err < 0)
        return makeError("display {}: page flip failed ({})", device_->describe(),
                         std::strerror(-err));
    return {};
}

bool KmsOutput::waitIdle() { return !device_ || device_->waitFlip(kFlipWaitMs) == 0; }

uint32_t KmsOutput::modeWidth() const { return device_ ? device_->mode().hdisplay : 0; }
uint32_t KmsOutput::modeHeight() const { return device_ ? device_->mode().vdisplay : 0; }
std::string KmsOutput::describe() const { return device_ ? device_->describe() : "lost"; }

}  // namespace previs
