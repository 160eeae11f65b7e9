#pragma once

// The few string helpers every folder needs, once.

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <initializer_list>
#include <string>
#include <string_view>

namespace previs {

inline std::string lowercase(std::string s) {
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

// Lower-case extension with its dot ("" when none): ".exr" for "Plate.EXR".
inline std::string lowerExtension(const std::string& path) {
    return lowercase(std::filesystem::path(path).extension().string());
}

inline bool endsWith(std::string_view s, std::string_view suffix) {
    return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

// "a, b, c" (for messages listing choices).
template <typename Range>
std::string joined(const Range& items, std::string_view separator = ", ") {
    std::string out;
    bool first = true;
    for (const auto& item : items) {
        if (!first) out += separator;
        out += item;
        first = false;
    }
    return out;
}
inline std::string joined(std::initializer_list<std::string_view> items,
                          std::string_view separator = ", ") {
    return joined<std::initializer_list<std::string_view>>(items, separator);
}

}  // namespace previs
