// trace_photons: the photon pass of one iteration. Each invocation emits one photon from a
// photon light (chosen by the power it sends toward the specular objects), aimed at the sphere
// that holds every triangle that carries caustics, follows its scatterings there and stores
// it where it first lands on anything else after at least one of them (L S+ D, level 1), then
// once more where it lands next (level 2; shared/photon_records.h says why and which paths that
// carries). Like the path tracer's paths, a photon from a real light starts in both solutions
// and splits where it first meets a virtual object: the mixed photon goes on from the virtual
// surface, the real one continues the same ray behind it. Output: four records per photon in
// photon order, and the (bucket, record) sort pairs of the records that hold a photon, packed at
// the start of their workgroup's slots in record order with the workgroup's count beside them
// (most slots stay empty: on the caustics benchmark a quarter hold one), which photon_grid.comp
// gathers into one array and sorts.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

#include "scene_access.glsl"
#include "gpu/shaders/shared/photon_records.h"

layout(local_size_x = PV_PHOTON_GROUP_SIZE) in;

layout(binding = PV_BINDING_PHOTON_LIGHTS) uniform usamplerBuffer photonLightTexels;
layout(binding = PV_BINDING_PHOTON_RECORDS, scalar) writeonly buffer Records {
    PhotonRecord records[];
};
layout(binding = PV_BINDING_PHOTON_SORT_B, scalar) writeonly buffer SortPairs {
    uvec2 sortPairs[];
};
layout(binding = PV_BINDING_PHOTON_BLOCK_COUNTS, scalar) writeonly buffer GroupCounts {
    uint groupCounts[];
};

layout(binding = PV_BINDING_PHOTON_SPLATS, scalar) buffer Splats { uint splats[]; };

shared uint groupStored[PV_PHOTON_GROUP_SIZE];

// The photon light whose inclusive cdf first exceeds u (binary search).
uint pickPhotonLight(float u) {
    uint lo = 0u;
    uint hi = params.photonLightCount - 1u;
    while (lo < hi) {
        PV_COUNT_LOOP_ITERATION();
        uint mid = (lo + hi) / 2u;
        if (u < uintBitsToFloat(texelFetch(photonLightTexels, int(mid)).z)) hi = mid; else lo = mid + 1u;
    }
    return lo;
}

// A direction from `from` uniform in the cone that the aim sphere subtends (every direction when
// `from` is inside it); `solidAngle` is that cone's (the inverse of the direction's pdf).
vec3 sampleTowardAim(vec3 from, vec2 u, out float solidAngle) {
    vec3 d = params.photonAimCenter - from;
    float dist2 = dot(d, d);
    float r2 = params.photonAimRadius * params.photonAimRadius;
    if (dist2 <= r2) {
        solidAngle = 2.0 * PV_TWO_PI;
        return sampleUniformSphere(u);
    }
    // 1 − cos θmax as sin²/(1 + cos): no cancellation for a small, distant sphere.
    float sin2 = r2 / dist2;
    float oneMinusCos = sin2 / (1.0 + sqrt(max(0.0, 1.0 - sin2)));
    solidAngle = PV_TWO_PI * oneMinusCos;
    Frame f;
    f.n = d * inversesqrt(dist2);
    buildBasis(f.n, f.t, f.b);
    return toWorld(f, sampleUniformCone(u, oneMinusCos));
}

// A ray of a distant light travelling along `dir`: it starts outside the scene on a disk
// perpendicular to `dir` the size of the aim sphere's cross-section (area π R²).
Ray distantPhotonRay(vec3 dir, vec2 u) {
    Frame f;
    f.n = dir;
    buildBasis(f.n, f.t, f.b);
    vec2 disk = params.photonAimRadius * sampleUniformDiskConcentric(u);
    Ray ray;
    ray.origin = params.photonAimCenter + disk.x * f.t + disk.y * f.b - dir * params.photonSceneRadius;
    ray.direction = dir;
    ray.tMin = 0.0;
    ray.tMax = PV_FLOAT_MAX;
    return ray;
}

// A photon's random numbers: the path tracer's generator (shared/sampler.h) with the photon as
// the sample and the iteration as the "pixel", so that under Sobol' the iteration's photons are
// one scrambled net: their points on the light and lobe choices split in proportion, which
// smooths the caustic's density estimate; their directions are stratified as evenly, along a
// curve that keeps consecutive photons together (photonDirectionSample). Each iteration is
// scrambled afresh, so iterations stay independent and the estimate unbiased.
#define PV_PHOTON_SET_EMIT 0u    // .xyw direction toward the aim, .z light pick
#define PV_PHOTON_SET_POINT 1u   // .xy point on the light (or on a distant light's disk)
#define PV_PHOTON_SET_BOUNCE 2u  // + b: scattering b (.xy direction, .z lobe)

// Emits photon `photon`: its first ray and its power (flux, over the iteration's photon count).
// False when the sample carries nothing (a back face, outside a spot's cone).
bool emitPhoton(uint photon, SampleKey key, out Ray ray, out vec3 power, out bool real) {
    vec4 uEmit = sampleSet(kSampler, key, PV_PHOTON_SET_EMIT);
    uvec4 entry = texelFetch(photonLightTexels, int(pickPhotonLight(uEmit.z)));
    float pick = uintBitsToFloat(entry.w) * float(params.photonCount);
    real = (entry.x & PV_PHOTON_LIGHT_REAL) != 0u;
    vec2 uPoint = sampleSet(kSampler, key, PV_PHOTON_SET_POINT).xy;
    vec2 uDir = photonDirectionSample(photon, params.photonCount, uEmit.xyw, uEmit.xy);
    ray.tMin = 0.0;
    ray.tMax = PV_FLOAT_MAX;
    power = vec3(0.0);
    if ((entry.x & 0xffu) == PV_PHOTON_LIGHT_TRIANGLE) {
        uint t = entry.y;
        uvec4 tri = triangleAt(t);
        vec3 p0 = PV_TRIANGLE_VERTEX(t, 0u);
        vec3 p1 = PV_TRIANGLE_VERTEX(t, 1u);
        vec3 p2 = PV_TRIANGLE_VERTEX(t, 2u);
        vec2 b = sampleUniformTriangle(uPoint);
        vec3 p = (1.0 - b.x - b.y) * p0 + b.x * p1 + b.y * p2;
        vec3 n = cross(p1 - p0, p2 - p0);
        float area = 0.5 * length(n);
        if (!(area > 0.0)) return false;
        n = normalize(n);
        float solidAngle;
        vec3 dir = sampleTowardAim(p, uDir, solidAngle);
        float cosLight = dot(dir, n);
        GpuMaterial m = materialAt(tri.w);
        if (cosLight == 0.0 || !emitsToward(m, cosLight > 0.0)) return false;
        vec2 uv = (1.0 - b.x - b.y) * uvAt(tri.x) + b.x * uvAt(tri.y) + b.y * uvAt(tri.z);
        // Φ = Le·|cos θ| / (p_area · p_dir) with p_area = 1/area and p_dir = 1/solidAngle.
        power = emittedRadiance(m, uv) * abs(cosLight) * area * solidAngle / pick;
        ray.origin = offsetRayOrigin(p, cosLight > 0.0 ? n : -n);
        ray.direction = dir;
        return maxComponent(power) > 0.0;
    }
    float crossSection = PV_PI * params.photonAimRadius * params.photonAimRadius;
    if ((entry.x & 0xffu) == PV_PHOTON_LIGHT_ENVIRONMENT) {
        // The environment as a distant light: a direction d from its importance sampling (the
        // light arrives from d; the photon travels along −d), then a point on the disk:
        // Φ = Le(d) · π R² / p(d), p the solid-angle density the path tracer's light sampling
        // draws with.
        float pdf;
        uint texel;
        vec3 d = envSampleTexel(uDir, params.envWidth, params.envHeight,
                                vec2(params.envRotationCos, params.envRotationSin), pdf, texel);
        if (!(pdf > 0.0)) return false;
        ray = distantPhotonRay(-d, uPoint);
        power = params.envScale * envRadianceAt(texel) * crossSection / (pdf * pick);
        return maxComponent(power) > 0.0;
    }
    GpuLight light = lightAt(entry.y);
    uint type = light.type & PV_LIGHT_TYPE_MASK;
    if (type == PV_LIGHT_DIRECTIONAL) {
        // Illuminance E (lux) over the disk: Φ = E · π R².
        ray = distantPhotonRay(light.direction, uPoint);
        power = light.intensity * crossSection / pick;
    } else if (type == PV_LIGHT_CONE) {
        // Radiance L over a cone of solid angle Ω: Φ = L · Ω · π R² (direction, then the disk).
        Frame f;
        f.n = light.direction;
        buildBasis(f.n, f.t, f.b);
        vec3 dir = toWorld(f, sampleUniformCone(uDir, light.cosInnerCone));
        ray = distantPhotonRay(dir, uPoint);
        power = light.intensity * (PV_TWO_PI * light.cosInnerCone) * crossSection / pick;
    } else {
        // Point and spot: intensity I (W/sr) over the cone toward the aim sphere: Φ = I · Ω.
        float solidAngle;
        vec3 dir = sampleTowardAim(light.position, uDir, solidAngle);
        vec3 intensity = light.intensity;
        if (type == PV_LIGHT_SPOT) {
            // The same smooth falloff as the path tracer's light sampling.
            float cd = dot(light.direction, dir);
            float scale = 1.0 / max(0.001, light.cosInnerCone - light.cosOuterCone);
            float a = clamp((cd - light.cosOuterCone) * scale, 0.0, 1.0);
            intensity *= a * a;
        }
        ray.origin = light.position;
        ray.direction = dir;
        power = intensity * solidAngle / pick;
    }
    return maxComponent(power) > 0.0;
}

struct PhotonState {
    Ray ray;
    vec3 power;
    uint bounces;  // scatterings so far
    uint level;    // records stored so far (0: still on its specular chain; 1: landed once)
};

// The records this invocation's photon stores (level 1 and 2, mixed and real slots).
PhotonRecord gStored[PV_PHOTON_RECORDS_PER_PHOTON];

// Adds v to the fixed-point sum (FixedRgb) at splats[at..at+5] (per channel: fraction, whole)
// with atomics: integer additions, carries included, give the same bits in any order, so a
// replay is byte-identical and two solutions that splat the same photons hold the same sums.
void splatAdd(uint at, vec3 v) {
    FixedRgb x = fixedFromValue(v);
    for (uint c = 0u; c < 3u; ++c) {
        uint before = atomicAdd(splats[at + 2u * c], x.fraction[c]);
        uint carry = before > 0xffffffffu - x.fraction[c] ? 1u : 0u;
        if (x.whole[c] + carry > 0u) atomicAdd(splats[at + 2u * c + 1u], x.whole[c] + carry);
    }
}

// Light tracing's last step for a photon just stored at s (shared/photon_records.h's level 1 or 2),
// in place of the camera path's gather at its first vertex: where the camera sees s directly,
// the photon's light toward the camera goes to the pixel it lands in,
//   f(w_cam, w_i) · Φ · |cos θ_s| / (d² · cos³θ_c · A_pixel),
// the change of variables from the pixel's film area (A_pixel on the plane z = −1, where
// cameraRay's jitter is uniform) to the surface: dA_film = |cos θ_s| dA / (d² cos³θ_c), d the
// distance to the eye and θ_c the angle off the optical axis. Every photon the pixel sees counts,
// at no gather radius: no blur beyond the pixel's own box, where a gather at a jittered point
// took only the photons within r of it (docs/caustics.md, "The caustic seen directly"). What
// the camera sees of each solution follows trace_paths' rules: a mixed photon needs no blocker
// in the mixed scene; a real one no real blocker, and it is subtracted in the composite only
// where no virtual object hides it (there the camera's first hit is virtual, M = 1).
//
// The surface and its BSDF are taken as the camera ray sees them (normals toward the eye, the
// shading normal adapted to that ray), as the camera path's gather took them: a photon through
// a rough or thin transmitter seen from the other side still counts.
void splatToCamera(Hit hit, vec3 position, GpuMaterial m, PhotonState st, uint mode) {
    vec3 eye = params.worldFromCamera[3].xyz;
    vec3 toEye = eye - position;
    vec3 c = inverse(mat3(params.worldFromCamera)) * -toEye;  // camera frame, looking along −Z
    if (!(c.z < 0.0)) return;
    vec2 ndc = vec2(c.x, c.y) / (-c.z * params.tanHalfFov);
    vec2 film = vec2((ndc.x + 1.0) * 0.5 * float(params.width),
                     (1.0 - ndc.y) * 0.5 * float(params.height));
    if (!(film.x >= 0.0 && film.y >= 0.0 && film.x < float(params.width) &&
          film.y < float(params.height)))
        return;
    float dist2 = dot(toEye, toEye);
    float dist = sqrt(dist2);
    vec3 wCam = toEye / dist;
    Ray fromEye;
    fromEye.origin = eye;
    fromEye.direction = -wCam;
    Surface s = surfaceAt(fromEye, hit);
    BsdfParams bp = bsdfParamsAt(m, s);
    Frame frame;
    frame.n = s.shadingNormal;
    buildBasis(frame.n, frame.t, frame.b);
    vec3 wo = toLocal(frame, wCam);
    vec3 wi = -st.ray.direction;
    vec3 wiLocal = toLocal(frame, wi);
    if (!consistentSide(s, wCam, wo) || !consistentSide(s, wi, wiLocal)) return;
    float pdf;
    vec3 f = evaluateBsdf(bp, wo, wiLocal, pdf);
    float cosCamera = -c.z / length(c);
    float pixelArea = 4.0 * params.tanHalfFov.x * params.tanHalfFov.y /
                      (float(params.width) * float(params.height));
    vec3 l = f * st.power *
             (abs(dot(s.geometricNormal, wCam)) /
              (dist2 * cosCamera * cosCamera * cosCamera * pixelArea));
    if (!(maxComponent(l) > 0.0)) return;
    Ray ray = directionRay(s.position, s.geometricNormal, wCam, dist);
    // Real and shared photons test the virtual objects too: whether one hides them from the
    // mixed camera ray decides the composite.
    uint blocker = occluder(ray, mode == MODE_MIXED ? MODE_MIXED : MODE_SHARED);
    uint pixel = uint(film.y) * params.width + uint(film.x);
    if (mode != MODE_REAL && blocker == OCCLUDER_NONE) splatAdd(splatWord(PV_SPLAT_MIXED, pixel), l);
    if (kDifferential && mode != MODE_MIXED && blocker != OCCLUDER_REAL) {
        splatAdd(splatWord(PV_SPLAT_REAL, pixel), l);
        if (blocker == OCCLUDER_NONE) splatAdd(splatWord(PV_SPLAT_REAL_UNHIDDEN, pixel), l);
    }
}

// One segment of the photon in `st` (solution `mode`): the ray to its next hit, a record where it
// lands, and the scattered ray. Returns true when the photon has ended. Where a shared photon
// first meets a virtual object, its real solution's continuation is stored in realContinuation.
bool extendPhoton(SampleKey key, inout PhotonState st, inout uint mode,
                  inout PhotonState realContinuation, inout bool haveRealContinuation) {
    Hit hit;
    if (!intersectScene(st.ray, mode, hit)) return true;
    if (hit.triangle >= params.realTriangleCount && mode == MODE_SHARED) {
        realContinuation = st;
        haveRealContinuation = true;
        mode = MODE_MIXED;
    }
    Surface s = surfaceAt(st.ray, hit);
    GpuMaterial m = materialAt(s.material);
    if (kHasTransmission && !s.frontFace && maxComponent(m.attenuation) > 0.0)
        st.power *= exp(-m.attenuation * hit.t);  // Beer–Lambert, as trace_paths
    BsdfParams bp = bsdfParamsAt(m, s);
    bool landed = !bsdfCarriesCaustics(bp);
    if (landed) {
        // Direct light (no specular scattering yet) is the path tracer's.
        if (st.bounces == 0u) return true;
        uint slot = 2u * st.level + (mode == MODE_REAL ? 1u : 0u);
        uint solutions = mode == MODE_SHARED ? PV_PHOTON_IN_MIXED | PV_PHOTON_IN_REAL
                         : mode == MODE_MIXED ? PV_PHOTON_IN_MIXED
                                              : PV_PHOTON_IN_REAL;
        gStored[slot].position = s.position;
        gStored[slot].flags = solutions | (st.level == 1u ? PV_PHOTON_LEVEL_2 : 0u) |
                              (st.bounces << PV_PHOTON_BOUNCES_SHIFT);
        gStored[slot].power = st.power;
        gStored[slot].direction = packSnorm2x16(octahedralEncode(-st.ray.direction));
        if (photonSplatsActive()) splatToCamera(hit, s.position, m, st, mode);
        if (st.level == 1u) return true;
        st.level = 1u;
    }
    if (st.bounces >= params.photonMaxBounces) return true;
    Frame frame;
    frame.n = s.shadingNormal;
    buildBasis(frame.n, frame.t, frame.b);
    vec3 wo = toLocal(frame, -st.ray.direction);
    BsdfSample bs;
    vec4 u = sampleSet(kSampler, key, PV_PHOTON_SET_BOUNCE + st.bounces);
    if (!sampleBsdf(bp, wo, u, bs)) return true;
    // On to level 2 only through the non-delta part of D's BSDF (shared/photon_records.h):
    // a delta lobe there is the path tracer's.
    if (landed && bs.isDelta) return true;
    vec3 wi = toWorld(frame, bs.wi);
    if (!consistentSide(s, wi, bs.wi)) {
        // As trace_paths' scatter: a delta direction moves to its promised side, a sampled one
        // (a polished S vertex's) ends.
        if (!bs.isDelta) return true;
        wi = nearestDirectionOnSide(wi, s.geometricNormal, bs.wi.z > 0.0 ? 1.0 : -1.0);
    }
    // Flux is not rescaled by 1/η² across a refraction (radiance is; the sample weight
    // holds that factor for the path tracer's radiance): the adjoint BSDF (Veach 1997).
    // A thin wall does not refract, and its weight has no such factor.
    vec3 weight = bs.weight;
    if (bs.lobe == PV_LOBE_TRANSMISSION && !bp.thinWalled) weight *= bp.etaRel * bp.etaRel;
    // Rough glass's energy compensation (bsdf.h) is 1/E at the camera path's wo, which for the
    // light path is the direction the photon leaves in (seen from the other side of the
    // interface when it refracts), not the one it came from: the adjoint takes that factor.
    BsdfParams seen = bp;
    if (bs.lobe == PV_LOBE_TRANSMISSION) seen.etaRel = 1.0 / bp.etaRel;
    weight *= glassEnergyScale(seen, abs(bs.wi.z)) / glassEnergyScale(bp, wo.z);
    if (landed) {
        // Russian roulette on the albedo: level-2 photons keep about the power of
        // level-1 ones, so the density estimate is not a sum of faint photons.
        float pContinue = min(1.0, maxComponent(weight));
        if (!(u.w < pContinue)) return true;
        weight /= pContinue;
    }
    st.power *= weight;
    st.bounces += 1u;
    st.ray = directionRay(s.position, s.geometricNormal * (bs.wi.z > 0.0 ? 1.0 : -1.0),
                          wi, PV_FLOAT_MAX);
    return false;
}

void main() {
    params = paramsBuffer;  // before any branch (scene_access.glsl)
    // Whole workgroups only (photonCount is a multiple of the group size): no invocation leaves
    // before the barrier below.
    uint photon = gl_GlobalInvocationID.x;
    for (uint k = 0u; k < PV_PHOTON_RECORDS_PER_PHOTON; ++k) {
        gStored[k].position = vec3(0.0);
        gStored[k].flags = 0u;
        gStored[k].power = vec3(0.0);
        gStored[k].direction = 0u;
    }
    PhotonState st;
    SampleKey key = makeSampleKey(params.photonIteration, photon, params.seed ^ 0x9e3779b9u, 0u);
    st.bounces = 0u;
    st.level = 0u;
    bool real;
    bool emitted = params.photonLightCount > 0u && emitPhoton(photon, key, st.ray, st.power, real);
    uint mode = kDifferential && real ? MODE_SHARED : MODE_MIXED;
    PhotonState realContinuation = st;
    bool haveRealContinuation = false;
    // One loop traces the photon, then its real solution's continuation behind a virtual object,
    // and tests its exit at the end: llvmpipe runs a loop's whole body once more (masked) after
    // the last lane of a batch breaks at the top, and a second loop for the continuation would
    // run at least once for every batch (trace_paths.comp's tracePaths says more).
    if (emitted) {
        for (;;) {
            PV_COUNT_LOOP_ITERATION();
            bool ended = extendPhoton(key, st, mode, realContinuation, haveRealContinuation);
            if (ended) {
                if (!haveRealContinuation) break;
                st = realContinuation;
                mode = MODE_REAL;
                haveRealContinuation = false;
            }
        }
    }
    float cellSize = photonCellSize(params.photonRadius);
    uint stored = 0u;
    for (uint k = 0u; k < PV_PHOTON_RECORDS_PER_PHOTON; ++k) {
        records[PV_PHOTON_RECORDS_PER_PHOTON * photon + k] = gStored[k];
        stored += gStored[k].flags != 0u ? 1u : 0u;
    }
    // The pairs of the stored records only, in record order: this photon's go after those of the
    // group's photons before it. Counts, not atomics: the order is the same on every run.
    uint local = gl_LocalInvocationID.x;
    groupStored[local] = stored;
    barrier();
    uint slot = gl_WorkGroupID.x * PV_PHOTON_GROUP_SLOTS;
    for (uint j = 0u; j < local; ++j) slot += groupStored[j];
    for (uint k = 0u; k < PV_PHOTON_RECORDS_PER_PHOTON; ++k) {
        if (gStored[k].flags != 0u) {
            uint key = photonBucket(photonCell(gStored[k].position, cellSize));
            sortPairs[slot] = uvec2(key, PV_PHOTON_RECORDS_PER_PHOTON * photon + k);
            slot += 1u;
        }
    }
    if (local == PV_PHOTON_GROUP_SIZE - 1u) {
        groupCounts[gl_WorkGroupID.x] =
            slot - gl_WorkGroupID.x * PV_PHOTON_GROUP_SLOTS;
    }
    // One more entry after the groups' counts: the compaction's scan turns it into the total.
    if (photon == 0u) groupCounts[params.photonCount / PV_PHOTON_GROUP_SIZE] = 0u;
}
