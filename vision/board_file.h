#pragma once

// The tag board file (docs/board-format.md). Its TOML is read here, in config/, with the same
// checked reader as the other config formats (base/toml_reader.h): unknown keys and values out
// of range are errors naming the file, the line and the key. vision/ keeps the board itself
// (TagBoard::create validates the geometry); config depends on vision, never the reverse
// (STYLE.md, layout).

#include <string>

#include "base/result.h"
#include "vision/tag_board.h"

namespace previs {

// Ranges a board file's values must lie in, with why.
// Tag ids: the largest AprilTag family (tagStandard52h13) has 48714 codes.
constexpr int64_t kMaxBoardTagId = 65535;
// Edge of a tag's black square: a printed tag larger than this is not a board a camera tracks.
constexpr double kMaxTagSizeM = 10.0;
// Tag positions: a stage or a set, not a city; larger values are a typo (or millimetres).
constexpr double kMaxBoardPositionM = 1000.0;
// Euler angles: one turn either way.
constexpr double kMaxBoardRotationDeg = 360.0;

Result<TagBoard> loadTagBoard(const std::string& path);

}  // namespace previs
