#include "vision/tag_board.h"

#include <cmath>
#include <set>

#include "vision/tag_detector.h"

namespace previs {

namespace {

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

}  // namespace previs
