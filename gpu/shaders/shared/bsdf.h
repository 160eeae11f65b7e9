// The glTF 2.0 metallic-roughness BSDF with KHR_materials_transmission, _ior, _specular and
// _volume (thin walls or solids), in a local shading frame (normal +Z). Shared by
// trace_paths.comp and the C++ tests.
//
// The material is a mixture of four lobes:
//   f = m·f_metal + (1−m)·[ f_dielectricReflection + (1−t)(1−E(wo))·c/π + t·f_transmission ]
// with m metallic, t transmission, c base colour, F the dielectric Fresnel term (exact Fresnel
// of the IOR, scaled by specularFactor and tinted by specularColor as KHR_materials_specular
// does), metal Fresnel by Schlick with F0 = c, microfacets by GGX with Smith height-correlated
// masking (alpha = roughness²). The limit cases DESIGN.md §4 names are exact: metallic 0 and
// specular 0 give Lambert; metallic 1, roughness 0, white give a perfect mirror; transmission 1,
// roughness 0 give a smooth Fresnel dielectric.
//
// One departure from the glTF specification's sample BRDF: the diffuse base is weighted by
// 1 − E(wo), the light the specular layer does not reflect, E being the layer's directional
// albedo (albedo scaling, Kulla & Conty 2017, the technique glTF's clearcoat and sheen
// extensions prescribe; tabulated in specular_albedo.h), instead of 1 − F(h·wo). Decided by
// BsdfTest.WhitePlasticFurnaceDecidesTheDiffuseWeight, a white base under a clear coat that
// should reflect all light: the specification's 1 − F(h·wo) reflects up to 1.21× at roughness
// 0.3 (1.83× smooth at grazing), and 1 − F(n·wo), used before, only 0.66 at roughness 1 and 80°
// (dark rims on rough objects: a rough layer reflects far less than F(n·wo) at grazing angles).
// 1 − E never exceeds 1 (the table bounds E from above) and is exact when smooth, where
// E = F(n·wo); it is not reciprocal, which a path tracer does not rely on.
//
// Rough dielectrics follow pbrt-v4's DielectricBxDF: a visible microfacet is sampled first and
// reflects or refracts with its own Fresnel term (always reflects on total internal reflection),
// so glass seen from inside beyond the critical angle still transmits through tilted microfacets.
// Single-scattering GGX still loses the light a microfacet sends back into the surface; the
// white furnace of clear glass (∫ f |cos| with refraction's 1/η² undone), at θo = 0°, 30°, 60°,
// 80° (BsdfTest.RoughGlassKeepsSingleScatteringTimesItsCompensation measures it):
//   roughness  from outside (η 1.5)        from inside (η 1/1.5)
//   0.1        1.000 1.000 1.000 0.999     1.000 1.000 1.000 0.998
//   0.3        0.999 0.999 0.994 0.948     0.991 0.988 0.971 0.894
//   0.5        0.992 0.988 0.961 0.913     0.930 0.907 0.829 0.797
//   1.0        0.894 0.855 0.742 0.709     0.418 0.455 0.513 0.497
// That light is not lost in real glass: it scatters again and leaves. The glass part of the
// material (weight t) is therefore scaled by 1/E(wo), E being the single-scattering energy above,
// tabulated (specular_albedo.h): the furnace gives 1 (within the table's resolution, never
// above; BsdfTest.RoughGlassFurnaceIsOne), as Cycles' multiscatter glass does. Like the diffuse
// weight, it is not reciprocal: a photon leaving rough glass (trace_photons.comp) takes the
// factor at the direction it leaves in, the camera path's wo. Thin walls keep single scattering.
//
// A thin-walled material (glTF: transmission without KHR_materials_volume, or thickness 0) is a
// slab too thin to see: light crosses both faces and leaves along its incoming direction (rough:
// the mirror image of the reflection lobe, as the glTF specification's thin-walled BTDF), the
// interface reflectance is the slab's, 2F/(1 + F), and radiance is not scaled by 1/η² (it ends
// in the medium it started in). The caller passes etaRel = ior from both sides.
//
// Convention: the caller flips the frame so that wo.z > 0 and passes etaRel, the IOR of the side
// a transmitted ray enters over the IOR of the side wo is on (ior when hitting a front face).
// Reflection keeps wi.z > 0, transmission gives wi.z < 0.
#ifndef PREVIS_SHARED_BSDF_H
#define PREVIS_SHARED_BSDF_H

#include "gpu/shaders/shared/prelude.h"
#include "gpu/shaders/shared/sampling.h"
#include "gpu/shaders/shared/specular_albedo.h"

PV_BEGIN

// Directions closer to the tangent plane than this cosine carry no energy (the cosine factor
// makes their contribution vanish) but would overflow the microfacet terms; they are skipped.
#define PV_MIN_COSINE 1.0e-7f

// Below this alpha a microfacet lobe is treated as a perfect specular (delta) lobe: GGX with
// alpha → 0 tends to it, and float D values overflow well before alpha = 0.
#define PV_DELTA_ALPHA 1.0e-4f

#define PV_LOBE_METAL 0u
#define PV_LOBE_DIELECTRIC_REFLECTION 1u
#define PV_LOBE_DIFFUSE 2u
#define PV_LOBE_TRANSMISSION 3u

struct BsdfParams {
    vec3 baseColor;
    float metallic;
    vec3 specularColor;
    float alpha;  // GGX roughness, perceptual roughness squared
    float transmission;
    float etaRel;  // see the convention above
    float specular;
    bool thinWalled;  // transmission through a thin slab, not into a volume (see above)
};

struct BsdfSample {
    vec3 wi;
    float pdf;    // solid angle pdf of the mixture; 0 for delta lobes
    vec3 weight;  // f·|cosθi| / pdf (for delta lobes: the lobe coefficient / choice prob)
    uint lobe;
    bool isDelta;
};

// Exact Fresnel reflectance of an unpolarised wave at a smooth dielectric boundary; cosThetaI
// measured on the incident side, eta = η_transmitted / η_incident. 1 on total internal reflection.
PV_INLINE float fresnelDielectric(float cosThetaI, float eta) {
    cosThetaI = clamp(cosThetaI, 0.0f, 1.0f);
    float sin2ThetaI = 1.0f - cosThetaI * cosThetaI;
    float sin2ThetaT = sin2ThetaI / (eta * eta);
    if (sin2ThetaT >= 1.0f) return 1.0f;
    float cosThetaT = sqrt(max(0.0f, 1.0f - sin2ThetaT));
    float rParl = (eta * cosThetaI - cosThetaT) / (eta * cosThetaI + cosThetaT);
    float rPerp = (cosThetaI - eta * cosThetaT) / (cosThetaI + eta * cosThetaT);
    return 0.5f * (rParl * rParl + rPerp * rPerp);
}

// The energy compensation of rough glass seen from wo: the factor on the glass part of the
// material (1/E, see above); 1 for smooth glass, thin walls and materials without transmission
// (a scene without transmission compiles this away: kHasTransmission zeroes p.transmission).
PV_INLINE float glassEnergyScale(BsdfParams p, float cosThetaO) {
    if (p.transmission <= 0.0f || p.thinWalled || p.alpha < PV_DELTA_ALPHA) return 1.0f;
    return 1.0f / max(glassAlbedo(cosThetaO, p.alpha, p.etaRel), 0.05f);
}

// The reflectance of the dielectric interface: one boundary, or for a thin wall the slab's two
// boundaries with the light bouncing between them, R + T²R/(1 − R²) = 2R/(1 + R) (the two
// faces have the same Fresnel term: the angle inside is the same on both, and Fresnel is
// symmetric under reversing the ray).
PV_INLINE vec3 dielectricFresnel(BsdfParams p, float cosThetaI) {
    float f = fresnelDielectric(cosThetaI, p.etaRel);
    if (p.thinWalled) f = 2.0f * f / (1.0f + f);
    return p.specular * min(p.specularColor * f, vec3(1.0f));
}

PV_INLINE bool bsdfIsDelta(BsdfParams p) { return p.alpha < PV_DELTA_ALPHA; }

// No diffuse base under the specular layer: a metal, full transmission or a black base.
PV_INLINE bool bsdfHasNoDiffuse(BsdfParams p) {
    return p.metallic >= 1.0f || p.transmission >= 1.0f || maxComponent(p.baseColor) <= 0.0f;
}

// Every lobe a delta (a smooth mirror, smooth glass without a diffuse base).
PV_INLINE bool bsdfIsPurelySpecular(BsdfParams p) { return bsdfIsDelta(p) && bsdfHasNoDiffuse(p); }

// Below this alpha (roughness 0.1) a mirror or glass scatters into a lobe so narrow that the
// light it throws from a lamp onto a diffuse surface is a caustic: the path tracer finds it only
// where a diffuse bounce happens to sample the lobe toward the lamp (white speckles beside a
// polished chrome ball under a softbox), the photon map as a density.
#define PV_CAUSTIC_ALPHA 0.01f

// A surface that carries caustics: purely specular, or as smooth as PV_CAUSTIC_ALPHA without a
// diffuse base (a polished metal, slightly rough glass). Photons pass through it, and a camera
// path gathers photons at every vertex that is not one (shared/photon_records.h).
PV_INLINE bool bsdfCarriesCaustics(BsdfParams p) {
    return p.alpha < PV_CAUSTIC_ALPHA && bsdfHasNoDiffuse(p);
}

// The share of light the specular layer lets through to the diffuse base seen from wo: one
// minus the layer's directional albedo (albedo scaling). Smooth, the albedo is F(n·wo); rough,
// it is the tabulated integral of the GGX lobe (specular_albedo.h), since the light a rough
// layer does not reflect is 1 − E, not 1 − F(n·wo). A thin wall keeps 1 − F(n·wo) of its slab
// Fresnel (the table holds one interface).
PV_INLINE vec3 diffuseWeight(BsdfParams p, float cosThetaO) {
    // No specular layer (specularFactor 0: a plain Lambertian): everything reaches the base.
    // Exact, and it spares the photon gather a table lookup per photon.
    if (p.specular <= 0.0f) return vec3(1.0f);
    if (bsdfIsDelta(p) || p.thinWalled) return vec3(1.0f) - dielectricFresnel(p, cosThetaO);
    float e = specularAlbedo(cosThetaO, p.alpha, p.etaRel);
    return vec3(1.0f) - min(p.specular * p.specularColor * e, vec3(1.0f));
}

PV_INLINE vec3 schlickFresnel(vec3 f0, float cosTheta) {
    float m = clamp(1.0f - cosTheta, 0.0f, 1.0f);
    float m2 = m * m;
    return f0 + (vec3(1.0f) - f0) * (m2 * m2 * m);
}

// D(h) = α² / (π (cos²θ (α²−1) + 1)²), with the denominator written as sin²θ + α² cos²θ from the
// components: the textbook form cancels to 0 in float for tiny α at h = n.
PV_INLINE float ggxD(vec3 h, float alpha) {
    float a2 = alpha * alpha;
    float d = (h.x * h.x + h.y * h.y) + a2 * (h.z * h.z);
    return a2 / (PV_PI * d * d);
}

PV_INLINE float ggxLambda(vec3 w, float alpha) {
    float z2 = w.z * w.z;
    if (z2 <= 0.0f) return PV_FLOAT_MAX;
    float tan2 = (w.x * w.x + w.y * w.y) / z2;
    return 0.5f * (sqrt(1.0f + alpha * alpha * tan2) - 1.0f);
}

PV_INLINE float ggxG1(vec3 w, float alpha) { return 1.0f / (1.0f + ggxLambda(w, alpha)); }

PV_INLINE float ggxG2(vec3 wo, vec3 wi, float alpha) {
    return 1.0f / (1.0f + ggxLambda(wo, alpha) + ggxLambda(wi, alpha));
}

// Density of visible normals seen from wo (Heitz 2018): D_wo(h) = G1(wo)·max(0, wo·h)·D(h)/wo.z.
PV_INLINE float ggxVisibleNormalPdf(vec3 wo, vec3 h, float alpha) {
    return ggxG1(wo, alpha) * max(0.0f, dot(wo, h)) * ggxD(h, alpha) / abs(wo.z);
}

// Samples a visible normal (Heitz 2018, "Sampling the GGX Distribution of Visible Normals").
PV_INLINE vec3 sampleGgxVisibleNormal(vec3 wo, float alpha, vec2 u) {
    vec3 vh = normalize(vec3(alpha * wo.x, alpha * wo.y, wo.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = lensq > 0.0f ? vec3(-vh.y, vh.x, 0.0f) * inversesqrt(lensq) : vec3(1.0f, 0.0f, 0.0f);
    vec3 t2 = cross(vh, t1);
    float r = sqrt(u.x);
    float phi = PV_TWO_PI * u.y;
    float p1 = r * cos(phi);
    float p2 = r * sin(phi);
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrt(max(0.0f, 1.0f - p1 * p1)) + s * p2;
    vec3 nh = p1 * t1 + p2 * t2 + sqrt(max(0.0f, 1.0f - p1 * p1 - p2 * p2)) * vh;
    return normalize(vec3(alpha * nh.x, alpha * nh.y, max(1.0e-7f, nh.z)));
}

// Refraction of wo about normal n (same side as wo) with eta = η_t/η_i; false on total internal
// reflection.
PV_INLINE bool refractDirection(vec3 wo, vec3 n, float eta, PV_OUT(vec3) wi) {
    float cosThetaI = dot(n, wo);
    float sin2ThetaI = max(0.0f, 1.0f - cosThetaI * cosThetaI);
    float sin2ThetaT = sin2ThetaI / (eta * eta);
    if (sin2ThetaT >= 1.0f) {
        wi = vec3(0.0f);
        return false;
    }
    float cosThetaT = sqrt(1.0f - sin2ThetaT);
    wi = -wo / eta + (cosThetaI / eta - cosThetaT) * n;
    return true;
}

// Lobe selection probabilities from the lobe coefficients seen from wo (a scalar estimate; the
// sample weight uses the exact coefficients, so the choice only affects variance): .x metal,
// .y the dielectric interface (reflection and transmission together), .z the diffuse base.
// Reflection and transmission are one lobe because the choice between them belongs to the
// microfacet, not to the macro surface: from inside glass beyond the critical angle the macro
// Fresnel term is 1, yet tilted microfacets still transmit (Walter et al. 2007).
PV_INLINE vec3 bsdfLobeProbabilities(BsdfParams p, vec3 wo) {
    float fe = maxComponent(dielectricFresnel(p, wo.z));
    float metal = p.metallic * maxComponent(schlickFresnel(p.baseColor, wo.z));
    float base = (1.0f - p.metallic) * (1.0f - fe) * maxComponent(p.baseColor);
    float diffuse = (1.0f - p.metallic) * (1.0f - p.transmission) *
                    maxComponent(diffuseWeight(p, wo.z) * p.baseColor);
    vec3 w = vec3(metal, (1.0f - p.metallic) * fe + base * p.transmission, diffuse);
    float sum = w.x + w.y + w.z;
    return sum > 0.0f ? w / sum : vec3(0.0f);
}

// Within the dielectric lobe, the probability of reflecting off a microfacet seen at cosine
// cosThetaH from wo: its reflection over its reflection plus transmission coefficient, as
// pbrt-v4's DielectricBxDF. Total internal reflection on the microfacet gives 1, so no sample
// is lost to a refraction that cannot happen.
PV_INLINE float dielectricReflectionProbability(BsdfParams p, float cosThetaH) {
    if (fresnelDielectric(cosThetaH, p.etaRel) >= 1.0f) return 1.0f;
    vec3 fd = dielectricFresnel(p, cosThetaH);
    float r = maxComponent(fd);
    float t = p.transmission * maxComponent((vec3(1.0f) - fd) * p.baseColor);
    return r + t > 0.0f ? r / (r + t) : 1.0f;
}

// Smooth glass and nothing else (no metal, no diffuse base), seen from where both its
// reflection and its refraction can happen: an integrator may follow both branches instead of
// choosing one (trace_paths.comp splits there, with smoothDielectricReflection and
// smoothDielectricRefraction). pReflect is the probability with which bsdfSample would choose
// the reflection.
PV_INLINE bool bsdfSplitsAtSmoothGlass(BsdfParams p, vec3 wo, PV_OUT(float) pReflect) {
    pReflect = 0.0f;
    if (!bsdfIsDelta(p) || p.metallic > 0.0f || p.transmission < 1.0f || wo.z < PV_MIN_COSINE)
        return false;
    pReflect = dielectricReflectionProbability(p, wo.z);
    return pReflect > 0.0f && pReflect < 1.0f;
}

// The non-delta part of the BSDF: f(wo, wi) (without the cosine) and the mixture pdf of
// sampling wi with bsdfSample. Delta lobes contribute nothing here.
PV_INLINE vec3 bsdfEvaluate(BsdfParams p, vec3 wo, vec3 wi, PV_OUT(float) pdf) {
    pdf = 0.0f;
    if (wo.z < PV_MIN_COSINE || abs(wi.z) < PV_MIN_COSINE) return vec3(0.0f);
    vec3 prob = bsdfLobeProbabilities(p, wo);
    bool delta = bsdfIsDelta(p);
    // The glass part (weight t) of the interface is energy-compensated, the rest is not.
    float glassScale = glassEnergyScale(p, wo.z);
    vec3 f = vec3(0.0f);
    if (wi.z > 0.0f) {
        vec3 h = normalize(wo + wi);
        float hDotO = max(dot(h, wo), 0.0f);
        vec3 fd = dielectricFresnel(p, hDotO);
        if (prob.z > 0.0f) {
            f += (1.0f - p.metallic) * (1.0f - p.transmission) * diffuseWeight(p, wo.z) *
                 p.baseColor * PV_INV_PI;
            pdf += prob.z * cosineHemispherePdf(wi.z);
        }
        if (!delta && hDotO > 0.0f) {
            float dg = ggxD(h, p.alpha) * ggxG2(wo, wi, p.alpha) / (4.0f * wo.z * wi.z);
            float reflectionPdf = ggxVisibleNormalPdf(wo, h, p.alpha) / (4.0f * hDotO);
            f += p.metallic * schlickFresnel(p.baseColor, hDotO) * dg;
            f += (1.0f - p.metallic) * fd * dg * (1.0f + p.transmission * (glassScale - 1.0f));
            pdf += (prob.x + prob.y * dielectricReflectionProbability(p, hDotO)) * reflectionPdf;
        }
    } else if (!delta && p.transmission > 0.0f && prob.y > 0.0f && p.thinWalled) {
        // A thin wall transmits into the mirror image of the reflection lobe: the light crosses
        // both faces of the slab, and the bending of the first is undone by the second.
        vec3 wr = vec3(wi.x, wi.y, -wi.z);
        vec3 h = normalize(wo + wr);
        float hDotO = dot(h, wo);
        if (hDotO > 0.0f) {
            vec3 fd = dielectricFresnel(p, hDotO);
            float dg = ggxD(h, p.alpha) * ggxG2(wo, wr, p.alpha) / (4.0f * wo.z * wr.z);
            f += (1.0f - p.metallic) * p.transmission * (vec3(1.0f) - fd) * p.baseColor * dg;
            pdf += prob.y * (1.0f - dielectricReflectionProbability(p, hDotO)) *
                   ggxVisibleNormalPdf(wo, h, p.alpha) / (4.0f * hDotO);
        }
    } else if (!delta && p.transmission > 0.0f && prob.y > 0.0f) {
        // Rough transmission (Walter et al. 2007), in pbrt-v4's form: wm is the generalised
        // half vector, and the pair (wo, wi) exists only through a microfacet that refracts.
        float etap = p.etaRel;
        vec3 wm = normalize(wi * etap + wo);
        if (wm.z < 0.0f) wm = -wm;
        float dotIM = dot(wi, wm);
        float dotOM = dot(wo, wm);
        if (dotIM < 0.0f && dotOM > 0.0f) {
            float denom = dotIM + dotOM / etap;
            float denom2 = denom * denom;
            if (denom2 > 0.0f) {
                vec3 fd = dielectricFresnel(p, dotOM);
                float ft = ggxD(wm, p.alpha) * ggxG2(wo, wi, p.alpha) *
                           abs(dotIM * dotOM / (wi.z * wo.z * denom2)) / (etap * etap);
                f += (1.0f - p.metallic) * p.transmission * (vec3(1.0f) - fd) * p.baseColor * ft *
                     glassScale;
                pdf += prob.y * (1.0f - dielectricReflectionProbability(p, dotOM)) *
                       ggxVisibleNormalPdf(wo, wm, p.alpha) * abs(dotIM) / denom2;
            }
        }
    }
    return f;
}

// The two branches of a smooth (delta) dielectric lobe: the mirror reflection and the refraction
// (straight through a thin wall), each weighted by its coefficient over `choice`, the
// probability with which the caller picked it (1 when it follows both). false when the branch
// carries nothing. wo.z ≥ PV_MIN_COSINE.
PV_INLINE bool smoothDielectricReflection(BsdfParams p, vec3 wo, float choice,
                                          PV_OUT(BsdfSample) s) {
    s.isDelta = true;
    s.pdf = 0.0f;
    s.lobe = PV_LOBE_DIELECTRIC_REFLECTION;
    s.wi = vec3(-wo.x, -wo.y, wo.z);
    s.weight = (1.0f - p.metallic) * dielectricFresnel(p, wo.z) / choice;
    return maxComponent(s.weight) > 0.0f;
}

PV_INLINE bool smoothDielectricRefraction(BsdfParams p, vec3 wo, float choice,
                                          PV_OUT(BsdfSample) s) {
    s.isDelta = true;
    s.pdf = 0.0f;
    s.lobe = PV_LOBE_TRANSMISSION;
    s.weight = (1.0f - p.metallic) * p.transmission * (vec3(1.0f) - dielectricFresnel(p, wo.z)) *
               p.baseColor / choice;
    if (p.thinWalled) {
        // Straight through the slab, back into the medium it came from.
        s.wi = -wo;
    } else {
        s.wi = vec3(0.0f, 0.0f, 1.0f);
        if (!refractDirection(wo, vec3(0.0f, 0.0f, 1.0f), p.etaRel, s.wi)) return false;
        // Radiance is scaled by 1/η² across the boundary (non-symmetric scattering, Veach 1997).
        s.weight /= p.etaRel * p.etaRel;
    }
    return maxComponent(s.weight) > 0.0f;
}

// Samples wi from the lobe mixture; false when no direction could be generated (black material,
// a microfacet that reflects below the surface or refracts above it) — the path ends there.
PV_INLINE bool bsdfSample(BsdfParams p, vec3 wo, float uLobe, vec2 u, PV_OUT(BsdfSample) s) {
    s.wi = vec3(0.0f, 0.0f, 1.0f);
    s.pdf = 0.0f;
    s.weight = vec3(0.0f);
    s.lobe = PV_LOBE_DIFFUSE;
    s.isDelta = false;
    if (wo.z < PV_MIN_COSINE) return false;
    vec3 prob = bsdfLobeProbabilities(p, wo);
    bool delta = bsdfIsDelta(p);
    // uDielectric re-uses uLobe, rescaled to [0, 1) within the dielectric lobe's interval, to
    // choose reflection or transmission on the microfacet.
    uint lobe;
    float uDielectric = 0.0f;
    if (uLobe < prob.x) {
        lobe = PV_LOBE_METAL;
    } else if (uLobe < prob.x + prob.y) {
        lobe = PV_LOBE_DIELECTRIC_REFLECTION;
        uDielectric = min((uLobe - prob.x) / prob.y, 0.99999994f);
    } else if (prob.z > 0.0f) {
        lobe = PV_LOBE_DIFFUSE;
    } else {
        return false;
    }
    if (delta && lobe != PV_LOBE_DIFFUSE) {
        // Perfect specular: the weight is the lobe's coefficient over its choice probability.
        s.isDelta = true;
        float cosO = wo.z;
        if (lobe == PV_LOBE_METAL) {
            s.wi = vec3(-wo.x, -wo.y, wo.z);
            s.weight = p.metallic * schlickFresnel(p.baseColor, cosO) / prob.x;
            s.lobe = lobe;
            return maxComponent(s.weight) > 0.0f;
        }
        float pReflect = dielectricReflectionProbability(p, cosO);
        if (uDielectric < pReflect) return smoothDielectricReflection(p, wo, prob.y * pReflect, s);
        return smoothDielectricRefraction(p, wo, prob.y * (1.0f - pReflect), s);
    }
    s.lobe = lobe;
    if (lobe == PV_LOBE_DIFFUSE) {
        s.wi = sampleCosineHemisphere(u);
    } else {
        vec3 h = sampleGgxVisibleNormal(wo, p.alpha, u);
        if (lobe == PV_LOBE_DIELECTRIC_REFLECTION &&
            uDielectric >= dielectricReflectionProbability(p, dot(wo, h))) {
            s.lobe = PV_LOBE_TRANSMISSION;
            if (p.thinWalled) {
                s.wi = reflect(-wo, h);
                s.wi.z = -s.wi.z;
            } else if (!refractDirection(wo, h, p.etaRel, s.wi)) {
                return false;
            }
        } else {
            s.wi = reflect(-wo, h);
        }
    }
    // A microfacet can send a reflection below the surface or a refraction above it; such
    // samples are discarded (single-scattering microfacets lose that energy), so bsdfEvaluate's
    // pdf (which counts each lobe only on its own side) is exactly the density of the
    // directions returned.
    bool reflection = s.lobe != PV_LOBE_TRANSMISSION;
    if (reflection ? s.wi.z < PV_MIN_COSINE : s.wi.z > -PV_MIN_COSINE) return false;
    vec3 f = bsdfEvaluate(p, wo, s.wi, s.pdf);
    if (!(s.pdf > 0.0f)) return false;
    s.weight = f * abs(s.wi.z) / s.pdf;
    return true;
}

// The reflection of wo about an adapted shading normal leaves the geometric surface at least at
// this cosine: above the tangent plane, and far enough from it that the reflected ray, offset
// from the surface, does not graze the facet it leaves.
#define PV_ADAPTED_REFLECTION_COSINE 1.0e-3f

// Shading-normal adaptation (Keller et al. 2017, "The Iray Light Transport Simulation and
// Rendering System", §A.3): where the mirror direction of wo about the interpolated (or normal-
// mapped) normal ns points below the geometric surface, ns is tilted toward the geometric normal
// ng just enough that it does not: the new normal is the half vector of wo and the nearest
// direction above the surface. A smooth mirror or glass then never sends a path into the facet
// it reflects from, which killed paths at the silhouettes of smooth-shaded meshes (and shading
// with ng instead, where wo is below ns, made a visible seam). World space; wo and ns on ng's
// side (wo·ng > 0, ns·ng ≥ 0), all unit vectors.
// The unit direction nearest to w on the side `side` (+1 or −1) of the plane normal to ng, at
// least PV_ADAPTED_REFLECTION_COSINE away from it; w itself when it already is. ng unit.
PV_INLINE vec3 nearestDirectionOnSide(vec3 w, vec3 ng, float side) {
    const float c = PV_ADAPTED_REFLECTION_COSINE;
    float a = dot(w, ng) * side;
    if (a >= c) return w;
    vec3 t = w - dot(w, ng) * ng;
    float tLen = length(t);
    if (!(tLen > 1.0e-6f)) return ng * side;
    return t * (sqrt(1.0f - c * c) / tLen) + (c * side) * ng;
}

PV_INLINE vec3 adaptShadingNormal(vec3 wo, vec3 ng, vec3 ns) {
    vec3 r = 2.0f * dot(wo, ns) * ns - wo;
    float a = dot(r, ng);
    if (a >= PV_ADAPTED_REFLECTION_COSINE) return ns;
    // Grazing wo: wo + r below cancels; the answer tends to ng anyway.
    if (dot(wo, ng) < 2.0f * PV_ADAPTED_REFLECTION_COSINE) return ng;
    return normalize(wo + nearestDirectionOnSide(r, ng, 1.0f));
}

PV_END

#endif
