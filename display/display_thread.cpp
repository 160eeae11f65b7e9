#include "display/display_thread.h"

#include <chrono>

#include "base/guarded_thread.h"
#include "base/log.h"

namespace previs {

DisplayThread::DisplayThread(std::unique_ptr<FrameOutput> output, Stage* stage)
    : output_(std::move(output)), stage_(stage) {
    stats_.kind = output_->kind();
    thread_ = std::thread([this] {
        // Names show in top -H and /proc/PID/task/*/comm (15 characters at most).
        pthread_setname_np(pthread_self(), "pv-display");
        // run() returns only when stopping; an exception from an output counts as a failed
        // frame and the loop goes on with the next one.
        for (bool failed = true; failed;) {
            failed = false;
            runGuarded(
                "display", [this] { run(); },
                [&](const std::string&) {
                    failed = true;
                    std::lock_guard lock(statsMutex_);
                    ++stats_.failed;
                });
        }
    });
}

DisplayThread::~DisplayThread() { stop(); }

void DisplayThread::submit(std::shared_ptr<const DisplayFrame> frame) {
    if (slot_.publish(std::move(frame))) dropped_.fetch_add(1);
}

void DisplayThread::stop() {
    {
        std::lock_guard lock(slot_.mutex());
        stopping_ = true;
    }
    slot_.wakeAll();
    if (thread_.joinable()) thread_.join();
}

DisplayStats DisplayThread::stats() const {
    std::lock_guard lock(statsMutex_);
    DisplayStats s = stats_;
    s.dropped = dropped_.load();
    return s;
}

void DisplayThread::run() {
    uint64_t failuresLogged = 0;
    for (;;) {
        std::shared_ptr<const DisplayFrame> frame = slot_.waitTake(stopping_);
        if (!frame) return;
        const Status status = [&] {
            StageStep step(stage_);
            return output_->show(*frame);
        }();
        const std::string kind = output_->kind();
        const int64_t nowNs = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                  std::chrono::steady_clock::now().time_since_epoch())
                                  .count();
        const bool droppedByOutput = status.ok() && output_->lastFrameDropped();
        if (droppedByOutput) dropped_.fetch_add(1);
        const bool shown = status.ok() && kind != "lost" && !droppedByOutput;
        {
            std::lock_guard lock(statsMutex_);
            stats_.kind = kind;
            if (shown) {
                ++stats_.shown;
                stats_.lastShownNs = nowNs;
                stats_.lastCaptureTimestampNs = frame->captureTimestampNs;
                stats_.lastIndex = frame->index;
            } else if (!droppedByOutput) {
                ++stats_.failed;
            }
        }
        // A failing output (e.g. a full disk) would log every frame: the first few, then every
        // 100th.
        if (!status.ok() && (failuresLogged < 5 || failuresLogged % 100 == 0))
            logError("{}", status.message());
        if (!status.ok()) ++failuresLogged;
    }
}

}  // namespace previs
