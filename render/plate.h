#pragma once

// The plate (the camera image L_oc of Eq. 1) must be finite, non-negative radiance: a NaN or
// Inf would pass through the composite unchanged (and poison tone mapping and any average taken
// over the image), a negative value is no radiance at all. docs/plates.md gives the rule.

#include <cstddef>

#include "image/image.h"

namespace previs {

struct PlateRepair {
    size_t nonFinite = 0;  // channel values that were NaN or ±Inf
    size_t negative = 0;   // finite channel values below 0
    size_t total() const { return nonFinite + negative; }
};

// Replaces, per channel value: NaN and ±Inf by the mean of the same channel's finite,
// non-negative values among the 8 neighbours (in the image as given), or 0 when there is none;
// finite negative values by 0. Every other value is left bit for bit.
PlateRepair repairPlate(ImageF& plate);

}  // namespace previs
