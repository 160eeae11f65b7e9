#pragma once

// Where the specialization constants are applied: on the host before the driver compiles
// (gpu/spirv_specialise.h: it compiles less code), or by the driver (the reference the tests
// compare the first against; RendererTestOptions::specialise in render/renderer.h).

namespace previs {

enum class Specialise { OnHost, InDriver };

}  // namespace previs
