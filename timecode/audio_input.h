#pragma once

// Audio for the LTC decoder: live from an ALSA capture device on its own thread, or from a file
// (WAV or raw samples) for tests and replay. Both hand mono float chunks to a sink together with
// the CLOCK_MONOTONIC time of each chunk's first sample, which is what maps a decoded LTC frame
// to the camera's timestamps.

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "base/result.h"

typedef struct _snd_pcm snd_pcm_t;

namespace previs {

// Called on the capture thread with consecutive chunks (mono, ±1.0 full scale).
using AudioSink = std::function<void(std::span<const float> samples, int64_t firstSampleMonoNs)>;

// The CLOCK_MONOTONIC time of each captured chunk's first sample. Each read gives a measurement
// (now − (samples still buffered + samples read) / rate) that is late by however long the thread
// waited to run, never early; consecutive chunks are also exactly their sample count apart on the
// sound card's clock. So each stamp follows the previous one by the sample count, moved a little
// toward a later measurement (the card's drift against CLOCK_MONOTONIC) and a lot toward an
// earlier one (the prediction was late).
class ChunkClock {
public:
    explicit ChunkClock(int sampleRate) : sampleRate_(sampleRate) {}
    int64_t stamp(int64_t measuredNs, int64_t frames);
    // Samples were lost (an overrun): start over from the next measurement.
    void reset() {
        nextNs_.reset();
        lastNs_.reset();
    }

private:
    int sampleRate_;
    std::optional<int64_t> nextNs_;
    std::optional<int64_t> lastNs_;
};

struct AlsaCaptureConfig {
    std::string device = "default";  // "hw:1,0", "plughw:1,0", "default"
    int channel = 0;                 // which channel of the device's frames carries LTC, from 0
    int sampleRate = 48000;
    int periodFrames = 480;  // 10 ms at 48 kHz: the chunk size and the latency it adds
};

class AlsaCapture {
public:
    // Opens and starts the device; the error names the device and what to check.
    static Result<std::unique_ptr<AlsaCapture>> create(const AlsaCaptureConfig& config,
                                                       AudioSink sink);
    ~AlsaCapture();
    AlsaCapture(const AlsaCapture&) = delete;
    AlsaCapture& operator=(const AlsaCapture&) = delete;

    int sampleRate() const { return sampleRate_; }
    int channels() const { return channels_; }
    // Why the capture thread stopped (device unplugged...), or nothing while it runs.
    std::optional<std::string> failure() const;
    uint64_t overruns() const { return overruns_.load(); }

private:
    struct PcmDeleter {
        void operator()(snd_pcm_t* pcm) const;
    };

    AlsaCapture(const AlsaCaptureConfig& config, snd_pcm_t* pcm, AudioSink sink)
        : config_(config), pcm_(pcm), sink_(std::move(sink)) {}

    Result<int> configure();
    void run();
    // Whether to go on after `err` from a read.
    bool recover(long err);
    // CLOCK_MONOTONIC of the first of the `frames` just read.
    int64_t chunkTime(long frames);

    AlsaCaptureConfig config_;
    std::unique_ptr<snd_pcm_t, PcmDeleter> pcm_;
    AudioSink sink_;
    int sampleRate_ = 0;
    int channels_ = 0;
    ChunkClock clock_{48000};
    std::atomic<bool> stop_ = false;
    std::atomic<uint64_t> overruns_ = 0;
    mutable std::mutex failureMutex_;
    std::optional<std::string> failure_;
    std::thread thread_;  // last: started once everything above is set
};

// Samples of one channel of a file.
struct AudioClip {
    std::vector<float> samples;
    int sampleRate = 48000;
};

// A WAV file (PCM 16/24/32-bit or 32-bit float, any channel count; `channel` picks one), or raw
// signed 16-bit little-endian mono samples at `rawSampleRate` (any other extension).
Result<AudioClip> readAudioFile(const std::string& path, int channel = 0,
                                int rawSampleRate = 48000);
// 16-bit PCM mono WAV.
Status writeWavFile(const std::string& path, const AudioClip& clip);
// Hands `clip` to `sink` in chunks of `chunkFrames` as though captured from `firstSampleMonoNs`
// on: what replay and tests feed a TimecodeSource with.
void playAudioClip(const AudioClip& clip, int64_t firstSampleMonoNs, int chunkFrames,
                   const AudioSink& sink);

}  // namespace previs
