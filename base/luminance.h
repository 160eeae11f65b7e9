#pragma once

// Relative luminance of linear Rec. 709 / sRGB primaries (ITU-R BT.709), the one weighting used
// for every "how bright" decision on the host. The shaders' copy is luminance() in
// gpu/shaders/shared/sampling.h (GLSL cannot include this header); keep the weights equal.

namespace previs {

inline constexpr double kLuminanceR = 0.2126, kLuminanceG = 0.7152, kLuminanceB = 0.0722;

template <typename T>
constexpr T luminance(T r, T g, T b) {
    return T(kLuminanceR) * r + T(kLuminanceG) * g + T(kLuminanceB) * b;
}

}  // namespace previs
