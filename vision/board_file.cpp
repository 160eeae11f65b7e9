#include "vision/board_file.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include "base/toml_reader.h"
#include "vision/tag_detector.h"

namespace previs {

namespace {

constexpr const char* kWhat = "tag board";

// A number in (0, hi] or [lo, hi], absent: nullopt.
Result<std::optional<double>> numberIn(const TomlReader& r, const toml::table& t,
                                       std::string_view section, std::string_view key, double lo,
                                       double hi, bool openLow) {
    Result<std::optional<double>> v = r.number(t, section, key);
    if (!v || !*v) return v;
    const double x = **v;
    if (x < lo || x > hi || (openLow && x == lo))
        return r.fail(t.get(key), "'{}' is {}; it must be in {}{}, {}]",
                      TomlReader::dotted(section, key), x, openLow ? "(" : "[", lo, hi);
    return v;
}

// `count` numbers each within [-limit, limit].
Result<std::optional<std::vector<double>>> numbersWithin(const TomlReader& r, const toml::table& t,
                                                         std::string_view section,
                                                         std::string_view key, size_t count,
                                                         double limit) {
    Result<std::optional<std::vector<double>>> v = r.numbers(t, section, key, count);
    if (!v || !*v) return v;
    for (size_t i = 0; i < count; ++i)
        if (std::abs((**v)[i]) > limit)
            return r.fail(t.get(key), "'{}[{}]' is {}; it must be in [{}, {}]",
                          TomlReader::dotted(section, key), i, (**v)[i], -limit, limit);
    return v;
}

Result<BoardTag> readTag(const TomlReader& r, const toml::table& t, size_t index,
                         std::optional<double> defaultSize) {
    const std::string section = fmt::format("tag[{}]", index);
    if (Status s = r.checkKeys(t, section,
                               {"id", "size_m", "position_m", "rotation_deg", "world_from_tag"});
        !s)
        return s.error();
    BoardTag tag;
    Result<std::optional<int64_t>> id = r.integer(t, section, "id");
    if (!id) return id.error();
    if (!*id) return r.fail(&t, "[[tag]] number {} has no 'id' (an integer)", index + 1);
    if (**id < 0 || **id > kMaxBoardTagId)
        return r.fail(t.get("id"), "'{}.id' is {}; it must be an integer in [0, {}]", section, **id,
                      kMaxBoardTagId);
    tag.id = int(**id);

    Result<std::optional<double>> size = numberIn(r, t, section, "size_m", 0.0, kMaxTagSizeM, true);
    if (!size) return size.error();
    if (!*size) *size = defaultSize;
    if (!*size)
        return r.fail(&t, "tag {} has no 'size_m' and the file has no 'tag_size_m'", tag.id);
    tag.sizeM = **size;

    const bool hasMatrix = t.contains("world_from_tag");
    if (hasMatrix && (t.contains("position_m") || t.contains("rotation_deg")))
        return r.fail(&t,
                      "tag {}: give either 'world_from_tag' or 'position_m'/'rotation_deg', "
                      "not both",
                      tag.id);
    if (hasMatrix) {
        Result<std::optional<std::vector<double>>> m =
            numbersWithin(r, t, section, "world_from_tag", 16, kMaxBoardPositionM);
        if (!m) return m.error();
        for (int i = 0; i < 16; ++i) tag.worldFromTag.val[i] = (**m)[size_t(i)];
        if (cv::norm(tag.worldFromTag.row(3) - cv::Matx14d(0, 0, 0, 1)) > 1e-9)
            return r.fail(t.get("world_from_tag"),
                          "tag {}: 'world_from_tag''s last row must be 0 0 0 1", tag.id);
        return tag;
    }
    Result<std::optional<std::vector<double>>> p =
        numbersWithin(r, t, section, "position_m", 3, kMaxBoardPositionM);
    if (!p) return p.error();
    if (!*p)
        return r.fail(&t, "tag {} needs 'position_m' = [x, y, z] (metres) or 'world_from_tag'",
                      tag.id);
    Result<std::optional<std::vector<double>>> rot =
        numbersWithin(r, t, section, "rotation_deg", 3, kMaxBoardRotationDeg);
    if (!rot) return rot.error();
    const std::vector<double> angles = rot->value_or(std::vector<double>{0.0, 0.0, 0.0});
    const cv::Matx33d rotation = rotationFromEulerDeg(angles[0], angles[1], angles[2]);
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) tag.worldFromTag(i, j) = rotation(i, j);
        tag.worldFromTag(i, 3) = (**p)[size_t(i)];
    }
    return tag;
}

}  // namespace

Result<TagBoard> loadTagBoard(const std::string& path) {
    Result<toml::table> parsed = parseTomlFile(path, kWhat);
    if (!parsed) return parsed.error();
    const toml::table& root = *parsed;
    const TomlReader r(path, kWhat);
    if (Status s = r.checkKeys(root, "", {"family", "tag_size_m", "tag"}); !s) return s.error();

    Result<std::optional<std::string>> family = r.string(root, "", "family");
    if (!family) return family.error();
    if (*family) {
        const std::vector<std::string>& known = supportedTagFamilies();
        if (std::find(known.begin(), known.end(), **family) == known.end()) {
            return r.fail(root.get("family"), "'family' is '{}'; supported: {}", **family,
                          joined(known));
        }
    }
    Result<std::optional<double>> defaultSize =
        numberIn(r, root, "", "tag_size_m", 0.0, kMaxTagSizeM, true);
    if (!defaultSize) return defaultSize.error();

    const toml::node* tagNode = root.get("tag");
    const toml::array* tagArray = tagNode ? tagNode->as_array() : nullptr;
    if (!tagArray || tagArray->empty())
        return r.fail(tagNode, "no [[tag]] tables; see docs/board-format.md for the format");
    std::vector<BoardTag> tags;
    for (size_t i = 0; i < tagArray->size(); ++i) {
        const toml::table* t = tagArray->get(i)->as_table();
        if (!t) return r.fail(tagArray->get(i), "'tag' must be [[tag]] tables");
        Result<BoardTag> tag = readTag(r, *t, i, *defaultSize);
        if (!tag) return tag.error();
        tags.push_back(*tag);
    }
    return TagBoard::create(std::move(tags), fmt::format("cannot load tag board '{}'", path),
                            family->value_or(std::string()));
}

}  // namespace previs
