#pragma once

// It exposes toml++ (previs_base links it for the formats that read TOML).
// Typed, checked access to a parsed TOML file for the project's config formats (the scene
// description, the service config). Every failure is one message naming the file, the line and
// the dotted key, and what to change (DESIGN.md §7: a bad config never crashes anything).

#include <fmt/format.h>
#include <toml++/toml.h>

#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "base/result.h"
#include "base/strings.h"

namespace previs {

// `what` names the format in messages: "cannot load <what> '<path>': ...".
class TomlReader {
public:
    TomlReader(std::string path, std::string what);

    // Errors with the file, and the node's line when it has one.
    template <typename... Args>
    Error fail(const toml::node* at, fmt::format_string<Args...> format, Args&&... args) const {
        return failMessage(at, fmt::format(format, std::forward<Args>(args)...));
    }
    Error failMessage(const toml::node* at, const std::string& what) const;

    // An unknown key is most often a typo; ignoring it would silently do something else than
    // the user asked for, so it is an error listing the valid keys.
    Status checkKeys(const toml::table& table, std::string_view section,
                     std::initializer_list<std::string_view> valid) const;

    // Each returns nullopt (or null) when the key is absent and an error when it has the wrong
    // type. `section` is the dotted path of `table` ("" at the top), for messages.
    Result<const toml::table*> table(const toml::table& parent, std::string_view section,
                                     std::string_view key) const;
    Result<std::optional<std::string>> string(const toml::table& table, std::string_view section,
                                              std::string_view key) const;
    // Integers are accepted where a number is asked for (`scale = 1` as `scale = 1.0`); the
    // value must be finite.
    Result<std::optional<double>> number(const toml::table& table, std::string_view section,
                                         std::string_view key) const;
    Result<std::optional<int64_t>> integer(const toml::table& table, std::string_view section,
                                           std::string_view key) const;
    Result<std::optional<bool>> boolean(const toml::table& table, std::string_view section,
                                        std::string_view key) const;
    // A boolean, left as `value` when absent.
    Status booleanIn(const toml::table& table, std::string_view section, std::string_view key,
                     bool& value) const {
        Result<std::optional<bool>> v = boolean(table, section, key);
        if (!v) return v.error();
        value = v->value_or(value);
        return {};
    }
    // An array of exactly `count` finite numbers (any number of them when `count` is 0).
    Result<std::optional<std::vector<double>>> numbers(const toml::table& table,
                                                       std::string_view section,
                                                       std::string_view key, size_t count) const;
    // An array of strings (any number of them).
    Result<std::optional<std::vector<std::string>>> strings(const toml::table& table,
                                                            std::string_view section,
                                                            std::string_view key) const;
    // A number within [lo, hi] (inclusive ends unless `openLow`), left as `value` when absent.
    template <typename T>
    Status numberIn(const toml::table& table, std::string_view section, std::string_view key,
                    T& value, double lo, double hi, bool openLow = false) const {
        Result<std::optional<double>> v = number(table, section, key);
        if (!v) return v.error();
        if (!*v) return {};
        const double x = **v;
        if (x < lo || x > hi || (openLow && x == lo))
            return fail(table.get(key), "'{}' is {}; it must be in {}{}, {}]", dotted(section, key),
                        x, openLow ? "(" : "[", lo, hi);
        value = T(x);
        return {};
    }
    // An integer within [lo, hi] into `value`, narrowed to its type (which must hold [lo, hi]);
    // left as it is when absent.
    template <typename T>
    Status integerIn(const toml::table& table, std::string_view section, std::string_view key,
                     T& value, int64_t lo, int64_t hi) const {
        static_assert(std::is_integral_v<T> && !std::is_same_v<T, bool>);
        Result<std::optional<int64_t>> v = integerWithin(table, section, key, lo, hi);
        if (!v) return v.error();
        if (*v) value = T(**v);
        return {};
    }
    // An existing regular file with one of `extensions` (lower case, with the dot); relative
    // paths start at the file's folder. Returns the resolved path.
    Result<std::string> file(const toml::node& node, std::string_view key, const std::string& value,
                             std::initializer_list<std::string_view> extensions,
                             const char* what) const;

    const std::string& path() const { return path_; }
    // Resolve relative paths against another folder (a config copied into a session).
    void setFolder(std::filesystem::path folder) { folder_ = std::move(folder); }
    const std::filesystem::path& folder() const { return folder_; }

    static std::string dotted(std::string_view section, std::string_view key) {
        return section.empty() ? std::string(key) : fmt::format("{}.{}", section, key);
    }

private:
    Result<std::optional<int64_t>> integerWithin(const toml::table& table, std::string_view section,
                                                 std::string_view key, int64_t lo,
                                                 int64_t hi) const;

    std::string path_;
    std::string what_;
    std::filesystem::path folder_;  // relative paths inside the file are relative to this
};

// Reads and parses `path`. A missing file, a directory and TOML syntax errors (toml++ throws
// them: Debian builds it with exceptions, see config/CMakeLists.txt) end here as an Error
// naming the file, the line and the column.
Result<toml::table> parseTomlFile(const std::string& path, const std::string& what);

// "a string", "an integer", ... for messages.
const char* tomlTypeName(const toml::node& node);

}  // namespace previs
