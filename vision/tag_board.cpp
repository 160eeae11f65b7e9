#include "vision/tag_board.h"

#include <cmath>
#include <set>

#include <toml++/toml.h>

#include "vision/tag_detector.h"

namespace previs {

namespace {

std::optional<std::vector<double>> numberArray(const toml::node* node) {
    const toml::array* array = node ? node->as_array() : nullptr;
    if (!array) return std::nullopt;
    std::vector<double> out;
    for (const toml::node& element : *array) {
        std::optional<double> v = element.value<double>();
        if (!v || !std::isfinite(*v)) return std::nullopt;
        out.push_back(*v);
    }
    return out;
}

bool isRotation(const cv::Matx33d& r) {
    cv::Matx33d shouldBeIdentity = r.t() * r;
    return cv::norm(shouldBeIdentity - cv::Matx33d::eye()) < 1e-4 &&
           std::abs(cv::determinant(r) - 1.0) < 1e-4;
}

}  // namespace

cv::Matx33d rotationFromEulerDeg(double rxDeg, double ryDeg, double rzDeg) {
    const double k = M_PI / 180.0;
    const double cx = std::cos(rxDeg * k), sx = std::sin(rxDeg * k);
    const double cy = std::cos(ryDeg * k), sy = std::sin(ryDeg * k);
    const double cz = std::cos(rzDeg * k), sz = std::sin(rzDeg * k);
    cv::Matx33d rx(1, 0, 0, 0, cx, -sx, 0, sx, cx);
    cv::Matx33d ry(cy, 0, sy, 0, 1, 0, -sy, 0, cy);
    cv::Matx33d rz(cz, -sz, 0, sz, cz, 0, 0, 0, 1);
    return rz * ry * rx;
}

const BoardTag* TagBoard::find(int id) const {
    for (const BoardTag& t : tags_)
        if (t.id == id) return &t;
    return nullptr;
}

std::array<cv::Point3d, 4> TagBoard::worldCorners(const BoardTag& tag) const {
    std::array<cv::Point3d, 4> local = tagCornersInTagFrame(tag.sizeM);
    std::array<cv::Point3d, 4> out;
    for (int i = 0; i < 4; ++i) {
        cv::Vec4d p = tag.worldFromTag * cv::Vec4d(local[i].x, local[i].y, local[i].z, 1.0);
        out[i] = cv::Point3d(p[0], p[1], p[2]);
    }
    return out;
}

Result<TagBoard> TagBoard::create(std::vector<BoardTag> tags, const std::string& source,
                                  std::string family) {
    if (tags.empty()) return makeError("{}: the board has no tags; add [[tag]] tables", source);
    std::set<int> seen;
    for (const BoardTag& t : tags) {
        if (t.id < 0) return makeError("{}: tag id {} is negative", source, t.id);
        if (!seen.insert(t.id).second)
            return makeError(
                "{}: tag id {} appears more than once; every tag on a board needs its own id",
                source, t.id);
        if (!(t.sizeM > 0.0) || !std::isfinite(t.sizeM))
            return makeError("{}: tag {} has size {} m; it must be a positive length in metres",
                             source, t.id, t.sizeM);
        cv::Matx33d r = t.worldFromTag.get_minor<3, 3>(0, 0);
        if (!isRotation(r))
            return makeError("{}: tag {}: the rotation of world_from_tag is not a rotation matrix",
                             source, t.id);
        for (int i = 0; i < 16; ++i)
            if (!std::isfinite(t.worldFromTag.val[i]))
                return makeError("{}: tag {}: non-finite pose", source, t.id);
    }
    TagBoard board;
    board.tags_ = std::move(tags);
    board.family_ = std::move(family);
    return board;
}

Result<TagBoard> TagBoard::load(const std::string& path) {
    // Debian's toml++ is built with exceptions; parse errors are caught here, at the module edge.
    toml::table root;
    try {
        root = toml::parse_file(path);
    } catch (const toml::parse_error& e) {
        const auto& where = e.source().begin;
        return makeError("{}:{}:{}: {} (see docs/board-format.md)", path, where.line,
                         where.column, e.description());
    } catch (const std::exception& e) {
        return makeError("cannot read tag board '{}': {}", path, e.what());
    }

    std::string family = root["family"].value_or(std::string());
    std::optional<double> defaultSize = root["tag_size_m"].value<double>();
    if (root.contains("tag_size_m") && !defaultSize)
        return makeError("{}: tag_size_m must be a number (metres)", path);
    const toml::array* tagArray = root["tag"].as_array();
    if (!tagArray)
        return makeError("{}: no [[tag]] tables; see docs/board-format.md for the format", path);

    std::vector<BoardTag> tags;
    int index = 0;
    for (const toml::node& node : *tagArray) {
        ++index;
        const toml::table* t = node.as_table();
        if (!t) return makeError("{}: tag entry {} is not a table", path, index);
        BoardTag tag;
        std::optional<int64_t> id = (*t)["id"].value<int64_t>();
        if (!id) return makeError("{}: [[tag]] number {} has no integer id", path, index);
        tag.id = int(*id);
        std::optional<double> size = (*t)["size_m"].value<double>();
        if (!size) size = defaultSize;
        if (!size)
            return makeError("{}: tag {} has no size_m and the file has no tag_size_m", path,
                             tag.id);
        tag.sizeM = *size;

        const bool hasMatrix = t->contains("world_from_tag");
        const bool hasEuler = t->contains("position_m") || t->contains("rotation_deg");
        if (hasMatrix && hasEuler)
            return makeError("{}: tag {}: give either world_from_tag or position_m/rotation_deg, "
                             "not both",
                             path, tag.id);
        if (hasMatrix) {
            auto m = numberArray(t->get("world_from_tag"));
            if (!m || m->size() != 16)
                return makeError("{}: tag {}: world_from_tag must be 16 numbers (4x4 row-major)",
                                 path, tag.id);
            for (int i = 0; i < 16; ++i) tag.worldFromTag.val[i] = (*m)[i];
            if (cv::norm(tag.worldFromTag.row(3) - cv::Matx14d(0, 0, 0, 1)) > 1e-9)
                return makeError("{}: tag {}: world_from_tag's last row must be 0 0 0 1", path,
                                 tag.id);
        } else {
            auto p = numberArray(t->get("position_m"));
            if (!p || p->size() != 3)
                return makeError("{}: tag {}: position_m must be 3 numbers [x, y, z] in metres",
                                 path, tag.id);
            std::vector<double> r{0.0, 0.0, 0.0};
            if (t->contains("rotation_deg")) {
                auto rr = numberArray(t->get("rotation_deg"));
                if (!rr || rr->size() != 3)
                    return makeError(
                        "{}: tag {}: rotation_deg must be 3 numbers [rx, ry, rz] in degrees", path,
                        tag.id);
                r = *rr;
            }
            cv::Matx33d rot = rotationFromEulerDeg(r[0], r[1], r[2]);
            for (int i = 0; i < 3; ++i) {
                for (int j = 0; j < 3; ++j) tag.worldFromTag(i, j) = rot(i, j);
                tag.worldFromTag(i, 3) = (*p)[i];
            }
        }
        tags.push_back(tag);
    }
    return create(std::move(tags), path, std::move(family));
}

}  // namespace previs
