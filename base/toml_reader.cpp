#include "base/toml_reader.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <exception>

namespace previs {
namespace {

namespace fs = std::filesystem;

}  // namespace

const char* tomlTypeName(const toml::node& node) {
    switch (node.type()) {
        case toml::node_type::table:
            return "a table";
        case toml::node_type::array:
            return "an array";
        case toml::node_type::string:
            return "a string";
        case toml::node_type::integer:
            return "an integer";
        case toml::node_type::floating_point:
            return "a floating-point number";
        case toml::node_type::boolean:
            return "a boolean";
        case toml::node_type::date:
            return "a date";
        case toml::node_type::time:
            return "a time";
        case toml::node_type::date_time:
            return "a date-time";
        case toml::node_type::none:
            break;
    }
    return "nothing";
}

namespace {

// TOML tells integers from floats; both are numbers here.
std::optional<double> asNumber(const toml::node& node) {
    if (const toml::value<int64_t>* i = node.as_integer()) return double(i->get());
    if (const toml::value<double>* f = node.as_floating_point()) return f->get();
    return std::nullopt;
}

}  // namespace

TomlReader::TomlReader(std::string path, std::string what)
    : path_(std::move(path)), what_(std::move(what)), folder_(fs::path(path_).parent_path()) {}

Error TomlReader::failMessage(const toml::node* at, const std::string& what) const {
    if (at && at->source().begin.line > 0)
        return makeError("cannot load {} '{}': line {}: {}", what_, path_, at->source().begin.line,
                         what);
    return makeError("cannot load {} '{}': {}", what_, path_, what);
}

Result<std::optional<int64_t>> TomlReader::integerWithin(const toml::table& table,
                                                         std::string_view section,
                                                         std::string_view key, int64_t lo,
                                                         int64_t hi) const {
    Result<std::optional<int64_t>> v = integer(table, section, key);
    if (!v || !*v) return v;
    if (**v < lo || **v > hi)
        return fail(table.get(key), "'{}' is {}; it must be an integer in [{}, {}]",
                    dotted(section, key), **v, lo, hi);
    return v;
}

Status TomlReader::checkKeys(const toml::table& table, std::string_view section,
                             std::initializer_list<std::string_view> valid) const {
    for (auto&& [key, node] : table) {
        if (std::find(valid.begin(), valid.end(), key.str()) != valid.end()) continue;
        if (section.empty())
            return fail(&node, "unknown key '{}' (valid top-level keys: {})", key.str(),
                        joined(valid));
        return fail(&node, "unknown key '{}' in [{}] (valid keys there: {})", key.str(), section,
                    joined(valid));
    }
    return {};
}

Result<const toml::table*> TomlReader::table(const toml::table& parent, std::string_view section,
                                             std::string_view key) const {
    const toml::node* node = parent.get(key);
    if (!node) return static_cast<const toml::table*>(nullptr);
    const toml::table* t = node->as_table();
    if (!t)
        return fail(node, "'{}' must be a table, written as a [{}] section, not {}",
                    dotted(section, key), dotted(section, key), tomlTypeName(*node));
    return t;
}

Result<std::optional<std::string>> TomlReader::string(const toml::table& table,
                                                      std::string_view section,
                                                      std::string_view key) const {
    const toml::node* node = table.get(key);
    if (!node) return std::optional<std::string>();
    const toml::value<std::string>* s = node->as_string();
    if (!s)
        return fail(node, "'{}' must be a string, not {}", dotted(section, key),
                    tomlTypeName(*node));
    return std::optional<std::string>(s->get());
}

Result<std::optional<double>> TomlReader::number(const toml::table& table, std::string_view section,
                                                 std::string_view key) const {
    const toml::node* node = table.get(key);
    if (!node) return std::optional<double>();
    const std::optional<double> v = asNumber(*node);
    if (!v)
        return fail(node, "'{}' must be a number, not {}", dotted(section, key),
                    tomlTypeName(*node));
    if (!std::isfinite(*v))
        return fail(node, "'{}' is {}; it must be a finite number", dotted(section, key), *v);
    return v;
}

Result<std::optional<int64_t>> TomlReader::integer(const toml::table& table,
                                                   std::string_view section,
                                                   std::string_view key) const {
    const toml::node* node = table.get(key);
    if (!node) return std::optional<int64_t>();
    const toml::value<int64_t>* i = node->as_integer();
    if (!i)
        return fail(node, "'{}' must be an integer, not {}", dotted(section, key),
                    tomlTypeName(*node));
    return std::optional<int64_t>(i->get());
}

Result<std::optional<bool>> TomlReader::boolean(const toml::table& table, std::string_view section,
                                                std::string_view key) const {
    const toml::node* node = table.get(key);
    if (!node) return std::optional<bool>();
    const toml::value<bool>* b = node->as_boolean();
    if (!b)
        return fail(node, "'{}' must be true or false, not {}", dotted(section, key),
                    tomlTypeName(*node));
    return std::optional<bool>(b->get());
}

Result<std::optional<std::vector<double>>> TomlReader::numbers(const toml::table& table,
                                                               std::string_view section,
                                                               std::string_view key,
                                                               size_t count) const {
    const toml::node* node = table.get(key);
    if (!node) return std::optional<std::vector<double>>();
    const toml::array* array = node->as_array();
    if (!array || (count > 0 && array->size() != count))
        return fail(node, "'{}' must be an array of {} numbers, not {}", dotted(section, key),
                    count > 0 ? fmt::format("{}", count) : std::string("some"),
                    array ? fmt::format("{} elements", array->size()) : tomlTypeName(*node));
    std::vector<double> values;
    for (size_t i = 0; i < array->size(); ++i) {
        const toml::node& element = *array->get(i);
        const std::optional<double> v = asNumber(element);
        if (!v || !std::isfinite(*v))
            return fail(&element, "'{}[{}]' must be a finite number, not {}", dotted(section, key),
                        i, v ? fmt::format("{}", *v) : tomlTypeName(element));
        values.push_back(*v);
    }
    return std::optional<std::vector<double>>(std::move(values));
}

Result<std::optional<std::vector<std::string>>> TomlReader::strings(const toml::table& table,
                                                                    std::string_view section,
                                                                    std::string_view key) const {
    const toml::node* node = table.get(key);
    if (!node) return std::optional<std::vector<std::string>>();
    const toml::array* array = node->as_array();
    if (!array)
        return fail(node, "'{}' must be an array of strings, not {}", dotted(section, key),
                    tomlTypeName(*node));
    std::vector<std::string> values;
    for (size_t i = 0; i < array->size(); ++i) {
        const toml::node& element = *array->get(i);
        const auto* v = element.as_string();
        if (!v)
            return fail(&element, "'{}[{}]' must be a string, not {}", dotted(section, key), i,
                        tomlTypeName(element));
        values.push_back(v->get());
    }
    return std::optional<std::vector<std::string>>(std::move(values));
}

Result<std::string> TomlReader::file(const toml::node& node, std::string_view key,
                                     const std::string& value,
                                     std::initializer_list<std::string_view> extensions,
                                     const char* what) const {
    if (value.empty()) return fail(&node, "'{}' is empty; give the {} file's path", key, what);
    const std::string ext = lowerExtension(value);
    if (std::find(extensions.begin(), extensions.end(), ext) == extensions.end())
        return fail(&node, "'{}' is '{}', not a {} file (accepted: {})", key, value, what,
                    joined(extensions));
    // fs::path's operator/ keeps an absolute right-hand side as it is.
    const fs::path resolved = folder_ / fs::path(value);
    std::error_code ec;
    if (!fs::is_regular_file(resolved, ec))
        return fail(&node, "'{}' is '{}', but '{}' {}{}", key, value, resolved.string(),
                    fs::exists(resolved, ec) ? "is not a file" : "does not exist",
                    fs::path(value).is_relative()
                        ? fmt::format(" (relative paths start at the {}'s folder)", what_)
                        : "");
    return resolved.string();
}

Result<toml::table> parseTomlFile(const std::string& path, const std::string& what) {
    std::error_code ec;
    if (!fs::exists(path, ec))
        return makeError("cannot load {} '{}': no such file (check the path)", what, path);
    if (!fs::is_regular_file(path, ec))
        return makeError("cannot load {} '{}': it is not a regular file", what, path);
    try {
        return toml::parse_file(path);
    } catch (const toml::parse_error& e) {
        return makeError("cannot load {} '{}': line {}, column {}: not valid TOML: {}", what, path,
                         e.source().begin.line, e.source().begin.column, e.description());
    } catch (const std::exception& e) {
        return makeError("cannot load {} '{}': {}", what, path, e.what());
    }
}

}  // namespace previs
