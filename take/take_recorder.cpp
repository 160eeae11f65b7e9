#include "take/take_recorder.h"

#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "base/log.h"
#include "capture/pixel_format.h"
#include "net/freed_calibration.h"
#include "take/take_files.h"

namespace previs {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

std::optional<uint64_t> freeBytes(const std::string& dir) {
    struct statvfs st {};
    if (::statvfs(dir.c_str(), &st) != 0) return std::nullopt;
    return uint64_t(st.f_bavail) * uint64_t(st.f_frsize);
}

bool validTakeName(const std::string& name) {
    return name.size() <= 64 && std::all_of(name.begin(), name.end(), [](char c) {
               return std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_';
           });
}

std::string takeFolderName(const std::string& name) {
    const std::time_t now = std::time(nullptr);
    std::tm local{};
    localtime_r(&now, &local);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%d_%H%M%S", &local);
    return name.empty() ? std::string(stamp) : std::string(stamp) + "_" + name;
}

// What a raw frame costs on disk and in the queue: its RGB bytes until the writer encodes it.
size_t frameBytes(const Frame& f) { return f.captured ? f.captured->size() : f.rgb.size(); }

// A frame that came without its captured bytes (none kept): lossless PNG at zlib level 1.
Result<std::vector<uint8_t>> encodeFramePng(const Frame& f) {
    cv::Mat bgr;
    cv::cvtColor(cv::Mat(int(f.height), int(f.width), CV_8UC3, const_cast<uint8_t*>(f.rgb.data())),
                 bgr, cv::COLOR_RGB2BGR);
    std::vector<uint8_t> png;
    if (!cv::imencode(".png", bgr, png, {cv::IMWRITE_PNG_COMPRESSION, 1}))
        return makeError("frame {}: PNG encoding failed", f.sequence);
    return png;
}

}  // namespace

// The writer's state: the session being appended, and per camera how its timestamps continue.
struct TakeRecorder::Take {
    explicit Take(SessionWriter w) : writer(std::move(w)) {}
    std::string dir;
    SessionWriter writer;
    uint64_t minFreeBytes = 0;
    Clock::time_point lastSpaceCheck{};
    // Per camera: a looping recorded source starts its timestamps over; the take's must not
    // decrease, so a jump back shifts the rest of that camera's (and its poses') timestamps.
    struct CameraClock {
        uint64_t offsetNs = 0;
        uint64_t lastNs = 0;
        bool any = false;
    };
    std::map<std::string, CameraClock> clocks;
    // Per camera: the rule its labels count at (timecode/timecode.h), its rate once known, and
    // its first frame while the rate waits for a second one to be measured.
    std::map<std::string, LabelRateRule> labelRules;
    std::map<std::string, TimecodeRate> timecodeRates;
    std::map<std::string, FrameItem> firstFrames;

    uint64_t takeTimestamp(const std::string& camera, uint64_t ns, uint64_t sequence) {
        CameraClock& c = clocks[camera];
        if (c.any && ns + c.offsetNs < c.lastNs) {
            c.offsetNs = c.lastNs - ns + 1;
            logInfo(
                "recording: {} frame {} goes back in time (a looping session); its "
                "timestamps continue from the take's",
                camera, sequence);
        }
        c.any = true;
        c.lastNs = ns + c.offsetNs;
        return c.lastNs;
    }
};

TakeRecorder::TakeRecorder(ServiceConfig config)
    : config_(std::move(config)), queueLimitBytes_(uint64_t(config_.record.queueMb) << 20) {}

TakeRecorder::~TakeRecorder() {
    if (recording()) {
        Result<std::string> stopped = stop();
        if (!stopped) logError("recording: {}", stopped.message());
    }
    finishWriter();
}

bool TakeRecorder::recording() const {
    std::lock_guard lock(mutex_);
    return status_.recording;
}

RecordStatus TakeRecorder::status() const {
    std::lock_guard lock(mutex_);
    RecordStatus s = status_;
    if (s.recording)
        s.seconds = std::chrono::duration<double>(Clock::now() - rollingSince_).count();
    return s;
}

void TakeRecorder::finishWriter() {
    if (writer_.joinable()) writer_.join();
}

Result<std::string> TakeRecorder::start(const std::string& name,
                                        std::shared_ptr<const LiveLighting> lighting) {
    {
        std::lock_guard lock(mutex_);
        if (phase_ == Phase::Starting) return makeError("already recording (a take is starting)");
        if (phase_ == Phase::Stopping)
            return makeError("the take {} is still stopping; start again once it has stopped",
                             status_.path);
        // Rolling without recording: the take stopped by itself (a full disk) and may restart.
        if (phase_ == Phase::Rolling && status_.recording)
            return makeError("already recording {}", status_.path);
        phase_ = Phase::Starting;
    }
    Result<std::string> opened = openTake(name, std::move(lighting));
    {
        std::lock_guard lock(mutex_);
        phase_ = opened ? Phase::Rolling : Phase::Idle;
    }
    phaseChanged_.notify_all();
    return opened;
}

Result<std::string> TakeRecorder::openTake(const std::string& name,
                                           std::shared_ptr<const LiveLighting> lighting) {
    finishWriter();  // a take that stopped by itself
    if (!validTakeName(name))
        return makeError("take name '{}': use at most 64 letters, digits, '-' and '_'", name);
    const std::string root = takesFolder(config_.record);
    std::error_code ec;
    fs::create_directories(root, ec);
    if (ec || ::access(root.c_str(), W_OK | X_OK) != 0)
        return makeError("cannot record into {}: {}; set [record] dir to a writable folder", root,
                         ec ? ec.message() : std::strerror(errno));
    const std::optional<uint64_t> free = freeBytes(root);
    const uint64_t minFree = config_.record.minFreeMb << 20;
    if (!free || *free < minFree)
        return makeError("cannot record into {}: {} MiB free, under [record] min_free_mb = {}",
                         root, free ? *free >> 20 : 0, config_.record.minFreeMb);
    std::string dir = (fs::path(root) / takeFolderName(name)).string();
    for (int n = 2; fs::exists(dir, ec); ++n)
        dir = (fs::path(root) / (takeFolderName(name) + "-" + std::to_string(n))).string();
    if (!fs::create_directory(dir, ec))
        return makeError("cannot create the take folder {}: {}", dir, ec.message());
    auto abandon = [&](const Error& e) -> Result<std::string> {
        fs::remove_all(dir, ec);
        return e;
    };
    Result<std::string> configToml = copyConfigIntoTake(config_, dir);
    if (!configToml) return abandon(configToml.error());
    SessionWriterOptions options;
    options.cameraRoles["scene"] = "scene";
    if (config_.fisheyeCamera) options.cameraRoles["fisheye"] = "fisheye";
    options.configToml = *configToml;
    options.flushInterval = std::chrono::milliseconds(config_.record.flushIntervalMs);
    Result<SessionWriter> writer = SessionWriter::create(dir, options);
    if (!writer) return abandon(writer.error());

    auto take = std::make_unique<Take>(std::move(*writer));
    take->dir = dir;
    take->minFreeBytes = minFree;
    if (Status s = setLabelRules(*take); !s) return abandon(s.error());
    {
        std::lock_guard lock(mutex_);
        status_ = RecordStatus{};
        freedRate_ = FreedRate{};
        status_.recording = true;
        rollingSince_ = Clock::now();
        status_.path = dir;
        status_.freeBytes = *free;
        accepting_ = true;
        draining_ = false;
    }
    keepCaptured_.store(true);
    if (lighting) push(std::move(lighting), 0);
    writer_ = std::thread([this, t = std::move(take)]() mutable { runWriter(std::move(t)); });
    logInfo("recording: take {} started", dir);
    return dir;
}

Result<std::string> TakeRecorder::stop() {
    std::unique_lock lock(mutex_);
    phaseChanged_.wait(lock, [&] { return phase_ != Phase::Starting; });
    if (phase_ == Phase::Stopping) {
        const uint64_t seen = stopsFinished_;
        phaseChanged_.wait(lock, [&] { return stopsFinished_ != seen; });
        return lastStopped_;
    }
    if (!status_.recording) return makeError("not recording");
    phase_ = Phase::Stopping;
    accepting_ = false;
    draining_ = true;
    const std::string dir = status_.path;
    lock.unlock();
    keepCaptured_.store(false);
    wake_.notify_all();
    finishWriter();
    lock.lock();
    logInfo("recording: take {} stopped: {} frames, {:.1f} MiB, {} dropped", dir, status_.frames,
            double(status_.bytes) / (1 << 20), status_.dropped);
    phase_ = Phase::Idle;
    lastStopped_ = dir;
    ++stopsFinished_;
    lock.unlock();
    phaseChanged_.notify_all();
    return dir;
}

void TakeRecorder::push(Item item, size_t bytes) {
    {
        std::lock_guard lock(mutex_);
        if (!accepting_) return;
        if (bytes > 0 && queuedBytes_ + bytes > queueLimitBytes_) {
            // The disk is slower than the cameras: this frame is lost to the take, never
            // silently (the count is in the status; the log says so now and then).
            if (status_.dropped++ % 100 == 0)
                logWarning("recording: the disk cannot keep up; {} frame(s) dropped so far",
                           status_.dropped);
            return;
        }
        queuedBytes_ += bytes;
        queue_.emplace_back(std::move(item), bytes);
    }
    wake_.notify_one();
}

void TakeRecorder::addFrame(const std::string& camera, std::shared_ptr<const Frame> frame) {
    if (!frame) return;
    const size_t bytes = std::max<size_t>(frameBytes(*frame), 1);
    std::string timecode, rate;
    if (camera == "scene") {
        lastSceneNs_.store(frame->timestampNs);
        if (timecodeSource_ && keepCaptured_.load(std::memory_order_relaxed)) {
            const Timecode label = timecodeSource_
                                       ->frameTimecode(int64_t(frame->timestampNs),
                                                       frame->wallClockNs, frame->sequence)
                                       .timecode;
            timecode = label.toString();
            rate = label.rate().name();
        }
    }
    push(FrameItem{camera, std::move(frame), std::move(timecode), std::move(rate)}, bytes);
}

void TakeRecorder::addPose(const TrackedFrame& tracked) {
    if (!tracked.frame) return;
    PoseRecord pose;
    pose.timestampNs = tracked.frame->timestampNs;
    pose.frame = tracked.frame->sequence;
    auto matrix = [](const cv::Matx44d& m) {
        std::array<double, 16> a{};
        for (int i = 0; i < 16; ++i) a[size_t(i)] = m(i / 4, i % 4);
        return a;
    };
    // The pose tracked on this very frame; a held pose (lost) is not this frame's.
    if (tracked.trackedWorldFromCamera) {
        pose.kind = PoseKind::Tracked;
        pose.worldFromCamera = matrix(*tracked.trackedWorldFromCamera);
        pose.reprojErrorPx = tracked.reprojErrorPx;
        pose.tags = tracked.tags;
    } else {
        pose.kind = PoseKind::Lost;
    }
    // And the live filter's, the one the preview composited, so a final render can choose.
    std::optional<PoseRecord> filtered;
    if (tracked.trackedWorldFromCamera && tracked.filtered && tracked.worldFromCamera) {
        filtered = pose;
        filtered->kind = PoseKind::Filtered;
        filtered->worldFromCamera = matrix(*tracked.worldFromCamera);
    }
    push(std::move(pose), 0);
    if (filtered) push(std::move(*filtered), 0);
}

void TakeRecorder::addEvent(SessionEvent event) {
    // On the scene camera's clock, which a replay fires events by: after the last frame seen.
    if (event.timestampNs == 0) event.timestampNs = lastSceneNs_.load() + 1;
    push(std::move(event), 0);
}

void TakeRecorder::addFreedPacket(int64_t receivedNs, std::span<const uint8_t> datagram) {
    // Counted against the queue as what it costs in memory, within its own share of it, and at
    // most kFreedRecordHz: a flood of valid packets is bounded in memory, in the take's
    // freed.csv and in the time a stop takes to drain, and never crowds out a frame.
    const size_t bytes = sizeof(std::pair<Item, size_t>) + datagram.size();
    {
        std::lock_guard lock(mutex_);
        if (!accepting_) return;
        if (!freedRate_.take(receivedNs) ||
            freedQueuedBytes_ + bytes > queueLimitBytes_ / kFreedQueueShare ||
            queuedBytes_ + bytes > queueLimitBytes_) {
            if (status_.freedDropped++ % 1000 == 0)
                logWarning(
                    "recording: FreeD packets beyond {} a second or the queue's share: {} left "
                    "out of the take so far (a flood on [tracking] listen?)",
                    kFreedRecordHz, status_.freedDropped);
            return;
        }
        freedQueuedBytes_ += bytes;
        queuedBytes_ += bytes;
        queue_.emplace_back(FreedPacket{receivedNs, {datagram.begin(), datagram.end()}}, bytes);
    }
    wake_.notify_one();
}

bool TakeRecorder::FreedRate::take(int64_t nowNs) {
    if (lastNs != 0 && nowNs > lastNs)
        tokens = std::min(double(kFreedBurst),
                          tokens + double(nowNs - lastNs) * 1e-9 * double(kFreedRecordHz));
    lastNs = std::max(lastNs, nowNs);
    if (tokens < 1.0) return false;
    tokens -= 1.0;
    return true;
}

void TakeRecorder::addLighting(std::shared_ptr<const LiveLighting> lighting) {
    if (lighting) push(std::move(lighting), 0);
}

void TakeRecorder::addPlateConsistency(const PlateConsistencyReading& reading) {
    push(reading, 0);  // one short line, as a FreeD packet
}

Status TakeRecorder::writeFrame(Take& take, const FrameItem& item) {
    const Frame& frame = *item.frame;
    std::vector<uint8_t> png;
    std::span<const uint8_t> bytes;
    std::string ext = "png";
    if (frame.captured && !frame.captured->empty()) {
        // As the camera sent it: a JPEG's bytes, a raw format's planes (".yuyv", ".nv12", ...).
        bytes = *frame.captured;
        ext = isJpegFourcc(frame.capturedFourcc) ? "jpg" : fourccToString(frame.capturedFourcc);
        for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    } else {
        Result<std::vector<uint8_t>> encoded = encodeFramePng(frame);
        if (!encoded) return encoded.error();
        png = std::move(*encoded);
        bytes = png;
    }
    FrameStamp stamp;
    if (frame.wallClockNs > 0) {
        stamp.wallClockNs = frame.wallClockNs;
        // The label and the rate it counts at, recorded together (docs/session-format.md).
        if (!item.timecode.empty()) {
            stamp.timecode = item.timecode;
            stamp.timecodeRate = item.timecodeRate;
        } else {
            const TimecodeRate rate = take.timecodeRates.at(item.camera);
            stamp.timecode = clockTimecode(frame.wallClockNs, rate).toString();
            stamp.timecodeRate = rate.name();
        }
    }
    // Every bracket frame with its exposure, so a replay merges the brackets as the box did.
    stamp.exposureStops = frame.exposureStops;
    const uint64_t ns = take.takeTimestamp(item.camera, frame.timestampNs, frame.sequence);
    if (Status s = take.writer.writeFrame(item.camera, frame.sequence, ns, bytes, ext, frame.width,
                                          frame.height, stamp);
        !s)
        return s;
    std::lock_guard lock(mutex_);
    status_.bytes += bytes.size();
    if (item.camera == "scene") ++status_.frames;
    return {};
}

Status TakeRecorder::setLabelRules(Take& take) const {
    std::vector<std::pair<std::string, const CameraConfig*>> cameras{
        {"scene", &config_.sceneCamera}};
    if (config_.fisheyeCamera) cameras.emplace_back("fisheye", &*config_.fisheyeCamera);
    for (const auto& [name, camera] : cameras) {
        Result<LabelRateRule> rule = labelRateRule(config_, *camera);
        if (!rule) return rule.error();
        take.labelRules.insert_or_assign(name, *rule);
        // A camera whose rate the config decides needs no measuring.
        if (std::optional<TimecodeRate> known = rule->fromConfig())
            take.timecodeRates.insert_or_assign(name, *known);
    }
    return {};
}

Status TakeRecorder::write(Take& take, Item& item) {
    if (auto* f = std::get_if<FrameItem>(&item)) {
        if (take.timecodeRates.count(f->camera)) return writeFrame(take, *f);
        // A camera without a configured fps: its timecode rate is its frame rate, measured on
        // its first two frames, so the first waits for the second.
        auto pending = take.firstFrames.find(f->camera);
        if (pending == take.firstFrames.end()) {
            take.firstFrames.emplace(f->camera, *f);
            return {};
        }
        const uint64_t dt = f->frame->timestampNs - pending->second.frame->timestampNs;
        take.timecodeRates.insert_or_assign(
            f->camera, take.labelRules[f->camera].rate(dt > 0 ? std::optional(1e9 / double(dt))
                                                              : std::nullopt));
        const FrameItem first = pending->second;
        take.firstFrames.erase(pending);
        if (Status s = writeFrame(take, first); !s) return s;
        return writeFrame(take, *f);
    }
    if (auto* pose = std::get_if<PoseRecord>(&item)) {
        const Take::CameraClock& c = take.clocks["scene"];
        pose->timestampNs += c.offsetNs;
        return take.writer.writePose(*pose);
    }
    if (auto* event = std::get_if<SessionEvent>(&item)) return take.writer.writeEvent(*event);
    if (auto* packet = std::get_if<FreedPacket>(&item))
        return take.writer.appendRecord("freed.csv", kFreedRecordingHeader,
                                        freedRecordingLine(packet->receivedNs, packet->bytes));
    if (auto* plate = std::get_if<PlateConsistencyReading>(&item)) {
        // On the scene camera's clock in the take, as its poses (docs/session-format.md).
        const PlateConsistency& v = plate->value;
        return take.writer.appendRecord(
            "plate_consistency.csv",
            "timestamp_ns,frame,ratio_r,ratio_g,ratio_b,spread_r,spread_g,spread_b,pixels,ok",
            fmt::format("{},{},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{},{}\n",
                        plate->timestampNs + take.clocks["scene"].offsetNs, plate->frame,
                        v.ratio[0], v.ratio[1], v.ratio[2], v.spread[0], v.spread[1], v.spread[2],
                        v.pixels, v.ok ? 1 : 0));
    }
    const auto& lit = std::get<std::shared_ptr<const LiveLighting>>(item);
    const uint64_t ns = lit->timestampNs + take.clocks["fisheye"].offsetNs;
    return take.writer.writeLighting(
        ns, [&](AtomicFile& file) { return writeLightingMap(*lit, file); },
        estimatedLightsJson(lit->lights));
}

void TakeRecorder::runWriter(std::unique_ptr<Take> take) {
    pthread_setname_np(pthread_self(), "pv-recorder");
    std::string stoppedBecause;
    for (;;) {
        std::optional<std::pair<Item, size_t>> next;
        {
            // Idle, the writer still makes what it wrote durable when due (flushIfDue below).
            const std::optional<Clock::time_point> flushDue = take->writer.flushDue();
            const Clock::time_point wakeBy = std::min(Clock::now() + std::chrono::milliseconds(200),
                                                      flushDue.value_or(Clock::time_point::max()));
            std::unique_lock lock(mutex_);
            wake_.wait_until(lock, wakeBy, [&] { return !queue_.empty() || draining_; });
            if (!queue_.empty()) {
                next = std::move(queue_.front());
                queue_.pop_front();
                queuedBytes_ -= next->second;
                if (std::holds_alternative<FreedPacket>(next->first))
                    freedQueuedBytes_ -= next->second;
            } else if (draining_) {
                break;
            }
        }
        if (next) {
            if (Status s = write(*take, next->first); !s) {
                stoppedBecause = s.message();
                break;
            }
        }
        if (Status s = take->writer.flushIfDue(); !s) {
            stoppedBecause = s.message();
            break;
        }
        if (Clock::now() - take->lastSpaceCheck > std::chrono::seconds(1)) {
            take->lastSpaceCheck = Clock::now();
            const std::optional<uint64_t> free = freeBytes(take->dir);
            std::lock_guard lock(mutex_);
            status_.freeBytes = free.value_or(0);
            if (free && *free < take->minFreeBytes) {
                stoppedBecause = fmt::format(
                    "the disk holding {} has {} MiB free, under [record] min_free_mb = {}",
                    take->dir, *free >> 20, take->minFreeBytes >> 20);
                break;
            }
        }
    }
    // A camera that sent one frame only: nothing measured (the rule's 30).
    for (auto& [camera, first] : take->firstFrames) {
        take->timecodeRates.insert_or_assign(camera, take->labelRules[camera].rate());
        if (Status s = writeFrame(*take, first); !s && stoppedBecause.empty())
            stoppedBecause = s.message();
    }
    Status flushed = take->writer.flush();
    if (!flushed && stoppedBecause.empty()) stoppedBecause = flushed.message();
    std::lock_guard lock(mutex_);
    if (!stoppedBecause.empty()) {
        // Everything before the failure is in the take; what was still queued is not.
        status_.dropped += size_t(std::count_if(queue_.begin(), queue_.end(), [](const auto& q) {
            return std::holds_alternative<FrameItem>(q.first);
        }));
        logError("recording: take {} stopped: {}; the service goes on previewing", take->dir,
                 stoppedBecause);
        status_.stoppedBecause = stoppedBecause;
    }
    queue_.clear();
    queuedBytes_ = 0;
    freedQueuedBytes_ = 0;
    keepCaptured_.store(false);
    accepting_ = false;
    draining_ = false;
    if (status_.recording)
        status_.seconds = std::chrono::duration<double>(Clock::now() - rollingSince_).count();
    status_.recording = false;
}

}  // namespace previs
