#pragma once

// A disk cache of host-specialised SPIR-V (gpu/spirv_specialise.h). Specialising the megakernel
// with SPIRV-Tools takes a fifth of a second or more at every start and at every change of a
// scene's features; its output depends only on the input module, the constants and the
// optimiser, so it is kept on disk as Mesa keeps its compiled shaders. An entry is written once
// (to a temporary file, then renamed: readers never see half an entry) and checked when read
// (key and checksum): a damaged, truncated or foreign file is a miss, never a wrong shader.
//
// Where: $PREVIS_SHADER_CACHE_DIR, else $XDG_CACHE_HOME/previs/spirv, else
// $HOME/.cache/previs/spirv (previsd.service sets the first to its CacheDirectory=).
// PREVIS_SHADER_CACHE_DISABLE=1 (or true) turns it off. A cache that cannot be written (a
// read-only home, a full disk) costs the specialisation, nothing else.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

class SpirvCache {
public:
    // The cache the environment names (above); disabled when it names none.
    static SpirvCache fromEnvironment();
    // A cache in `dir` holding at most `maxBytes` of entries (the oldest used go first).
    explicit SpirvCache(std::filesystem::path dir, uint64_t maxBytes = kDefaultMaxBytes);
    // No cache: every lookup misses, nothing is written.
    SpirvCache() = default;

    bool enabled() const { return !dir_.empty(); }
    const std::filesystem::path& dir() const { return dir_; }

    // The specialised module for `spirv` with `constants`: from the cache, or specialised now
    // and stored.
    Result<std::vector<uint32_t>> specialise(std::span<const uint32_t> spirv,
                                             std::span<const uint32_t> constants) const;

    // The parts specialise() is made of, for the tests. An entry's key: a 128-bit hash of the
    // input module, the constants, the optimiser's version and the pass list's version.
    struct Key {
        uint64_t low = 0;
        uint64_t high = 0;
    };
    static Key keyFor(std::span<const uint32_t> spirv, std::span<const uint32_t> constants);
    std::filesystem::path entryPath(const Key& key) const;
    std::optional<std::vector<uint32_t>> load(const Key& key) const;
    // Best effort: false when the entry could not be written (the cache is then only slower).
    bool store(const Key& key, std::span<const uint32_t> module) const;

    static constexpr uint64_t kDefaultMaxBytes = 256ull << 20;

private:
    void evictOver(uint64_t maxBytes) const;

    std::filesystem::path dir_;
    uint64_t maxBytes_ = kDefaultMaxBytes;
};

}  // namespace previs
