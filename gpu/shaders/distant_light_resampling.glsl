// ReSTIR for the preview's first vertex (Bitterli et al. 2020, "Spatiotemporal reservoir
// resampling for real-time ray tracing with dynamic direct lighting"): the distant light (the
// captured environment and the cone lights, one radiance function of direction) at the camera
// ray's first rough hit is one sample chosen from many, its weight that of all of them.
//
// - Candidates: PV_RESAMPLING_LIGHT_CANDIDATES drawn from the lights (environment texels, cone
//   directions) and one from the BSDF, combined with the balance heuristic over both strategies,
//   so a glossy lobe finds the light a light sample misses. The target p̂ is the unshadowed
//   contribution's luminance: no ray is traced for a candidate.
// - Reuse: the last preview frame's reservoir of this traced pixel and PV_RESAMPLING_NEIGHBOURS
//   around it (the other half of PV_BINDING_RESERVOIRS: no pass waits on another), each where its
//   surface lies in this one's plane with a normal that agrees, its count capped at
//   PV_RESAMPLING_M_CAP so that the history keeps moving. For a moving camera this is reuse from
//   the neighbourhood in the world, without a reprojection: a kept reservoir is a direction,
//   valid anywhere on the plane it was found on.
// - The biased combination (1/M, Bitterli et al.'s Algorithm 4 without visibility in the
//   target): a neighbour on a curved surface whose samples fall below this horizon counts in M
//   but never weighs, which darkens a curved surface a little; the normal and plane tests keep
//   that small (a 48×36 ball: −3 %, tests/integrator/distant_light_resampling_test.cpp). The
//   unbiased normalisation (Algorithm 6's Z, the counts of the reservoirs that could have chosen
//   the sample) was tried and dropped: a sample that few sources support gets a large weight,
//   and reuse spreads it over its neighbours frame after frame (the demo's preview held for 64
//   frames went from 0.18 to 0.38 √relMSE).
// - The differential: both solutions shade the one sample chosen, the real one where no real
//   geometry occludes it and the mixed one where no geometry at all does (addLightSample), so
//   the target and its candidates are the same for L_om and L_or and their noise cancels; with no
//   virtual object the two stay equal bit for bit.
//
// Included by trace_paths.comp after addLightSample.

layout(constant_id = PV_SPEC_RESAMPLING) const bool kResampling = false;
layout(binding = PV_BINDING_RESERVOIRS, scalar) buffer Reservoirs { vec4 reservoirs[]; };

#define PV_RESAMPLING_LIGHT_CANDIDATES 4u
#define PV_RESAMPLING_BSDF_CANDIDATES 1u
#define PV_RESAMPLING_NEIGHBOURS 3u
#define PV_RESAMPLING_RADIUS 6.0       // traced pixels around this one
// Candidates' count a reused reservoir stands for at most: a longer chain of a still camera's
// frames drifted bright on the demo under 1/M (held 64: cap 20 0.320, 4 0.131, 1 0.122; the unit
// scenes' gains the same at 4 as at 20).
#define PV_RESAMPLING_M_CAP 4.0
#define PV_RESAMPLING_MIN_COS 0.97     // normals of a reused reservoir's surface and this one's
#define PV_RESAMPLING_PLANE_SHARE 0.05  // its distance from this plane, a share of the hit's

// One reservoir as it streams: the direction kept, the sum of the weights streamed in, the
// candidates they stand for, and the chosen direction's target and contributions (f·|cos|·L,
// of the real and of the virtual lights).
struct Reservoir {
    vec3 direction;
    float weightSum;
    float count;
    float target;
    vec3 real;
    vec3 virt;
};

uint gResamplingRandom;
float resamplingRandom() {
    gResamplingRandom = pcgHash(gResamplingRandom);
    return float(gResamplingRandom >> 8u) * 5.9604644775390625e-8;
}

// Some distant light lights the scene.
bool hasDistantLight() {
    return (kHasEnv && params.envWidth > 0u) ||
           (kHasConeLights && params.lightCount > params.coneLightFirst);
}

// The share of light candidates drawn from the environment (the rest from the cone lights).
float environmentShare() {
    bool env = kHasEnv && params.envWidth > 0u;
    bool cones = kHasConeLights && params.lightCount > params.coneLightFirst;
    return env ? (cones ? 0.5 : 1.0) : 0.0;
}

// The distant light toward world direction `w`: its radiance from real lights (the environment,
// real cone lights) and from virtual ones; returns the light strategy's solid-angle pdf of `w`.
float distantLight(vec3 w, out vec3 real, out vec3 virt) {
    real = vec3(0.0);
    virt = vec3(0.0);
    float share = environmentShare();
    float pdf = 0.0;
    if (kHasEnv && params.envWidth > 0u) {
        vec2 rotation = vec2(params.envRotationCos, params.envRotationSin);
        real = params.envScale * envRadiance(w, params.envWidth, params.envHeight, rotation);
        pdf = share * envPdf(w, params.envWidth, params.envHeight, rotation);
    }
    if (kHasConeLights) {
        float cones = float(params.lightCount - params.coneLightFirst);
        for (uint i = params.coneLightFirst; i < params.lightCount; ++i) {
            PV_COUNT_LOOP_ITERATION();
            GpuLight light = lightAt(i);
            if (dot(w, -light.direction) < light.cosOuterCone) continue;
            if ((light.type & PV_LIGHT_REAL) != 0u) real += light.intensity;
            else virt += light.intensity;
            pdf += (1.0 - share) * uniformConePdf(light.cosInnerCone) / cones;
        }
    }
    return pdf;
}

// A direction drawn by the light strategy (distantLight's pdf).
vec3 sampleDistantLight(vec2 u, float uPick) {
    float share = environmentShare();
    if (uPick < share) {
        float pdf;
        uint texel;
        return envSampleTexel(u, params.envWidth, params.envHeight,
                              vec2(params.envRotationCos, params.envRotationSin), pdf, texel);
    }
    uint cones = params.lightCount - params.coneLightFirst;
    uint i = min(uint((uPick - share) / (1.0 - share) * float(cones)), cones - 1u);
    GpuLight light = lightAt(params.coneLightFirst + i);
    Frame cone;
    cone.n = -light.direction;
    buildBasis(cone.n, cone.t, cone.b);
    return toWorld(cone, sampleUniformCone(u, light.cosInnerCone));
}

// Direction `w`'s target p̂ at the vertex (the luminance of f·|cos|·L, unshadowed), with its
// contributions and the light and BSDF strategies' pdfs.
float resamplingTarget(Surface s, BsdfParams bp, Frame frame, vec3 wo, vec3 w, out vec3 real,
                       out vec3 virt, out float lightPdf, out float bsdfPdf) {
    lightPdf = distantLight(w, real, virt);
    bsdfPdf = 0.0;
    vec3 wLocal = toLocal(frame, w);
    if (!consistentSide(s, w, wLocal)) return 0.0;
    vec3 fCos = evaluateBsdf(bp, wo, wLocal, bsdfPdf) * abs(wLocal.z);
    real *= fCos;
    virt *= fCos;
    return luminance(real + virt);
}

// Streams direction `w` with weight `weight`, standing for `count` candidates, into `r`.
void streamInto(inout Reservoir r, vec3 w, float weight, float count, float target, vec3 real,
                vec3 virt) {
    r.weightSum += weight;
    r.count += count;
    if (weight > 0.0 && resamplingRandom() * r.weightSum < weight) {
        r.direction = w;
        r.target = target;
        r.real = real;
        r.virt = virt;
    }
}

// Streams one candidate of each strategy's draws: weight p̂ / Σ N·pdf (the balance heuristic).
void streamCandidate(inout Reservoir r, Surface s, BsdfParams bp, Frame frame, vec3 wo, vec3 w) {
    vec3 real;
    vec3 virt;
    float lightPdf;
    float bsdfPdf;
    float target = resamplingTarget(s, bp, frame, wo, w, real, virt, lightPdf, bsdfPdf);
    float density = float(PV_RESAMPLING_LIGHT_CANDIDATES) * lightPdf +
                    float(PV_RESAMPLING_BSDF_CANDIDATES) * bsdfPdf;
    streamInto(r, w, density > 0.0 ? target / density : 0.0, 0.0, target, real, virt);
}

// The first vertex's own candidates, as one reservoir of count 1.
Reservoir initialReservoir(Surface s, BsdfParams bp, Frame frame, vec3 wo) {
    Reservoir r;
    r.direction = vec3(0.0, 0.0, 1.0);
    r.weightSum = 0.0;
    r.count = 0.0;
    r.target = 0.0;
    r.real = vec3(0.0);
    r.virt = vec3(0.0);
    for (uint i = 0u; i < PV_RESAMPLING_LIGHT_CANDIDATES; ++i) {
        PV_COUNT_LOOP_ITERATION();
        vec2 u = vec2(resamplingRandom(), resamplingRandom());
        streamCandidate(r, s, bp, frame, wo, sampleDistantLight(u, resamplingRandom()));
    }
    BsdfSample bs;
    vec4 u = vec4(resamplingRandom(), resamplingRandom(), resamplingRandom(), 0.0);
    if (sampleBsdf(bp, wo, u, bs) && !bs.isDelta)
        streamCandidate(r, s, bp, frame, wo, toWorld(frame, bs.wi));
    r.count = 1.0;
    return r;
}

uint reservoirAt(uint which, uint pixelIndex) {
    return (which * params.width * params.height + pixelIndex) * PV_RESERVOIR_VEC4S;
}

// Streams the last frame's reservoir of traced pixel `pixel` into `r` where its surface is this
// one's (the plane and normal tests); its weight is p̂ here × its W × its capped count.
void reuseReservoir(inout Reservoir r, ivec2 pixel, Surface s, BsdfParams bp, Frame frame,
                    vec3 wo, float hitDistance) {
    if (any(lessThan(pixel, ivec2(0))) || pixel.x >= int(params.width) ||
        pixel.y >= int(params.height))
        return;
    uint at = reservoirAt(1u - params.reservoirHalf, uint(pixel.y) * params.width + uint(pixel.x));
    vec4 where = reservoirs[at + 1u];
    vec4 normal = reservoirs[at + 2u];
    if (!(where.w > 0.0) || dot(normal.xyz, frame.n) < PV_RESAMPLING_MIN_COS ||
        abs(dot(frame.n, where.xyz - s.position)) > PV_RESAMPLING_PLANE_SHARE * hitDistance)
        return;
    vec4 kept = reservoirs[at];
    vec3 real;
    vec3 virt;
    float lightPdf;
    float bsdfPdf;
    float target = resamplingTarget(s, bp, frame, wo, kept.xyz, real, virt, lightPdf, bsdfPdf);
    float count = min(where.w, PV_RESAMPLING_M_CAP);
    streamInto(r, kept.xyz, target * kept.w * count, count, target, real, virt);
}

// The distant light at the camera ray's first rough vertex `s` (`hitDistance` from the camera) of
// traced pixel `pixel`, resampled: added (without the path throughput) to the solutions that see
// it, and the pixel's reservoir stored for the next frame.
void resampleDistantLight(Surface s, BsdfParams bp, Frame frame, vec3 wo, uint mode, uvec2 pixel,
                          float hitDistance, SampleKey key, inout vec3 toMixed,
                          inout vec3 toReal) {
    gResamplingRandom = pcgHash(key.streamSeed ^ 0x7e5712u);
    Reservoir r = initialReservoir(s, bp, frame, wo);
    if (params.reservoirHistory != 0u) {
        reuseReservoir(r, ivec2(pixel), s, bp, frame, wo, hitDistance);
        for (uint i = 0u; i < PV_RESAMPLING_NEIGHBOURS; ++i) {
            PV_COUNT_LOOP_ITERATION();
            vec2 offset = (vec2(resamplingRandom(), resamplingRandom()) * 2.0 - 1.0) *
                          PV_RESAMPLING_RADIUS;
            reuseReservoir(r, ivec2(vec2(pixel) + offset + 0.5), s, bp, frame, wo, hitDistance);
        }
    }
    // W = Σw / (M·p̂(y)): the chosen direction's weight.
    float weight = r.target > 0.0 ? r.weightSum / (r.count * r.target) : 0.0;
    uint at = reservoirAt(params.reservoirHalf, pixel.y * params.width + pixel.x);
    reservoirs[at] = vec4(r.direction, weight);
    reservoirs[at + 1u] = vec4(s.position, r.count);
    reservoirs[at + 2u] = vec4(frame.n, 0.0);
    if (!(weight > 0.0)) return;
    Ray ray = directionRay(s.position, s.geometricNormal, r.direction, PV_FLOAT_MAX);
    if (maxComponent(r.real) > 0.0) addLightSample(r.real * weight, true, ray, mode, toMixed, toReal);
    if (maxComponent(r.virt) > 0.0)
        addLightSample(r.virt * weight, false, ray, mode, toMixed, toReal);
}

// A traced pixel whose sample has no resampled vertex leaves nothing for the next frame to reuse.
void clearReservoir(uvec2 pixel) {
    reservoirs[reservoirAt(params.reservoirHalf, pixel.y * params.width + pixel.x) + 1u].w = 0.0;
}
