// Directional albedos of the GGX microfacet lobes, tabulated for albedo scaling (Kulla & Conty
// 2017; Turquin 2019), three tables of one shape:
//   PV_ALBEDO_SPECULAR_LAYER: the dielectric specular layer's reflection, E(μ, α, η) =
//     ∫ F(h·wo) D G2 / (4 μ) dωi over the upper hemisphere, for GGX with Smith height-correlated
//     masking and the exact Fresnel term of relative IOR η (μ = cos θo). bsdf.h weights the
//     diffuse base by 1 − E: the light the specular layer does not reflect (see bsdf.h for why).
//   PV_ALBEDO_GLASS_OUTSIDE, PV_ALBEDO_GLASS_INSIDE: the energy single-scattering GGX keeps at a
//     rough glass boundary (reflection plus refraction, refraction's 1/η² undone), seen from the
//     side of lower IOR (η) and of higher IOR (table at 1/η). bsdf.h scales rough glass by 1/E,
//     the light the microfacets would send on after scattering more than once (as Cycles'
//     multiscatter glass, which scales by 1 + F_ms(1 − E)/E with F_ms = 1 for clear glass).
//
// Each is tabulated on a regular grid in √μ = i/15, √α = j/15 and √((η − 1)/2) = k/15 (i, j, k =
// 0..15; √α is glTF's roughness; η from 1 to 3), interpolated trilinearly: the square roots crowd
// the nodes where E changes fastest, at grazing angles, near the smooth limit and near η = 1
// (glass seen from inside loses most where its IOR is near the outside's). Each node is raised
// by the most the interpolation falls below E in the cells around it, so a table bounds E from
// above: the diffuse weight 1 − E and the glass scale 1/E may lose a little energy, never create
// it (the loss is measured in test_bsdf). The values are written by the disabled tests
// BsdfTest.DISABLED_PrintSpecularAlbedoTable and DISABLED_PrintGlassAlbedoTables
// (tests/shading/bsdf_test.cpp; run them with --gtest_also_run_disabled_tests) and checked against
// a fresh integration by BsdfTest.SpecularAlbedoTableBoundsTheIntegral and
// GlassAlbedoTablesBoundTheIntegral.
#ifndef PREVIS_SHARED_SPECULAR_ALBEDO_H
#define PREVIS_SHARED_SPECULAR_ALBEDO_H

#include "gpu/shaders/shared/prelude.h"

#define PV_SPECULAR_ALBEDO_MU 16
#define PV_SPECULAR_ALBEDO_ALPHA 16
#define PV_SPECULAR_ALBEDO_ETA 16
#define PV_SPECULAR_ALBEDO_ETA_MIN 1.0f
#define PV_SPECULAR_ALBEDO_ETA_MAX 3.0f
// One table's entries, and the tables' order in kSpecularAlbedo.
#define PV_ALBEDO_TABLE_SIZE \
    (PV_SPECULAR_ALBEDO_MU * PV_SPECULAR_ALBEDO_ALPHA * PV_SPECULAR_ALBEDO_ETA)
#define PV_ALBEDO_SPECULAR_LAYER 0
#define PV_ALBEDO_GLASS_OUTSIDE 1
#define PV_ALBEDO_GLASS_INSIDE 2
#define PV_SPECULAR_ALBEDO_SIZE (3 * PV_ALBEDO_TABLE_SIZE)
// The tables in 16-byte texels, as the renderer uploads them ahead of the materials.
#define PV_SPECULAR_ALBEDO_TEXELS (PV_SPECULAR_ALBEDO_SIZE / 4)

PV_BEGIN

// Index: table · PV_ALBEDO_TABLE_SIZE + (k · PV_SPECULAR_ALBEDO_ALPHA + j) ·
// PV_SPECULAR_ALBEDO_MU + i.
#ifdef __cplusplus
inline constexpr float kSpecularAlbedo[PV_SPECULAR_ALBEDO_SIZE] = {
#include "gpu/shaders/shared/specular_albedo_table.inc"
    ,
#include "gpu/shaders/shared/glass_albedo_table.inc"
};
#define PV_SPECULAR_ALBEDO(index) kSpecularAlbedo[index]
#endif
// GLSL reads the table from a buffer the host fills from kSpecularAlbedo (render/renderer.cpp):
// a GLSL constant array indexed at run time is copied to every invocation's scratch memory by
// llvmpipe, which made the megakernel 20× slower. The includer defines
// PV_SPECULAR_ALBEDO(index) -> float before including this header.

PV_INLINE float albedoTableAt(int table, int i, int j, int k) {
    return PV_SPECULAR_ALBEDO(table * PV_ALBEDO_TABLE_SIZE +
                              (k * PV_SPECULAR_ALBEDO_ALPHA + j) * PV_SPECULAR_ALBEDO_MU + i);
}

// E(μ, α, η) of one table, clamped to the table's range (η below 1 reads as 1).
PV_INLINE float albedoTable(int table, float mu, float alpha, float eta) {
    float x = sqrt(clamp(mu, 0.0f, 1.0f)) * float(PV_SPECULAR_ALBEDO_MU - 1);
    float y = sqrt(clamp(alpha, 0.0f, 1.0f)) * float(PV_SPECULAR_ALBEDO_ALPHA - 1);
    float z = sqrt((clamp(eta, PV_SPECULAR_ALBEDO_ETA_MIN, PV_SPECULAR_ALBEDO_ETA_MAX) -
                    PV_SPECULAR_ALBEDO_ETA_MIN) /
                   (PV_SPECULAR_ALBEDO_ETA_MAX - PV_SPECULAR_ALBEDO_ETA_MIN)) *
              float(PV_SPECULAR_ALBEDO_ETA - 1);
    int i = min(int(x), PV_SPECULAR_ALBEDO_MU - 2);
    int j = min(int(y), PV_SPECULAR_ALBEDO_ALPHA - 2);
    int k = min(int(z), PV_SPECULAR_ALBEDO_ETA - 2);
    float fx = x - float(i);
    float fy = y - float(j);
    float fz = z - float(k);
    // Written out rather than looped: llvmpipe counts loop iterations against a shader-wide
    // budget (prelude.h).
    float e00 = mix(albedoTableAt(table, i, j, k), albedoTableAt(table, i + 1, j, k), fx);
    float e01 = mix(albedoTableAt(table, i, j + 1, k), albedoTableAt(table, i + 1, j + 1, k), fx);
    float e10 =
        mix(albedoTableAt(table, i, j, k + 1), albedoTableAt(table, i + 1, j, k + 1), fx);
    float e11 = mix(albedoTableAt(table, i, j + 1, k + 1),
                    albedoTableAt(table, i + 1, j + 1, k + 1), fx);
    float e0 = mix(e00, e01, fy);
    float e1 = mix(e10, e11, fy);
    float e = mix(e0, e1, fz);
    return e;
}

// The specular layer's reflection (η below 1 reads as 1: no reflection).
PV_INLINE float specularAlbedo(float mu, float alpha, float eta) {
    return albedoTable(PV_ALBEDO_SPECULAR_LAYER, mu, alpha, eta);
}

// Rough glass's single-scattering energy from either side (etaRel as in bsdf.h).
PV_INLINE float glassAlbedo(float mu, float alpha, float etaRel) {
    return etaRel >= 1.0f ? albedoTable(PV_ALBEDO_GLASS_OUTSIDE, mu, alpha, etaRel)
                          : albedoTable(PV_ALBEDO_GLASS_INSIDE, mu, alpha, 1.0f / etaRel);
}

PV_END

#endif
