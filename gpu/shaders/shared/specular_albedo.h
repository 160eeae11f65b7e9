// Directional albedo of the dielectric specular lobe, E(μ, α, η) = ∫ F(h·wo) D G2 / (4 μ) dωi
// over the upper hemisphere, for GGX with Smith height-correlated masking and the exact Fresnel
// term of relative IOR η (μ = cos θo). bsdf.h weights the diffuse base by 1 − E: the light the
// specular layer does not reflect (albedo scaling, Kulla & Conty 2017; see bsdf.h for why).
//
// Tabulated on a regular grid in √μ = i/15, √α = j/15 (i, j = 0..15; √α is glTF's roughness)
// and η = 1 + 2k/7 (k = 0..7), interpolated trilinearly: the square roots crowd the nodes where
// E changes fastest, at grazing angles and near the smooth limit. Each node is raised by the
// most the interpolation falls below E in the cells around it, so the table bounds E from above
// (the diffuse weight 1 − E may lose a little energy, never create it; the loss is measured in
// test_bsdf). The values are written by the disabled test
// BsdfTest.DISABLED_PrintSpecularAlbedoTable (tests/shading/test_bsdf.cpp; run it with
// --gtest_also_run_disabled_tests) and checked against a fresh integration by
// BsdfTest.SpecularAlbedoTableBoundsTheIntegral.
#ifndef PREVIS_SHARED_SPECULAR_ALBEDO_H
#define PREVIS_SHARED_SPECULAR_ALBEDO_H

#include "shared/prelude.h"

#define PV_SPECULAR_ALBEDO_MU 16
#define PV_SPECULAR_ALBEDO_ALPHA 16
#define PV_SPECULAR_ALBEDO_ETA 8
#define PV_SPECULAR_ALBEDO_ETA_MIN 1.0f
#define PV_SPECULAR_ALBEDO_ETA_MAX 3.0f
#define PV_SPECULAR_ALBEDO_SIZE \
    (PV_SPECULAR_ALBEDO_MU * PV_SPECULAR_ALBEDO_ALPHA * PV_SPECULAR_ALBEDO_ETA)
// The table in 16-byte texels, as the renderer uploads it ahead of the materials.
#define PV_SPECULAR_ALBEDO_TEXELS (PV_SPECULAR_ALBEDO_SIZE / 4)

PV_BEGIN

// Index: (k · PV_SPECULAR_ALBEDO_ALPHA + j) · PV_SPECULAR_ALBEDO_MU + i.
#ifdef __cplusplus
inline constexpr float kSpecularAlbedo[PV_SPECULAR_ALBEDO_SIZE] = {
#include "shared/specular_albedo_table.inc"
};
#define PV_SPECULAR_ALBEDO(index) kSpecularAlbedo[index]
#endif
// GLSL reads the table from a buffer the host fills from kSpecularAlbedo (render/renderer.cpp):
// a GLSL constant array indexed at run time is copied to every invocation's scratch memory by
// llvmpipe, which made the megakernel 20× slower. The includer defines
// PV_SPECULAR_ALBEDO(index) -> float before including this header.

PV_INLINE float specularAlbedoAt(int i, int j, int k) {
    return PV_SPECULAR_ALBEDO((k * PV_SPECULAR_ALBEDO_ALPHA + j) * PV_SPECULAR_ALBEDO_MU + i);
}

// E(μ, α, η), clamped to the table's range (η below 1 reads as 1: no reflection).
PV_INLINE float specularAlbedo(float mu, float alpha, float eta) {
    float x = sqrt(clamp(mu, 0.0f, 1.0f)) * float(PV_SPECULAR_ALBEDO_MU - 1);
    float y = sqrt(clamp(alpha, 0.0f, 1.0f)) * float(PV_SPECULAR_ALBEDO_ALPHA - 1);
    float z = (clamp(eta, PV_SPECULAR_ALBEDO_ETA_MIN, PV_SPECULAR_ALBEDO_ETA_MAX) -
               PV_SPECULAR_ALBEDO_ETA_MIN) /
              (PV_SPECULAR_ALBEDO_ETA_MAX - PV_SPECULAR_ALBEDO_ETA_MIN) *
              float(PV_SPECULAR_ALBEDO_ETA - 1);
    int i = min(int(x), PV_SPECULAR_ALBEDO_MU - 2);
    int j = min(int(y), PV_SPECULAR_ALBEDO_ALPHA - 2);
    int k = min(int(z), PV_SPECULAR_ALBEDO_ETA - 2);
    float fx = x - float(i);
    float fy = y - float(j);
    float fz = z - float(k);
    // Written out rather than looped: llvmpipe counts loop iterations against a shader-wide
    // budget (prelude.h).
    float e0 = mix(mix(specularAlbedoAt(i, j, k), specularAlbedoAt(i + 1, j, k), fx),
                   mix(specularAlbedoAt(i, j + 1, k), specularAlbedoAt(i + 1, j + 1, k), fx), fy);
    float e1 = mix(mix(specularAlbedoAt(i, j, k + 1), specularAlbedoAt(i + 1, j, k + 1), fx),
                   mix(specularAlbedoAt(i, j + 1, k + 1), specularAlbedoAt(i + 1, j + 1, k + 1),
                       fx),
                   fy);
    float e = mix(e0, e1, fz);
    return e;
}

PV_END

#endif
