#pragma once

// Specialisation of a SPIR-V module on the host, before the driver sees it. A driver compiles
// the whole module — on lavapipe it inlines every call and runs its optimisation loop over the
// inlined code — before it folds the specialization constants and drops the code they disable.
// Freezing the constants and removing dead branches and functions first hands it less than half
// the code: pipeline creation 0.44 → 0.19 s on the area-light scene (BENCHMARKS.md).

#include <cstdint>
#include <span>
#include <vector>

#include "base/result.h"

namespace previs {

// The version of specialiseSpirv's pass list: part of a cached module's key (gpu/spirv_cache.h),
// so that a changed list never reads an entry the old one wrote. Bump it with any change there.
inline constexpr uint32_t kSpecialisePassesVersion = 1;

// `spirv` with its 32-bit specialization constants (id i = constants[i]) frozen to constants and
// the branches and functions they disable removed (SPIRV-Tools). The result has no
// specialization constants left; it computes what the driver would with the same values.
Result<std::vector<uint32_t>> specialiseSpirv(std::span<const uint32_t> spirv,
                                              std::span<const uint32_t> constants);

}  // namespace previs
