#include "gpu/spirv_cache.h"

#include <spirv-tools/libspirv.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <string_view>
#include <system_error>

#include "base/atomic_file.h"
#include "base/log.h"
#include "gpu/spirv_specialise.h"

namespace previs {

namespace {

namespace fs = std::filesystem;

// An entry file: this header, then the module's words.
constexpr uint32_t kEntryMagic = 0x43535650u;  // "PVSC" little-endian
// Bumped when the entry layout changes; the pass list has its own version (spirv_specialise.h).
constexpr uint32_t kEntryFormat = 1u;
constexpr uint32_t kSpirvMagic = 0x07230203u;

struct EntryHeader {
    uint32_t magic;
    uint32_t format;
    uint64_t keyLow;
    uint64_t keyHigh;
    uint64_t words;
    uint64_t checksum;  // XXH3-64 of the module's bytes
};
static_assert(sizeof(EntryHeader) == 40);

bool truthy(const char* v) {
    if (!v) return false;
    const std::string_view s(v);
    return s == "1" || s == "true" || s == "yes" || s == "on";
}

// Hex of the key, the entry's file name.
std::string keyName(const SpirvCache::Key& key) {
    return fmt::format("{:016x}{:016x}.spv", key.high, key.low);
}

}  // namespace

SpirvCache SpirvCache::fromEnvironment() {
    if (truthy(std::getenv("PREVIS_SHADER_CACHE_DISABLE"))) return SpirvCache();
    if (const char* dir = std::getenv("PREVIS_SHADER_CACHE_DIR"); dir && *dir)
        return SpirvCache(dir);
    if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg)
        return SpirvCache(fs::path(xdg) / "previs" / "spirv");
    if (const char* home = std::getenv("HOME"); home && *home)
        return SpirvCache(fs::path(home) / ".cache" / "previs" / "spirv");
    return SpirvCache();
}

SpirvCache::SpirvCache(fs::path dir, uint64_t maxBytes)
    : dir_(std::move(dir)), maxBytes_(maxBytes) {}

SpirvCache::Key SpirvCache::keyFor(std::span<const uint32_t> spirv,
                                   std::span<const uint32_t> constants) {
    XXH3_state_t* state = XXH3_createState();
    PV_ASSERT(state);
    XXH3_128bits_reset(state);
    const uint32_t versions[] = {kEntryFormat, kSpecialisePassesVersion, uint32_t(spirv.size()),
                                 uint32_t(constants.size())};
    XXH3_128bits_update(state, versions, sizeof(versions));
    const char* tools = spvSoftwareVersionString();
    XXH3_128bits_update(state, tools, std::strlen(tools));
    XXH3_128bits_update(state, spirv.data(), spirv.size_bytes());
    XXH3_128bits_update(state, constants.data(), constants.size_bytes());
    const XXH128_hash_t h = XXH3_128bits_digest(state);
    XXH3_freeState(state);
    return {h.low64, h.high64};
}

fs::path SpirvCache::entryPath(const Key& key) const { return dir_ / keyName(key); }

std::optional<std::vector<uint32_t>> SpirvCache::load(const Key& key) const {
    if (!enabled()) return std::nullopt;
    const fs::path path = entryPath(key);
    std::ifstream in(path, std::ios::binary);
    if (!in) return std::nullopt;
    EntryHeader h{};
    if (!in.read(reinterpret_cast<char*>(&h), sizeof(h))) return std::nullopt;
    // A module is at least its 5-word SPIR-V header; 64 Mi words bounds a damaged count.
    if (h.magic != kEntryMagic || h.format != kEntryFormat || h.keyLow != key.low ||
        h.keyHigh != key.high || h.words < 5 || h.words > (64ull << 20))
        return std::nullopt;
    std::vector<uint32_t> module(h.words);
    if (!in.read(reinterpret_cast<char*>(module.data()), std::streamsize(h.words * 4)))
        return std::nullopt;
    // Trailing bytes: not an entry this code wrote.
    if (in.peek() != std::ifstream::traits_type::eof()) return std::nullopt;
    if (XXH3_64bits(module.data(), module.size() * 4) != h.checksum || module[0] != kSpirvMagic)
        return std::nullopt;
    // Used now: eviction removes the entries used longest ago first.
    std::error_code ec;
    fs::last_write_time(path, fs::file_time_type::clock::now(), ec);
    return module;
}

bool SpirvCache::store(const Key& key, std::span<const uint32_t> module) const {
    if (!enabled()) return false;
    std::error_code ec;
    fs::create_directories(dir_, ec);
    if (ec) {
        logDebug("shader cache {}: {}; specialising without it", dir_.string(), ec.message());
        return false;
    }
    // A temporary no other writer uses; rename() then replaces any entry atomically, so a reader
    // (another process of the same build) sees the old file or the new one, never a part.
    EntryHeader h{kEntryMagic, kEntryFormat,  key.low,
                  key.high,    module.size(), XXH3_64bits(module.data(), module.size_bytes())};
    Result<AtomicFile> file =
        AtomicFile::create(entryPath(key).string(), {.durable = false, .hidden = true});
    Status written = file ? file->write({reinterpret_cast<const uint8_t*>(&h), sizeof(h)})
                          : Status(file.error());
    if (written)
        written =
            file->write({reinterpret_cast<const uint8_t*>(module.data()), module.size_bytes()});
    if (written) written = file->commit();
    if (!written) {
        logDebug("shader cache {}: {}; specialising without it", dir_.string(), written.message());
        return false;
    }
    evictOver(maxBytes_);
    return true;
}

void SpirvCache::evictOver(uint64_t maxBytes) const {
    struct Entry {
        fs::path path;
        uint64_t bytes;
        fs::file_time_type used;
    };
    std::vector<Entry> entries;
    uint64_t total = 0;
    std::error_code ec;
    const fs::file_time_type now = fs::file_time_type::clock::now();
    for (const fs::directory_entry& e : fs::directory_iterator(dir_, ec)) {
        std::error_code entryError;
        if (!e.is_regular_file(entryError)) continue;
        // A writer that died between writing and renaming leaves its temporary file.
        if (e.path().extension() == ".tmp") {
            if (now - e.last_write_time(entryError) > std::chrono::hours(1) && !entryError)
                fs::remove(e.path(), entryError);
            continue;
        }
        if (e.path().extension() != ".spv") continue;
        const uint64_t bytes = e.file_size(entryError);
        const fs::file_time_type used = e.last_write_time(entryError);
        if (entryError) continue;
        entries.push_back({e.path(), bytes, used});
        total += bytes;
    }
    if (total <= maxBytes) return;
    std::sort(entries.begin(), entries.end(),
              [](const Entry& a, const Entry& b) { return a.used < b.used; });
    for (const Entry& e : entries) {
        if (total <= maxBytes) break;
        if (fs::remove(e.path, ec)) total -= e.bytes;
    }
}

Result<std::vector<uint32_t>> SpirvCache::specialise(std::span<const uint32_t> spirv,
                                                     std::span<const uint32_t> constants) const {
    const Key key = keyFor(spirv, constants);
    if (auto cached = load(key)) return std::move(*cached);
    auto module = specialiseSpirv(spirv, constants);
    if (module) store(key, *module);
    return module;
}

}  // namespace previs
