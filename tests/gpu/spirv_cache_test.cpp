#include "gpu/spirv_cache.h"

#include <gtest/gtest.h>

#include <array>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>
#include <vector>

#include "gpu/spirv_specialise.h"
#include "specialise_probe.spv.h"
#include "tests/support/temp_dir.h"

namespace previs {
namespace {

namespace fs = std::filesystem;

std::span<const uint32_t> probeModule() {
    return {specialise_probe_spv, sizeof(specialise_probe_spv) / 4};
}

constexpr std::array<uint32_t, 3> kAllOn{1, 1, 5};
constexpr std::array<uint32_t, 3> kSquareOff{1, 0, 5};

// A fresh cache folder per test.
fs::path cacheDir(const std::string& name) {
    fs::path dir = testing::scratchDir("spirv_cache") / name;
    fs::remove_all(dir);
    return dir;
}

std::vector<char> readAll(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeAll(const fs::path& p, const std::vector<char>& bytes) {
    std::ofstream out(p, std::ios::binary | std::ios::trunc);
    out.write(bytes.data(), std::streamsize(bytes.size()));
}

TEST(SpirvCacheTest, AHitGivesWhatSpecialisingGives) {
    const SpirvCache cache(cacheDir("hit"));
    auto fresh = specialiseSpirv(probeModule(), kAllOn);
    ASSERT_TRUE(fresh.ok()) << fresh.message();
    auto first = cache.specialise(probeModule(), kAllOn);  // a miss: specialises and stores
    ASSERT_TRUE(first.ok()) << first.message();
    const SpirvCache::Key key = SpirvCache::keyFor(probeModule(), kAllOn);
    ASSERT_TRUE(fs::is_regular_file(cache.entryPath(key)));
    auto loaded = cache.load(key);
    ASSERT_TRUE(loaded.has_value());
    EXPECT_EQ(*loaded, *fresh);
    auto second = cache.specialise(probeModule(), kAllOn);  // a hit
    ASSERT_TRUE(second.ok());
    EXPECT_EQ(*second, *fresh);
}

TEST(SpirvCacheTest, OtherConstantsOrAnotherModuleAreAnotherEntry) {
    const SpirvCache::Key on = SpirvCache::keyFor(probeModule(), kAllOn);
    const SpirvCache::Key off = SpirvCache::keyFor(probeModule(), kSquareOff);
    EXPECT_FALSE(on.low == off.low && on.high == off.high);
    std::vector<uint32_t> changed(probeModule().begin(), probeModule().end());
    changed.back() ^= 1u;
    const SpirvCache::Key other = SpirvCache::keyFor(changed, kAllOn);
    EXPECT_FALSE(on.low == other.low && on.high == other.high);
    // One constant fewer is another key too (the count is hashed, not only the words).
    const SpirvCache::Key shorter = SpirvCache::keyFor(probeModule(), std::span(kAllOn).first(2));
    EXPECT_FALSE(on.low == shorter.low && on.high == shorter.high);

    const SpirvCache cache(cacheDir("distinct"));
    auto a = cache.specialise(probeModule(), kAllOn);
    auto b = cache.specialise(probeModule(), kSquareOff);
    ASSERT_TRUE(a.ok() && b.ok());
    EXPECT_NE(*a, *b);
    EXPECT_EQ(*cache.load(off), *specialiseSpirv(probeModule(), kSquareOff));
}

// Every way an entry can be damaged is a miss, and specialise() then replaces it.
TEST(SpirvCacheTest, ADamagedEntryIsAMissNeverAWrongModule) {
    const SpirvCache cache(cacheDir("damaged"));
    const SpirvCache::Key key = SpirvCache::keyFor(probeModule(), kAllOn);
    ASSERT_TRUE(cache.specialise(probeModule(), kAllOn).ok());
    const fs::path entry = cache.entryPath(key);
    const std::vector<char> good = readAll(entry);
    ASSERT_GT(good.size(), 40u + 20u);

    std::vector<std::vector<char>> damaged;
    damaged.push_back({});                                  // empty
    damaged.emplace_back(good.begin(), good.begin() + 20);  // half a header
    damaged.emplace_back(good.begin(), good.end() - 4);     // truncated module
    damaged.push_back(good);
    damaged.back().push_back('x');  // trailing byte
    damaged.push_back(good);
    damaged.back()[good.size() - 7] ^= 0x10;  // a flipped module bit
    damaged.push_back(good);
    damaged.back()[9] ^= 0x01;  // another key
    damaged.push_back(good);
    damaged.back()[24] ^= char(0x01);  // a wrong word count
    for (size_t i = 0; i < damaged.size(); ++i) {
        writeAll(entry, damaged[i]);
        EXPECT_FALSE(cache.load(key).has_value()) << "damage " << i;
        auto again = cache.specialise(probeModule(), kAllOn);
        ASSERT_TRUE(again.ok());
        EXPECT_EQ(*again, *specialiseSpirv(probeModule(), kAllOn)) << "damage " << i;
        EXPECT_EQ(readAll(entry), good) << "damage " << i << " not replaced";
    }
}

TEST(SpirvCacheTest, AnUnwritableFolderOnlyCostsTheSpecialisation) {
    // A regular file where the folder should be: create_directories fails for root too.
    const fs::path blocker = cacheDir("blocked");
    fs::create_directories(blocker.parent_path());
    writeAll(blocker, {'x'});
    const SpirvCache cache(blocker / "spirv");
    auto module = cache.specialise(probeModule(), kAllOn);
    ASSERT_TRUE(module.ok()) << module.message();
    EXPECT_EQ(*module, *specialiseSpirv(probeModule(), kAllOn));
    EXPECT_FALSE(cache.store(SpirvCache::keyFor(probeModule(), kAllOn), *module));
}

TEST(SpirvCacheTest, TheEntriesUsedLongestAgoGoFirst) {
    const fs::path dir = cacheDir("evict");
    auto on = specialiseSpirv(probeModule(), kAllOn);
    auto off = specialiseSpirv(probeModule(), kSquareOff);
    ASSERT_TRUE(on.ok() && off.ok());
    const SpirvCache::Key onKey = SpirvCache::keyFor(probeModule(), kAllOn);
    const SpirvCache::Key offKey = SpirvCache::keyFor(probeModule(), kSquareOff);
    // Room for one entry and a half.
    const uint64_t entryBytes = 40 + 4 * std::max(on->size(), off->size());
    const SpirvCache cache(dir, entryBytes * 3 / 2);
    ASSERT_TRUE(cache.store(onKey, *on));
    // Older by a minute, so the order does not rest on the file system's time resolution.
    fs::last_write_time(cache.entryPath(onKey),
                        fs::file_time_type::clock::now() - std::chrono::minutes(1));
    ASSERT_TRUE(cache.store(offKey, *off));
    EXPECT_FALSE(fs::exists(cache.entryPath(onKey)));
    EXPECT_TRUE(cache.load(offKey).has_value());
}

TEST(SpirvCacheTest, WritersOfTheSameEntryNeverLeaveAPartOfOne) {
    const SpirvCache cache(cacheDir("race"));
    const SpirvCache::Key key = SpirvCache::keyFor(probeModule(), kAllOn);
    const std::vector<uint32_t> expected = *specialiseSpirv(probeModule(), kAllOn);
    std::vector<std::thread> writers;
    std::atomic<int> wrongReads{0};
    for (int t = 0; t < 4; ++t)
        writers.emplace_back([&] {
            for (int i = 0; i < 20; ++i) {
                cache.store(key, expected);
                auto read = cache.load(key);
                if (read && *read != expected) ++wrongReads;
            }
        });
    for (std::thread& w : writers) w.join();
    EXPECT_EQ(wrongReads.load(), 0);
    EXPECT_EQ(*cache.load(key), expected);
    // No temporary file is left behind.
    for (const fs::directory_entry& e : fs::directory_iterator(cache.dir()))
        EXPECT_EQ(e.path().extension(), ".spv") << e.path();
}

TEST(SpirvCacheTest, TheEnvironmentNamesTheFolderOrTurnsItOff) {
    const char* saved[3] = {std::getenv("PREVIS_SHADER_CACHE_DIR"),
                            std::getenv("PREVIS_SHADER_CACHE_DISABLE"),
                            std::getenv("XDG_CACHE_HOME")};
    const std::string keep[3] = {saved[0] ? saved[0] : "", saved[1] ? saved[1] : "",
                                 saved[2] ? saved[2] : ""};
    ::unsetenv("PREVIS_SHADER_CACHE_DISABLE");
    ::setenv("PREVIS_SHADER_CACHE_DIR", "/somewhere/spirv", 1);
    EXPECT_EQ(SpirvCache::fromEnvironment().dir(), fs::path("/somewhere/spirv"));
    ::unsetenv("PREVIS_SHADER_CACHE_DIR");
    ::setenv("XDG_CACHE_HOME", "/xdg", 1);
    EXPECT_EQ(SpirvCache::fromEnvironment().dir(), fs::path("/xdg/previs/spirv"));
    ::setenv("PREVIS_SHADER_CACHE_DISABLE", "1", 1);
    EXPECT_FALSE(SpirvCache::fromEnvironment().enabled());
    // A disabled cache specialises and stores nothing.
    const SpirvCache off;
    EXPECT_FALSE(off.load(SpirvCache::keyFor(probeModule(), kAllOn)).has_value());
    EXPECT_TRUE(off.specialise(probeModule(), kAllOn).ok());
    const char* names[3] = {"PREVIS_SHADER_CACHE_DIR", "PREVIS_SHADER_CACHE_DISABLE",
                            "XDG_CACHE_HOME"};
    for (int i = 0; i < 3; ++i) {
        if (saved[i])
            ::setenv(names[i], keep[i].c_str(), 1);
        else
            ::unsetenv(names[i]);
    }
}

}  // namespace
}  // namespace previs
