#include "capture/camera_source.h"

#include <time.h>

#include <utility>

#include "base/guarded_thread.h"
#include "base/log.h"

namespace previs {

namespace {

uint64_t clockNs(clockid_t clock) {
    timespec ts{};
    clock_gettime(clock, &ts);
    return uint64_t(ts.tv_sec) * 1'000'000'000ull + uint64_t(ts.tv_nsec);
}

// The wall clock when a frame stamped `monotonicNs` was captured: now on CLOCK_REALTIME less the
// frame's age on CLOCK_MONOTONIC. A timestamp not on this boot's monotonic clock (a recording's,
// or in the future) gets the wall clock of its arrival.
uint64_t wallClockOf(uint64_t monotonicNs) {
    const uint64_t mono = clockNs(CLOCK_MONOTONIC);
    const uint64_t wall = clockNs(CLOCK_REALTIME);
    const uint64_t age = mono - monotonicNs;
    return monotonicNs <= mono && age < 10'000'000'000ull ? wall - age : wall;
}

}  // namespace

const char* toString(CaptureState state) {
    switch (state) {
        case CaptureState::Stopped:
            return "stopped";
        case CaptureState::Opening:
            return "opening";
        case CaptureState::Streaming:
            return "streaming";
        case CaptureState::Lost:
            return "lost";
        case CaptureState::Finished:
            return "finished";
    }
    return "?";
}

CaptureThread::CaptureThread(FrameReaderFactory factory, CaptureOptions options)
    : factory_(std::move(factory)), options_(std::move(options)) {}

CaptureThread::~CaptureThread() { stop(); }

Status CaptureThread::start() {
    if (thread_.joinable()) return makeError("{}: already started", options_.name);
    if (!factory_) return makeError("{}: no frame source configured", options_.name);
    {
        std::lock_guard lock(stopMutex_);
        stopRequested_ = false;
    }
    state_ = CaptureState::Opening;
    thread_ = std::thread([this] {
        // Whatever escapes the loop counts as losing the device: reopen after the retry
        // interval, as for a camera that was unplugged.
        for (;;) {
            bool failed = false;
            runGuarded(
                options_.name.c_str(), [this] { run(); },
                [&](const std::string& why) {
                    failed = true;
                    setState(CaptureState::Lost, why);
                });
            if (!failed || waitForStop(options_.retryIntervalMs)) break;
        }
    });
    return {};
}

void CaptureThread::stop() {
    {
        std::lock_guard lock(stopMutex_);
        stopRequested_ = true;
    }
    stopCv_.notify_all();
    if (thread_.joinable()) thread_.join();
    state_ = CaptureState::Stopped;
}

CaptureStats CaptureThread::stats() const {
    CaptureStats s;
    s.state = state_.load();
    s.delivered = delivered_.load();
    s.dropped = slot_.dropped();
    s.badFrames = badFrames_.load();
    s.withheld = withheld_.load();
    s.reconnects = reconnects_.load();
    std::lock_guard lock(problemMutex_);
    s.problem = problem_;
    return s;
}

bool CaptureThread::waitForStop(int ms) {
    std::unique_lock lock(stopMutex_);
    return stopCv_.wait_for(lock, std::chrono::milliseconds(ms), [this] { return stopRequested_; });
}

void CaptureThread::setState(CaptureState state, const std::string& detail) {
    {
        std::lock_guard lock(problemMutex_);
        problem_ = state == CaptureState::Lost ? detail : std::string();
    }
    // One log line per change, not per retry: a camera left unplugged for an hour must not
    // fill the journal.
    const CaptureState old = state_.exchange(state);
    if (old == state) return;
    switch (state) {
        case CaptureState::Streaming:
            logInfo("{}: streaming{}", options_.name, detail.empty() ? "" : " (" + detail + ")");
            break;
        case CaptureState::Lost:
            logWarning("{}: {} (retrying every {} ms)", options_.name, detail,
                       options_.retryIntervalMs);
            break;
        case CaptureState::Finished:
            logInfo("{}: end of source", options_.name);
            break;
        default:
            break;
    }
}

void CaptureThread::run() {
    using Clock = std::chrono::steady_clock;
    std::unique_ptr<FrameReader> reader;
    uint64_t badBase = 0;
    uint64_t withheldBase = 0;
    bool everStreamed = false;
    Clock::time_point lastFrame;
    Clock::time_point lostSince;
    // Drops are logged as a summary at most every kDropLogInterval: a consumer that is slow
    // for a while must be visible in the log without one line per frame.
    constexpr auto kDropLogInterval = std::chrono::seconds(10);
    Clock::time_point dropLogTime = Clock::now();
    uint64_t droppedLogged = 0;
    uint64_t deliveredAtDropLog = 0;

    auto dropReader = [&](const std::string& why) {
        if (reader) {
            badBase += reader->badFrames();
            withheldBase += reader->withheldFrames();
            reader.reset();
        }
        if (state_.load() != CaptureState::Lost) lostSince = Clock::now();
        setState(CaptureState::Lost, why);
    };

    // Each pass is one step of the stage watch (base/stage_watch.h): opening the device, or one
    // bounded read and what follows it; the retry waits are idle.
    Stage* const stage = options_.stage;
    auto idle = [stage] {
        if (stage) stage->end();
    };
    while (true) {
        idle();
        {
            std::lock_guard lock(stopMutex_);
            if (stopRequested_) break;
        }
        if (stage) stage->begin(stageClockNs());
        if (!reader) {
            Result<std::unique_ptr<FrameReader>> opened = factory_();
            Status started = opened ? (*opened)->start() : Status(opened.error());
            if (!started) {
                dropReader(started.message());
                idle();
                if (waitForStop(options_.retryIntervalMs)) break;
                continue;
            }
            reader = std::move(*opened);
            lastFrame = Clock::now();
            std::string detail;
            if (everStreamed) {
                ++reconnects_;
                const auto ms =
                    std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - lostSince);
                detail =
                    fmt::format("back after {} ms, reconnect {}", ms.count(), reconnects_.load());
            }
            everStreamed = true;
            setState(CaptureState::Streaming, detail);
        }

        Frame frame;
        Result<bool> got = reader->read(options_.readTimeoutMs, frame);
        badFrames_ = badBase + (reader ? reader->badFrames() : 0);
        withheld_ = withheldBase + (reader ? reader->withheldFrames() : 0);
        if (!got) {
            dropReader(got.message());
            idle();
            if (waitForStop(options_.retryIntervalMs)) break;
            continue;
        }
        if (!*got) {
            if (reader->finished()) {
                setState(CaptureState::Finished, "");
                idle();
                // Stay alive until stop() so the state stays observable.
                while (!waitForStop(options_.readTimeoutMs)) {
                }
                break;
            }
            const auto silentMs =
                std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() - lastFrame)
                    .count();
            if (reader->isLive() && silentMs > options_.stallTimeoutMs)
                dropReader(fmt::format("no frame for {} ms", silentMs));
            continue;
        }
        lastFrame = Clock::now();
        // Counted before publishing, so stats().delivered never lags a frame already visible.
        frame.sequence = delivered_++;
        if (frame.wallClockNs == 0) frame.wallClockNs = wallClockOf(frame.timestampNs);
        auto shared = std::make_shared<const Frame>(std::move(frame));
        if (options_.onFrame) options_.onFrame(shared);
        slot_.publish(std::move(shared));
        if (lastFrame - dropLogTime >= kDropLogInterval) {
            const uint64_t dropped = slot_.dropped();
            if (dropped > droppedLogged)
                logWarning("{}: the consumer missed {} of the last {} frames ({} in total)",
                           options_.name, dropped - droppedLogged,
                           delivered_.load() - deliveredAtDropLog, dropped);
            droppedLogged = dropped;
            deliveredAtDropLog = delivered_.load();
            dropLogTime = lastFrame;
        }
    }
    idle();
    if (reader) {
        badBase += reader->badFrames();
        withheldBase += reader->withheldFrames();
    }
    badFrames_ = badBase;
    withheld_ = withheldBase;
    reader.reset();
}

}  // namespace previs
