#include "render/plate.h"

#include <cmath>
#include <vector>

namespace previs {

namespace {

bool usable(float v) { return std::isfinite(v) && v >= 0.0f; }

}  // namespace

PlateRepair repairPlate(ImageF& plate) {
    PlateRepair repair;
    const size_t channels = plate.channels;
    // A first pass finds the bad values; a clean plate (the usual case) is not copied.
    std::vector<size_t> bad;
    for (size_t i = 0; i < plate.pixels.size(); ++i)
        if (!usable(plate.pixels[i])) bad.push_back(i);
    if (bad.empty()) return repair;
    // Neighbour means are taken from the plate as given, so the result does not depend on the
    // order in which bad values are repaired.
    const std::vector<float> given = plate.pixels;
    const int w = int(plate.width), h = int(plate.height);
    for (size_t i : bad) {
        const float v = given[i];
        if (!std::isfinite(v)) {
            ++repair.nonFinite;
            const size_t pixel = i / channels, c = i % channels;
            const int x = int(pixel % plate.width), y = int(pixel / plate.width);
            double sum = 0.0;
            int count = 0;
            for (int dy = -1; dy <= 1; ++dy)
                for (int dx = -1; dx <= 1; ++dx) {
                    const int nx = x + dx, ny = y + dy;
                    if ((dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
                    const float n = given[(size_t(ny) * plate.width + nx) * channels + c];
                    if (!usable(n)) continue;
                    sum += n;
                    ++count;
                }
            plate.pixels[i] = count > 0 ? float(sum / count) : 0.0f;
        } else {
            ++repair.negative;
            plate.pixels[i] = 0.0f;
        }
    }
    return repair;
}

}  // namespace previs
