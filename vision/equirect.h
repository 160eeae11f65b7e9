#pragma once

// The equirectangular parameterisation of DESIGN.md §4, in one place: direction d (world, unit)
// ↔ u = 0.5 + atan2(d.z, d.x)/(2π), v = 0.5 − asin(d.y)/π, v = 0 the top row; and the exact
// solid angle of a texel.

#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>

namespace previs {

// (u, v) in [0,1]² → unit direction.
inline cv::Vec3d equirectDirection(double u, double v) {
    const double phi = (u - 0.5) * 2.0 * M_PI;
    const double lat = (0.5 - v) * M_PI;
    return {std::cos(lat) * std::cos(phi), std::sin(lat), std::cos(lat) * std::sin(phi)};
}

// Unit direction → (u, v).
inline cv::Vec2d equirectUv(const cv::Vec3d& d) {
    const double u = 0.5 + std::atan2(d[2], d[0]) / (2.0 * M_PI);
    const double v = 0.5 - std::asin(std::clamp(d[1], -1.0, 1.0)) / M_PI;
    return {u, v};
}

// Centre of texel (x, y) of a width × height map.
inline cv::Vec3d equirectTexelDirection(int x, int y, int width, int height) {
    return equirectDirection((x + 0.5) / width, (y + 0.5) / height);
}

// Exact solid angle of any texel of row y: (2π/W)·(cos θ_top − cos θ_bottom), θ the polar angle
// from +Y, θ_top = πy/H. Rows sum to 4π.
inline double equirectTexelSolidAngle(int y, int width, int height) {
    const double t0 = M_PI * y / height;
    const double t1 = M_PI * (y + 1) / height;
    return 2.0 * M_PI / width * (std::cos(t0) - std::cos(t1));
}

}  // namespace previs
