#pragma once

// Which of a service's threads is stuck (DESIGN.md §6: one thread per source and stage). Each
// thread marks the steps it takes (a frame captured, a tag detection, a render, a frame shown);
// a step that lasts longer than the limit is a hang. A thread that waits for work is idle, never
// stuck, so a camera that sends nothing or a preview that is not asked for is not a hang. The
// service's main loop feeds systemd's watchdog only while no stage is stuck (daemon/service.cpp):
// a hung capture, tracking, lighting, render or display thread gets the service restarted, with
// the stage named in the log.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <string>
#include <vector>

namespace previs {

// One thread's steps. Thread-safe: the owner begins and ends them, any thread reads.
class Stage {
public:
    explicit Stage(std::string name) : name_(std::move(name)) {}
    const std::string& name() const { return name_; }

    void begin(int64_t nowNs) {
        allowanceNs_.store(0);
        stepStartNs_.store(nowNs);
    }
    void end() {
        stepStartNs_.store(0);
        allowanceNs_.store(0);
    }
    // The step now under way may take `allowance` longer than any other (a pipeline compile on
    // a slow CPU: minutes on lavapipe under an emulated CPU), counted from its start.
    void allowLonger(std::chrono::nanoseconds allowance) {
        allowanceNs_.store(allowance.count());
        longerSteps_.fetch_add(1);
    }
    // How many steps were allowed longer so far: on a GPU context's stage, the pipelines compiled
    // (previsd's start counts them for its status).
    uint64_t longerSteps() const { return longerSteps_.load(); }

    // How long the step under way has been running beyond `limitNs` plus its allowance; 0 when
    // idle or within them.
    int64_t overdueNs(int64_t nowNs, int64_t limitNs) const;
    // How long the step under way has been running; 0 when idle.
    int64_t runningNs(int64_t nowNs) const;

private:
    const std::string name_;
    std::atomic<int64_t> stepStartNs_{0};  // 0: idle
    std::atomic<int64_t> allowanceNs_{0};
    std::atomic<uint64_t> longerSteps_{0};
};

// A step for the lifetime of a scope, timed by the steady clock.
class StageStep {
public:
    explicit StageStep(Stage* stage);
    ~StageStep();
    StageStep(const StageStep&) = delete;
    StageStep& operator=(const StageStep&) = delete;

private:
    Stage* stage_;
};

// The steady clock in nanoseconds, as Stage takes it.
int64_t stageClockNs();

class StageWatch {
public:
    // A stage to hand to its thread; the reference stays valid as long as the watch.
    Stage& add(std::string name);
    struct Stuck {
        std::string name;
        double seconds;  // in its step so far
    };
    // The stages whose step has lasted longer than `limitNs` (plus its allowance) at `nowNs`.
    std::vector<Stuck> stuck(int64_t nowNs, int64_t limitNs) const;

private:
    std::deque<Stage> stages_;  // stable addresses; added before the threads start
};

}  // namespace previs
