#pragma once

// A board of AprilTags with known poses in the world frame. Its file (docs/board-format.md) is
// read by vision/board_file.h.

#include <array>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "base/result.h"

namespace previs {

struct BoardTag {
    int id = -1;
    double sizeM = 0.0;                             // edge of the black square, metres
    cv::Matx44d worldFromTag = cv::Matx44d::eye();  // tag frame as estimateTagPose's
};

class TagBoard {
public:
    // Validates tags built in memory; `source` names them in errors (duplicate ids, bad sizes).
    static Result<TagBoard> create(std::vector<BoardTag> tags, const std::string& source,
                                   std::string family = {});

    const std::vector<BoardTag>& tags() const { return tags_; }
    const BoardTag* find(int id) const;
    // The family the file names, empty when it names none.
    const std::string& family() const { return family_; }
    // The tag's four corners in the world frame, in libapriltag's corner order.
    std::array<cv::Point3d, 4> worldCorners(const BoardTag& tag) const;

private:
    TagBoard() = default;
    std::vector<BoardTag> tags_;
    std::string family_;
};

// worldFromTag rotation from the board file's rotation_deg = [rx, ry, rz]: Rz·Ry·Rx, the same
// composition DESIGN.md §3 uses for --mount-rotation.
cv::Matx33d rotationFromEulerDeg(double rxDeg, double ryDeg, double rzDeg);

}  // namespace previs
