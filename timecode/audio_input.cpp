#include "timecode/audio_input.h"

#include <alsa/asoundlib.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <ctime>
#include <fstream>

#include "base/guarded_thread.h"
#include "base/log.h"
#include "base/monotonic_clock.h"

namespace previs {

namespace {

// How long one wait for samples may block, so the thread sees a stop request promptly.
constexpr int kWaitMs = 100;
// A chunk whose measured time is further than this from the one its predecessor predicts starts
// the smoothing over (an overrun, a stall): scheduling jitter is well below it.
constexpr int64_t kResyncNs = 5'000'000;
// How far a late measurement pulls the time line: 1/64 a chunk follows a drift of 100 ppm (1 µs
// per 10 ms chunk) while averaging scheduling jitter down 64 times.
constexpr int64_t kLateWeight = 64;

uint32_t le32(const uint8_t* p) { return p[0] | p[1] << 8 | p[2] << 16 | uint32_t(p[3]) << 24; }
uint16_t le16(const uint8_t* p) { return uint16_t(p[0] | p[1] << 8); }

struct WavFormat {
    int format = 0;  // 1 PCM, 3 float
    int channels = 0;
    int sampleRate = 0;
    int bits = 0;
};

float sampleAt(const uint8_t* p, const WavFormat& f) {
    if (f.format == 3) {
        float value;
        std::memcpy(&value, p, 4);
        return value;
    }
    switch (f.bits) {
        case 16:
            return float(int16_t(le16(p))) / 32768.0f;
        case 24:
            // The 24 bits placed at the top of an int32, shifted back down with their sign.
            return float(
                       int32_t(uint32_t(p[0]) << 8 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 24) >>
                       8) /
                   8388608.0f;
        default:
            return float(int32_t(le32(p))) / 2147483648.0f;
    }
}

Result<AudioClip> parseWav(const std::string& path, const std::vector<uint8_t>& bytes,
                           int channel) {
    if (bytes.size() < 12 || std::memcmp(bytes.data(), "RIFF", 4) != 0 ||
        std::memcmp(bytes.data() + 8, "WAVE", 4) != 0)
        return makeError("{}: not a RIFF/WAVE file", path);
    WavFormat fmtChunk;
    for (size_t at = 12; at + 8 <= bytes.size();) {
        const uint8_t* chunk = bytes.data() + at;
        const size_t size = le32(chunk + 4);
        const size_t body = at + 8;
        if (body + size > bytes.size())
            return makeError("{}: chunk runs past the file's end", path);
        if (std::memcmp(chunk, "fmt ", 4) == 0 && size >= 16) {
            fmtChunk = {le16(chunk + 8), le16(chunk + 10), int(le32(chunk + 12)), le16(chunk + 22)};
            // WAVE_FORMAT_EXTENSIBLE: the real format is the sub-format GUID's first two bytes.
            if (fmtChunk.format == 0xfffe && size >= 26) fmtChunk.format = le16(chunk + 32);
        } else if (std::memcmp(chunk, "data", 4) == 0) {
            const bool supported =
                (fmtChunk.format == 1 &&
                 (fmtChunk.bits == 16 || fmtChunk.bits == 24 || fmtChunk.bits == 32)) ||
                (fmtChunk.format == 3 && fmtChunk.bits == 32);
            if (!supported)
                return makeError(
                    "{}: WAV format {} with {}-bit samples is not supported (PCM 16/24/32 or float "
                    "32)",
                    path, fmtChunk.format, fmtChunk.bits);
            if (channel < 0 || channel >= fmtChunk.channels)
                return makeError("{}: channel {} asked, the file has {}", path, channel,
                                 fmtChunk.channels);
            const size_t frameBytes = size_t(fmtChunk.channels) * size_t(fmtChunk.bits / 8);
            AudioClip clip;
            clip.sampleRate = fmtChunk.sampleRate;
            clip.samples.reserve(size / frameBytes);
            for (size_t f = 0; (f + 1) * frameBytes <= size; ++f)
                clip.samples.push_back(sampleAt(
                    bytes.data() + body + f * frameBytes + size_t(channel) * (fmtChunk.bits / 8),
                    fmtChunk));
            return clip;
        }
        at = body + size + (size & 1);  // chunks are padded to even sizes
    }
    return makeError("{}: no data chunk", path);
}

void put16(std::ofstream& out, uint16_t v) {
    const char b[2] = {char(v & 0xff), char(v >> 8)};
    out.write(b, 2);
}
void put32(std::ofstream& out, uint32_t v) {
    put16(out, uint16_t(v & 0xffff));
    put16(out, uint16_t(v >> 16));
}

}  // namespace

void AlsaCapture::PcmDeleter::operator()(snd_pcm_t* pcm) const { snd_pcm_close(pcm); }

Result<std::unique_ptr<AlsaCapture>> AlsaCapture::create(const AlsaCaptureConfig& config,
                                                         AudioSink sink) {
    snd_pcm_t* pcm = nullptr;
    const int err =
        snd_pcm_open(&pcm, config.device.c_str(), SND_PCM_STREAM_CAPTURE, SND_PCM_NONBLOCK);
    if (err < 0)
        return makeError(
            "timecode audio device \"{}\": cannot open for capture: {} (check [timecode] device; "
            "`arecord -l` lists the cards)",
            config.device, snd_strerror(err));
    std::unique_ptr<AlsaCapture> capture(new AlsaCapture(config, pcm, std::move(sink)));
    if (Result<int> ok = capture->configure(); !ok) return ok.error();
    capture->thread_ = std::thread([raw = capture.get()] { raw->run(); });
    return capture;
}

Result<int> AlsaCapture::configure() {
    snd_pcm_t* pcm = pcm_.get();
    snd_pcm_hw_params_t* hw = nullptr;
    snd_pcm_hw_params_alloca(&hw);
    const auto fail = [&](const char* what, int err) {
        return makeError("timecode audio device \"{}\": {}: {}", config_.device, what,
                         snd_strerror(err));
    };
    int err = snd_pcm_hw_params_any(pcm, hw);
    if (err < 0) return fail("no capture configuration", err);
    if ((err = snd_pcm_hw_params_set_access(pcm, hw, SND_PCM_ACCESS_RW_INTERLEAVED)) < 0)
        return fail("interleaved access not supported", err);
    // 16 bits is what every USB interface offers; libltc decodes from 8 bits anyway.
    if ((err = snd_pcm_hw_params_set_format(pcm, hw, SND_PCM_FORMAT_S16_LE)) < 0)
        return fail("16-bit samples not supported (try \"plughw:...\")", err);
    unsigned channels = unsigned(config_.channel + 1);
    if ((err = snd_pcm_hw_params_set_channels_near(pcm, hw, &channels)) < 0 ||
        int(channels) <= config_.channel)
        return makeError(
            "timecode audio device \"{}\": has no channel {} ([timecode] channel "
            "counts from 0)",
            config_.device, config_.channel);
    unsigned rate = unsigned(config_.sampleRate);
    if ((err = snd_pcm_hw_params_set_rate_near(pcm, hw, &rate, nullptr)) < 0)
        return fail("sample rate not supported", err);
    snd_pcm_uframes_t period = snd_pcm_uframes_t(config_.periodFrames);
    snd_pcm_hw_params_set_period_size_near(pcm, hw, &period, nullptr);
    // Eight periods of buffer: a busy CPU delays a read, it does not overrun.
    snd_pcm_uframes_t buffer = period * 8;
    snd_pcm_hw_params_set_buffer_size_near(pcm, hw, &buffer);
    if ((err = snd_pcm_hw_params(pcm, hw)) < 0) return fail("cannot apply the configuration", err);
    if ((err = snd_pcm_start(pcm)) < 0) return fail("cannot start", err);
    sampleRate_ = int(rate);
    clock_ = ChunkClock(sampleRate_);
    channels_ = int(channels);
    config_.periodFrames = int(period);
    logInfo("timecode audio: \"{}\" at {} Hz, channel {} of {}, {} frames a period", config_.device,
            sampleRate_, config_.channel, channels_, config_.periodFrames);
    return 0;
}

AlsaCapture::~AlsaCapture() {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
}

std::optional<std::string> AlsaCapture::failure() const {
    std::lock_guard lock(failureMutex_);
    return failure_;
}

int64_t ChunkClock::stamp(int64_t measuredNs, int64_t frames) {
    int64_t t = measuredNs;
    if (nextNs_) {
        const int64_t error = measuredNs - *nextNs_;
        if (std::abs(error) < kResyncNs)
            t = *nextNs_ + (error > 0 ? error / kLateWeight : error / 2);
        // Far early is a misread delay, not lost samples (an overrun resets the clock): the
        // samples follow on from the last chunk's.
        else if (error < 0)
            t = *nextNs_;
        // Never before the last chunk: the chunks' order is the samples'.
        t = std::max(t, *lastNs_ + 1);
    }
    lastNs_ = t;
    nextNs_ = t + frames * 1'000'000'000 / sampleRate_;
    return t;
}

int64_t AlsaCapture::chunkTime(long frames) {
    snd_pcm_sframes_t delay = 0;
    if (snd_pcm_delay(pcm_.get(), &delay) < 0) delay = 0;
    // The first sample just read was captured (delay + frames) samples before now.
    return clock_.stamp(monotonicNowNs() - (int64_t(delay) + frames) * 1'000'000'000 / sampleRate_,
                        frames);
}

bool AlsaCapture::recover(long err) {
    if (err == -EAGAIN) return true;
    if (err == -EPIPE) ++overruns_;
    // Samples were lost: the time line starts over.
    clock_.reset();
    // After an overrun the stream is prepared again, not running; after a resume it runs.
    int result = snd_pcm_recover(pcm_.get(), int(err), 1);
    if (result >= 0 && snd_pcm_state(pcm_.get()) == SND_PCM_STATE_PREPARED)
        result = snd_pcm_start(pcm_.get());
    if (result < 0) {
        const std::string why = fmt::format("timecode audio device \"{}\": capture stopped: {}",
                                            config_.device, snd_strerror(int(err)));
        logError("{}", why);
        std::lock_guard lock(failureMutex_);
        failure_ = why;
        return false;
    }
    return true;
}

void AlsaCapture::run() {
    runGuarded("timecode audio", [&] {
        std::vector<int16_t> interleaved(size_t(config_.periodFrames) * size_t(channels_));
        std::vector<float> mono(size_t(config_.periodFrames));
        while (!stop_) {
            const int ready = snd_pcm_wait(pcm_.get(), kWaitMs);
            if (ready == 0) continue;  // nothing yet; look at stop_ again
            if (ready < 0) {
                if (!recover(ready)) return;
                continue;
            }
            const snd_pcm_sframes_t n = snd_pcm_readi(pcm_.get(), interleaved.data(),
                                                      snd_pcm_uframes_t(config_.periodFrames));
            if (n < 0) {
                if (!recover(long(n))) return;
                continue;
            }
            for (snd_pcm_sframes_t i = 0; i < n; ++i)
                mono[size_t(i)] =
                    float(interleaved[size_t(i) * size_t(channels_) + size_t(config_.channel)]) /
                    32768.0f;
            sink_(std::span<const float>(mono.data(), size_t(n)), chunkTime(long(n)));
        }
    });
}

Result<AudioClip> readAudioFile(const std::string& path, int channel, int rawSampleRate) {
    std::ifstream in(path, std::ios::binary);
    if (!in) return makeError("{}: cannot open: {}", path, std::strerror(errno));
    std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)),
                               std::istreambuf_iterator<char>());
    if (path.ends_with(".wav") || path.ends_with(".WAV")) return parseWav(path, bytes, channel);
    AudioClip clip;
    clip.sampleRate = rawSampleRate;
    for (size_t i = 0; i + 1 < bytes.size(); i += 2)
        clip.samples.push_back(float(int16_t(le16(&bytes[i]))) / 32768.0f);
    return clip;
}

Status writeWavFile(const std::string& path, const AudioClip& clip) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) return makeError("{}: cannot write: {}", path, std::strerror(errno));
    const uint32_t dataBytes = uint32_t(clip.samples.size() * 2);
    out.write("RIFF", 4);
    put32(out, 36 + dataBytes);
    out.write("WAVEfmt ", 8);
    put32(out, 16);
    put16(out, 1);  // PCM
    put16(out, 1);  // mono
    put32(out, uint32_t(clip.sampleRate));
    put32(out, uint32_t(clip.sampleRate) * 2);
    put16(out, 2);
    put16(out, 16);
    out.write("data", 4);
    put32(out, dataBytes);
    for (float s : clip.samples) {
        const float clamped = std::min(std::max(s, -1.0f), 32767.0f / 32768.0f);
        put16(out, uint16_t(int16_t(std::lround(clamped * 32768.0f))));
    }
    out.flush();
    if (!out) return makeError("{}: write failed: {}", path, std::strerror(errno));
    return {};
}

void playAudioClip(const AudioClip& clip, int64_t firstSampleMonoNs, int chunkFrames,
                   const AudioSink& sink) {
    const size_t chunk = size_t(std::max(chunkFrames, 1));
    for (size_t at = 0; at < clip.samples.size(); at += chunk) {
        const size_t n = std::min(chunk, clip.samples.size() - at);
        const int64_t t = firstSampleMonoNs + int64_t(at) * 1'000'000'000 / clip.sampleRate;
        sink(std::span<const float>(clip.samples.data() + at, n), t);
    }
}

}  // namespace previs
