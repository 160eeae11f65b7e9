#pragma once

// Tag corners re-fitted in linear light (issue 38: the demo take's 2.2 mm bias). A camera's
// transfer curve (sRGB, a highlight roll-off) is concave, so on a blurred edge its code values
// cross the midpoint between ink and paper on the dark side of the true edge: libapriltag, which
// fits edges on the codes, shrinks every black square by a fraction of a pixel (0.3 px per edge
// on the demo take), and the board pose moves by millimetres. In radiance a blurred edge is the
// step convolved with a symmetric kernel, so its centre is where half the step's area lies on
// each side whatever the blur. This module finds that centre on profiles across each edge of a
// detected tag, fits a line to them and intersects the lines.
//
// Only through the camera's own curve: the refit moves an edge by as much as the curve it
// inverts differs from the frame's. ViSP's rendered benchmark is linear in its codes (its
// checkerboard, finer than a pixel near the horizon, averages to half of white); read through
// sRGB, every tag36h11 corner there moves 0.6-0.7 px outward and the tag poses go from 2-21 mm
// to 33-71 mm off; through its true curve (gamma 1) the corners move by -0.14..+0.13 px, 0.02 px
// outward on average, not significantly. The same renders recorded through sRGB put
// libapriltag's edges 0.5-1.3 px off on every family; the refit through sRGB brings them back
// to within 0.6 px of the truth and every tag within ViSP's thresholds
// (tests/vision/tag_edges_test.cpp, bench/visp_tag_poses.h). So a caller without the camera's
// radiometric model keeps libapriltag's corners (TrackerSettings::linearFromCode unset, `previs
// track` without --tone-curve).

#include <array>
#include <opencv2/core.hpp>
#include <vector>

#include "vision/inverse_tone_map.h"
#include "vision/tag_detector.h"

namespace previs {

class CameraCalibration;

// Code value (0..255) → relative linear radiance; any positive scale (edges use ratios).
using LinearFromCode = std::array<float, 256>;

// A grey code through the camera's configured radiometry (vision/inverse_tone_map.h; its
// defaults are the sRGB decoding curve of a webcam, a phone or a JPEG).
LinearFromCode linearFromCodeTable(const InverseToneMapSettings& radiometry);
// Gamma 1 (machine-vision cameras).
LinearFromCode identityLinearFromCode();

struct EdgeRefineStats {
    int refined = 0;  // tags whose corners were re-fitted
    int kept = 0;     // tags left as detected (too small, low contrast, a fit that disagreed)
};

// Re-fits the corners of each detection on the 8-bit grey frame they came from, read in linear
// light through `table`. `border` is the family's quad edge (TagDetector::border): `bits` across
// it, and on each side of it one bit of a single tone (the black border and the white margin of
// tag36h11; the white ring inside the black one of a reversed border), so a profile of ±0.8 bit
// across an edge sees only ink, the edge and paper. A tag whose bits are under 2.5 px, whose
// edges lack contrast (or have ink and paper the wrong way round), or whose re-fitted corner
// lands more than 1.5 px from libapriltag's keeps libapriltag's corners. With a distorting `lens`
// the edges' lines are fitted where they are straight: in its ideal pinhole pixels.
EdgeRefineStats refineTagCornersInLinearLight(std::vector<TagDetection>& detections,
                                              const cv::Mat& gray8, const LinearFromCode& table,
                                              const TagBorder& border,
                                              const CameraCalibration* lens = nullptr);

}  // namespace previs
