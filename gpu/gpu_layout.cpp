// Compile-time checks that the C++ view of the shared structs matches the GLSL scalar layout
// (STYLE.md: every shared struct has static_assert(sizeof/offsetof) checks).
#include <cstddef>

#include "gpu/shaders/shared/composite.h"
#include "gpu/shaders/shared/denoise.h"
#include "gpu/shaders/shared/held_reprojection_params.h"
#include "gpu/shaders/shared/photon_records.h"
#include "gpu/shaders/shared/scene_types.h"

namespace previs::shader {

static_assert(sizeof(vec3) == 12 && alignof(vec3) == 4,
              "GLM vec3 must be packed as in scalar layout");
static_assert(sizeof(BvhNode) == 32);
static_assert(offsetof(BvhNode, leftOrFirst) == 12);
static_assert(offsetof(BvhNode, count) == 28);
static_assert(sizeof(GpuMaterial) == 96);
static_assert(offsetof(GpuMaterial, emission) == 16);
static_assert(offsetof(GpuMaterial, specularColor) == 32);
static_assert(offsetof(GpuMaterial, baseColorTexture) == 60);
static_assert(sizeof(TextureInfo) == 16);
static_assert(sizeof(GpuLight) == 48);
static_assert(offsetof(GpuLight, intensity) == 32);
static_assert(sizeof(EmissiveTriangle) == 16);
static_assert(offsetof(FrameParams, tanHalfFov) == 64);
static_assert(sizeof(FrameParams) % 4 == 0);
// Read as whole 16-byte texels (trace_paths.comp: materialAt, lightAt, emissiveTriangleAt,
// loadBvhNode), field by field in this order.
static_assert(sizeof(WideBvhNode) == 112 && offsetof(WideBvhNode, child) == 96);
static_assert(sizeof(BvhNode) % 16 == 0 && sizeof(GpuMaterial) % 16 == 0);
static_assert(sizeof(GpuLight) % 16 == 0 && sizeof(EmissiveTriangle) % 16 == 0);
static_assert(offsetof(GpuMaterial, metallic) == 28 && offsetof(GpuMaterial, roughness) == 44);
static_assert(offsetof(GpuMaterial, transmission) == 48 && offsetof(GpuMaterial, flags) == 76);
static_assert(offsetof(GpuMaterial, attenuation) == 80);
static_assert(offsetof(GpuLight, type) == 12 && offsetof(GpuLight, cosOuterCone) == 28);
static_assert(offsetof(GpuLight, cosInnerCone) == 44 && offsetof(EmissiveTriangle, pdf) == 12);
// Two texels (trace_paths.comp's gather reads position + flags, then power + direction).
static_assert(sizeof(PhotonRecord) == 32 && offsetof(PhotonRecord, flags) == 12);
static_assert(offsetof(PhotonRecord, power) == 16 && offsetof(PhotonRecord, direction) == 28);
static_assert(sizeof(DenoiseParams) == 144 && offsetof(DenoiseParams, tanHalfFov) == 64);
static_assert(sizeof(FilmParams) == 76 && offsetof(FilmParams, maskSharpness) == 24);
static_assert(offsetof(FilmParams, viewLutSize) == 72 &&
              offsetof(FilmParams, heldOutlineTest) == 40);
static_assert(offsetof(FilmParams, held) == 32 && offsetof(FilmParams, exposure) == 52);
static_assert(sizeof(ReprojectParams) == 96 && offsetof(ReprojectParams, width) == 80);
static_assert(offsetof(DenoiseParams, width) == 80 && offsetof(DenoiseParams, sigmaMask) == 140);

}  // namespace previs::shader
