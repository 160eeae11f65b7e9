// trace_paths: unidirectional path tracing with next-event estimation and multiple importance
// sampling (environment map, emissive triangles, punctual lights), Russian roulette, thin-lens
// camera and jittered box-filter supersampling. Each invocation traces samplesPerDispatch paths
// for one pixel and adds their sum to the pixel's compensated (Kahan) running sum.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

#include "scene_access.glsl"

layout(local_size_x = PV_WORKGROUP_SIZE_X, local_size_y = PV_WORKGROUP_SIZE_Y) in;

layout(binding = PV_BINDING_ACCUM_SUM, scalar) buffer AccumSum { vec4 accumSum[]; };
layout(binding = PV_BINDING_ACCUM_COMPENSATION, scalar) buffer AccumCompensation {
    vec4 accumCompensation[];
};
layout(binding = PV_BINDING_STATS, scalar) buffer Stats { RenderStats stats; };
// The denoiser's guides (shared/denoise.h), written only where kDenoiseGuides.
layout(constant_id = PV_SPEC_DENOISE_GUIDES) const bool kDenoiseGuides = false;
layout(binding = PV_BINDING_GUIDES, scalar) buffer Guides { vec4 guides[]; };
// This iteration's photon map (photon_grid.comp): records sorted by bucket, two texels each, and
// each bucket's [begin, end) as two words, two buckets a texel (one fetch per bucket).
layout(binding = PV_BINDING_PHOTON_SORTED) uniform usamplerBuffer photonTexels;
layout(binding = PV_BINDING_PHOTON_CELLS) uniform usamplerBuffer photonCellTexels;
// The photons the camera sees directly, splatted by this iteration's photon pass (scene_types.h).
layout(binding = PV_BINDING_PHOTON_SPLATS, scalar) readonly buffer Splats { uint splats[]; };
layout(binding = PV_BINDING_HELD_SAMPLES, scalar) buffer HeldSamples { vec4 heldSamples[]; };

#include "gpu/shaders/shared/photon_records.h"
#include "gpu/shaders/shared/denoise.h"
#include "gpu/shaders/shared/held_reprojection_params.h"

// What the camera ray's first hit shows the denoiser (beginPath and tracePaths set them where
// kDenoiseGuides).
vec3 gGuideAlbedo;
vec3 gGuideNormal;
float gGuideDepthM;
// Whether the sample's camera ray first hit phantom (real) geometry: the real slot's w, which the
// plate-consistency meter (render/plate_consistency.h) needs to compare L_or with the plate only
// over real surfaces seen, never the environment behind them or a virtual object.
bool gFirstHitReal;
// How far the camera ray's first hit in the mixed scene lies (metres; PV_GUIDE_MISS_DEPTH_M on a
// miss): the held view's samples carry it, so that they can follow a moving camera
// (render/held_reprojection.h).
float gFirstHitDistanceM;
// ... and its geometric normal, facing the camera (0 on a miss): the held view's samples keep the
// last one, which tells a moved history whether the new camera sees the same surface there.
vec3 gFirstHitNormal;
// The traced pixel this invocation traces.
uvec2 gPixel;

// Four random numbers of dimension set `set` (shared/sampler.h's table) for sample `key`.
vec4 draw(SampleKey key, uint set) { return sampleSet(kSampler, key, set); }

// Adds a light sample's contribution `c` along shadow ray `ray` to the solutions that see it:
// the real shadow ray first (real geometry), and only if that is clear the mixed shadow ray
// (virtual geometry). A virtual light exists only in the mixed scene.
void addLightSample(vec3 c, bool lightIsReal, Ray ray, uint mode, inout vec3 toMixed,
                    inout vec3 toReal) {
    // A virtual light has nothing to give the real solution: no ray (nor a dropped sample).
    if (mode == MODE_REAL && !lightIsReal) return;
    uint blocker = occluder(ray, mode);
    if (mode == MODE_REAL) {
        if (blocker == OCCLUDER_NONE) toReal += c;
        return;
    }
    if (blocker == OCCLUDER_REAL) return;
    if (mode == MODE_SHARED && lightIsReal) toReal += c;
    if (blocker == OCCLUDER_NONE) toMixed += c;
}

#include "distant_light_resampling.glsl"

// Solid-angle pdf with which emissive-triangle sampling picks the point `lightSurface` seen from
// `from`: the triangle's power share times shared/triangle_light.h's density, the very function
// the sampler uses, so MIS weighs a BSDF-sampled hit with the light strategy's own density.
float emissiveLightPdf(uint triangle, vec3 from, Surface lightSurface) {
    return wordAsFloat(triangleLightPdfWords, triangle) *
           triangleLightDirectionPdf(from, PV_TRIANGLE_VERTEX(triangle, 0u),
                                     PV_TRIANGLE_VERTEX(triangle, 1u),
                                     PV_TRIANGLE_VERTEX(triangle, 2u), lightSurface.position,
                                     kLightSolidAngle);
}

// Solid-angle pdf with which light sampling picks direction `dir` from cone light `light` (0
// outside the cone): uniform choice of the light, uniform direction in its cone.
float coneLightPdf(GpuLight light, vec3 dir) {
    if (dot(dir, -light.direction) < light.cosOuterCone) return 0.0;
    return uniformConePdf(light.cosInnerCone) / float(params.lightCount);
}

// Next-event estimation at a surface: one environment sample, one emissive-triangle sample and
// one light of the lights buffer (punctual or cone), each added (without the path throughput) to
// the solutions that see it. `photonsCarry`: the path is on a caustic chain the photon map
// carries (photonMapCarries), so the photon lights' light is left out here. `distantResampled`:
// the environment and the cone lights are resampled at this vertex (resampleDistantLight).
void sampleDirectLight(Surface s, BsdfParams bp, Frame frame, vec3 wo, uint mode, SampleKey key,
                       uint depth, bool photonsCarry, bool distantResampled, inout vec3 toMixed,
                       inout vec3 toReal) {
    if (kHasEnv && params.envWidth > 0u && !(photonsCarry && params.photonEnvironment != 0u) &&
        !distantResampled) {
        float envPdfValue;
        uint texel;
        vec2 u = draw(key, vertexSet(depth, PV_SET_VERTEX_ENV)).xy;
        vec3 wi = envSampleTexel(u, params.envWidth, params.envHeight,
                                 vec2(params.envRotationCos, params.envRotationSin), envPdfValue, texel);
        vec3 wiLocal = toLocal(frame, wi);
        if (envPdfValue > 0.0 && consistentSide(s, wi, wiLocal)) {
            float bsdfPdf;
            vec3 f = evaluateBsdf(bp, wo, wiLocal, bsdfPdf);
            if (maxComponent(f) > 0.0) {
                // The sampled texel's radiance (see envSampleTexel). The captured environment
                // is real: it lights both solutions.
                vec3 le = params.envScale * envRadianceAt(texel);
                vec3 c = f * abs(wiLocal.z) * le * powerHeuristic(envPdfValue, bsdfPdf) / envPdfValue;
                addLightSample(c, true, directionRay(s.position, s.geometricNormal, wi, PV_FLOAT_MAX),
                               mode, toMixed, toReal);
            }
        }
    }
    if (photonsCarry) return;
    if (kHasEmissive && params.emissiveTriangleCount > 0u) {
        vec4 u = draw(key, vertexSet(depth, PV_SET_VERTEX_EMISSIVE));
        float uPick = u.z;
        vec2 uPoint = u.xy;
        EmissiveTriangle et = emissiveTriangleAt(pickEmissiveTriangle(uPick));
        uvec4 tri = triangleAt(et.triangle);
        vec3 p0 = PV_TRIANGLE_VERTEX(et.triangle, 0u);
        vec3 p1 = PV_TRIANGLE_VERTEX(et.triangle, 1u);
        vec3 p2 = PV_TRIANGLE_VERTEX(et.triangle, 2u);
        // Density of the point's direction given the triangle (solid angle or area sampling).
        float pointPdf;
        vec2 b = sampleTriangleLight(s.position, p0, p1, p2, uPoint, kLightSolidAngle, pointPdf);
        vec3 lightPoint = (1.0 - b.x - b.y) * p0 + b.x * p1 + b.y * p2;
        vec3 ng = normalize(cross(p1 - p0, p2 - p0));
        vec3 d = lightPoint - s.position;
        float dist2 = dot(d, d);
        vec3 wi = d * inversesqrt(dist2);
        float cosLight = dot(-wi, ng);
        GpuMaterial lm = materialAt(tri.w);
        bool facing = cosLight > 0.0 || (cosLight < 0.0 && emitsToward(lm, false));
        vec3 wiLocal = toLocal(frame, wi);
        if (facing && dist2 > 0.0 && consistentSide(s, wi, wiLocal)) {
            float lightPdf = et.pdf * pointPdf;
            float bsdfPdf;
            vec3 f = evaluateBsdf(bp, wo, wiLocal, bsdfPdf);
            if (maxComponent(f) > 0.0 && lightPdf > 0.0) {
                vec2 uv = (1.0 - b.x - b.y) * uvAt(tri.x) + b.x * uvAt(tri.y) + b.y * uvAt(tri.z);
                vec3 c = f * abs(wiLocal.z) * emittedRadiance(lm, uv) *
                         powerHeuristic(lightPdf, bsdfPdf) / lightPdf;
                addLightSample(c, et.triangle < params.realTriangleCount,
                               segmentRay(s.position, s.geometricNormal, lightPoint, ng), mode,
                               toMixed, toReal);
            }
        }
    }
    if (kHasPunctual && params.lightCount > 0u) {
        vec4 u = draw(key, vertexSet(depth, PV_SET_VERTEX_LIGHT));
        uint index = min(uint(u.z * float(params.lightCount)), params.lightCount - 1u);
        GpuLight light = lightAt(index);
        uint type = light.type & PV_LIGHT_TYPE_MASK;
        vec3 wi;
        vec3 li;
        float dist = PV_FLOAT_MAX;
        // Solid-angle pdf of a cone light's sample (with the choice of the light); 0 for the
        // delta lights, which BSDF sampling cannot hit.
        float lightPdf = 0.0;
        if (kHasConeLights && type == PV_LIGHT_CONE && distantResampled) {
            return;
        } else if (kHasConeLights && type == PV_LIGHT_CONE) {
            Frame cone;
            cone.n = -light.direction;
            buildBasis(cone.n, cone.t, cone.b);
            wi = toWorld(cone, sampleUniformCone(u.xy, light.cosInnerCone));
            li = light.intensity;  // radiance
            lightPdf = uniformConePdf(light.cosInnerCone) / float(params.lightCount);
        } else if (type == PV_LIGHT_DIRECTIONAL) {
            wi = -light.direction;
            li = light.intensity;  // illuminance (lux) from a delta direction
        } else {
            vec3 d = light.position - s.position;
            float dist2 = dot(d, d);
            wi = d * inversesqrt(dist2);
            li = light.intensity / dist2;  // inverse-square law
            if (type == PV_LIGHT_SPOT) {
                // glTF KHR_lights_punctual's recommended smooth cone falloff.
                float cd = dot(light.direction, -wi);
                float scale = 1.0 / max(0.001, light.cosInnerCone - light.cosOuterCone);
                float a = clamp((cd - light.cosOuterCone) * scale, 0.0, 1.0);
                li *= a * a;
            }
            dist = sqrt(dist2);
        }
        vec3 wiLocal = toLocal(frame, wi);
        if (maxComponent(li) > 0.0 && consistentSide(s, wi, wiLocal)) {
            float bsdfPdf;
            vec3 f = evaluateBsdf(bp, wo, wiLocal, bsdfPdf);
            if (maxComponent(f) > 0.0) {
                Ray r = directionRay(s.position, s.geometricNormal, wi, PV_FLOAT_MAX);
                bool distant = type == PV_LIGHT_DIRECTIONAL || type == PV_LIGHT_CONE;
                if (!distant) r.tMax = length(light.position - r.origin);
                vec3 c = lightPdf > 0.0
                             ? f * abs(wiLocal.z) * li * powerHeuristic(lightPdf, bsdfPdf) / lightPdf
                             : f * abs(wiLocal.z) * li * float(params.lightCount);
                addLightSample(c, (light.type & PV_LIGHT_REAL) != 0u, r, mode, toMixed, toReal);
            }
        }
    }
}

// The sample's position in its traced pixel, in [0, 1)² (cameraRay's, and addHeldSample's to
// find its output pixel): the sampler's jitter, or, in a preview frame with a held view, the
// phase schedule's cell with that jitter inside it (FrameParams::heldPhaseCells).
vec2 gCameraJitter;

vec2 cameraJitter(uint pixelIndex, uint sampleIndex, SampleKey key) {
    vec2 u = draw(key, PV_SET_CAMERA_JITTER).xy;
    if (params.heldPhaseCells == 0u) return u;
    return heldPhaseJitter(params.heldPhase + sampleIndex,
                           pcgHash(pixelIndex ^ pcgHash(params.heldPhaseSeed)),
                           params.heldPhaseCells, u);
}

Ray cameraRay(uvec2 pixel, vec2 jitter, SampleKey key) {
    vec2 ndc = vec2((float(pixel.x) + jitter.x) / float(params.width) * 2.0 - 1.0,
                    1.0 - (float(pixel.y) + jitter.y) / float(params.height) * 2.0);
    vec3 dir = vec3(ndc * params.tanHalfFov, -1.0);
    if (kHasLensGrid) {
        // The calibrated lens: bilinear in the grid of pixel-corner rays (OpenCV's frame has y
        // down and z forward; previs's camera looks along −Z with +Y up).
        vec2 p = vec2(float(pixel.x) + jitter.x, float(pixel.y) + jitter.y);
        uvec2 c = min(uvec2(p), uvec2(params.width - 1u, params.height - 1u));
        vec2 f = p - vec2(c);
        uint row = params.width + 1u;
        uint i00 = c.y * row + c.x;
        vec2 top = mix(lensGridAt(i00), lensGridAt(i00 + 1u), f.x);
        vec2 bottom = mix(lensGridAt(i00 + row), lensGridAt(i00 + row + 1u), f.x);
        vec2 n = mix(top, bottom, f.y);
        dir = vec3(n.x, -n.y, -1.0);
    }
    vec3 origin = vec3(0.0);
    if (kHasThinLens && params.apertureRadiusM > 0.0) {
        // Thin lens: the lens sits at the camera position, perpendicular to the optical axis;
        // all rays through a pixel meet on the focal plane z = -focusDistance.
        vec3 focus = dir * params.focusDistanceM;
        vec2 u = draw(key, PV_SET_CAMERA_LENS).xy;
        origin = vec3(params.apertureRadiusM * sampleUniformDiskConcentric(u), 0.0);
        dir = focus - origin;
    }
    Ray ray;
    ray.origin = (params.worldFromCamera * vec4(origin, 1.0)).xyz;
    ray.direction = normalize(mat3(params.worldFromCamera) * dir);
    ray.tMin = 0.0;
    ray.tMax = PV_FLOAT_MAX;
    return ray;
}

// The gather's sums are in 32.32 fixed point (FixedRgb, scene_access.glsl): a density estimate
// does not depend on the order of a bucket's records, and two solutions that gathered the same
// photons get the same bits.
void fixedAdd(inout FixedRgb sum, vec3 v) {
    FixedRgb x = fixedFromValue(v);
    uvec3 carry;
    sum.fraction = uaddCarry(sum.fraction, x.fraction, carry);
    sum.whole += x.whole + carry;
}

// Sum `sum` (PV_SPLAT_*) of the photons splatted onto pixel `pixelIndex` this iteration.
vec3 splattedLight(uint sum, uint pixelIndex) {
    uint at = splatWord(sum, pixelIndex);
    FixedRgb v;
    v.fraction = uvec3(splats[at], splats[at + 2u], splats[at + 4u]);
    v.whole = uvec3(splats[at + 1u], splats[at + 3u], splats[at + 5u]);
    return fixedValue(v);
}

// One pass of gatherPhotons over the records in the 2×2×2 cells from `first` (edge 2r, r =
// params.photonRadius) that lie within rq ≤ r of s: adds Σ f(wo, wi_p)·Φ_p·K(d_p) (K at
// radius rq; without glossy materials Σ Φ_p·K(d_p), gatherPhotons applying the constant f) to
// the sums and returns how many records it took (weighted like them where a bucket is
// subsampled). Level-1 records only if `level1`; scatterings must fit in maxBounces.
float gatherWithin(Surface s, BsdfParams bp, Frame frame, vec3 wo, uint maxBounces, float uWindow,
                   bool level1, ivec3 first, float rq, inout FixedRgb sumMixed,
                   inout FixedRgb sumReal) {
    float cellSize = photonCellSize(params.photonRadius);
    float rq2 = rq * rq;
    float norm = 1.0 / (PV_PI * rq2);
    float taken = 0.0;
    // One loop over the records of all the cells, one record per trip, the cell moved on within
    // the trip: on llvmpipe a loop's body runs at least once (masked) whether or not a lane has
    // work, so a record loop per cell would run the record's code (the BSDF) once per cell at
    // the least, and lanes would wait for each other cell by cell instead of once. Loops test
    // their exit at the end (see tracePaths).
    ivec3 place = ivec3(0);
    uint cellsLeft = uint(PV_PHOTON_GATHER_SPAN * PV_PHOTON_GATHER_SPAN * PV_PHOTON_GATHER_SPAN);
    uint k = 0u;
    uint examined = 0u;
    uint n = 0u;
    uint start = 0u;
    uint rangeStart = 0u;
    float share = 0.0;
    for (;;) {
        PV_COUNT_LOOP_ITERATION();
        // On to the next cell that holds records to examine, when this one is done.
        for (; k >= examined && cellsLeft > 0u;) {
            PV_COUNT_LOOP_ITERATION();
            ivec3 cell = first + place;
            // A cell the sphere misses holds nothing to take (most of them once rq < r).
            vec3 lo = vec3(cell) * cellSize;
            vec3 outside = max(lo - s.position, vec3(0.0)) +
                           max(s.position - lo - cellSize, vec3(0.0));
            uvec2 range = uvec2(0u);
            if (dot(outside, outside) < rq2) {
                // The 8 cells' buckets differ (photonBucket): each record is summed once.
                uint bucket = photonBucket(cell);
                uvec4 pair = texelFetch(photonCellTexels, int(bucket >> 1u));
                range = (bucket & 1u) != 0u ? pair.zw : pair.xy;
            }
            n = range.y - range.x;
            examined = min(n, params.photonGatherCap);
            start = examined < n ? min(uint(uWindow * float(n)), n - 1u) : 0u;
            share = float(n) / float(max(examined, 1u));
            rangeStart = range.x;
            k = 0u;
            // The next of the 8 places, x fastest (no division: a per-lane loop on llvmpipe).
            place.x += 1;
            if (place.x == PV_PHOTON_GATHER_SPAN) {
                place.x = 0;
                place.y += 1;
                if (place.y == PV_PHOTON_GATHER_SPAN) {
                    place.y = 0;
                    place.z += 1;
                }
            }
            cellsLeft -= 1u;
        }
        if (k < examined) {
            // The window wraps: (start + k) mod n without a division (a per-lane scalar loop on
            // llvmpipe).
            uint offset = start + k;
            uint at = rangeStart + (offset >= n ? offset - n : offset);
            uvec4 t0 = texelFetch(photonTexels, int(2u * at));
            vec3 d = uintBitsToFloat(t0.xyz) - s.position;
            // Level 1 only where the path may gather it (shared/photon_records.h's rule).
            bool levelGathered = level1 || (t0.w & PV_PHOTON_LEVEL_2) != 0u;
            float d2 = dot(d, d);
            if (d2 < rq2 && (t0.w >> PV_PHOTON_BOUNCES_SHIFT) <= maxBounces && levelGathered) {
                taken += share;
                uvec4 t1 = texelFetch(photonTexels, int(2u * at + 1u));
                vec3 wi = octahedralDecode(unpackSnorm2x16(t1.w));
                vec3 wiLocal = toLocal(frame, wi);
                if (consistentSide(s, wi, wiLocal)) {
                    float kernel = 2.0 * (1.0 - d2 / rq2);  // × norm: Epanechnikov
                    vec3 f = uintBitsToFloat(t1.xyz) * (norm * share * kernel);
                    // Without glossy materials the vertex is Lambertian: f is the same for
                    // every photon on its side (above the cosine limit of bsdfEvaluate).
                    if (kHasGlossy) {
                        float pdf;
                        f *= evaluateBsdf(bp, wo, wiLocal, pdf);
                    } else if (wiLocal.z < PV_MIN_COSINE) {
                        f = vec3(0.0);
                    }
                    if ((t0.w & PV_PHOTON_IN_MIXED) != 0u) fixedAdd(sumMixed, f);
                    if ((t0.w & PV_PHOTON_IN_REAL) != 0u) fixedAdd(sumReal, f);
                }
            }
        }
        k += 1u;
        if (k >= examined && cellsLeft == 0u) break;
    }
    return taken;
}

// The photon map's estimate of the caustic radiance leaving gather vertex `s` toward wo, for the
// mixed and the real solution: Σ f(wo, wi_p)·Φ_p·K(d_p) over the photons within the radius
// (level-2 ones only unless `level1`) whose scatterings fit in the depth left (depth: scatterings
// before this vertex), K the Epanechnikov kernel 2(1 − d²/r²)/(π r²) (docs/caustics.md says why
// not a uniform disc). Where the iteration's radius r holds M > k = photonGatherNeighbours
// records, the estimate is taken again at r·√(k/M), which holds about k: the blur shrinks where
// photons are dense — at a focus, where it is most of the error — and, given M, the records
// within r are spread evenly over its disc wherever the density is locally even, so the smaller
// disc's estimate has the same expectation there (docs/caustics.md, "The radius where photons are
// dense"). Both solutions use the same radius, so where they hold the same photons their sums
// stay equal. A bucket holding more than photonGatherCap records is subsampled — a window of that
// many at a random start, weighted by the ratio — which keeps the estimate unbiased and a lane's
// loop count bounded (llvmpipe's loop budget, shared/prelude.h).
void gatherPhotons(Surface s, BsdfParams bp, Frame frame, vec3 wo, uint depth, float uWindow,
                   bool level1, out vec3 toMixed, out vec3 toReal) {
    float r = params.photonRadius;
    uint maxBounces = params.maxDepth - depth - 1u;
    // The 2×2×2 cells (edge 2r) that the sphere of radius r around the point overlaps.
    ivec3 first = photonCell(s.position - vec3(r), photonCellSize(r));
    FixedRgb sumMixed;
    FixedRgb sumReal;
    float k = float(params.photonGatherNeighbours);
    // The second pass is the loop's second trip, not a second copy of the gather: on llvmpipe
    // every copy would run (masked) at every vertex, needed or not.
    float rq = r;
    for (bool again = false;;) {
        PV_COUNT_LOOP_ITERATION();
        sumMixed = FixedRgb(uvec3(0u), uvec3(0u));
        sumReal = FixedRgb(uvec3(0u), uvec3(0u));
        float taken = gatherWithin(s, bp, frame, wo, maxBounces, uWindow, level1, first, rq,
                                   sumMixed, sumReal);
        if (again || !(k > 0.0 && taken > k)) break;
        again = true;
        rq = r * sqrt(k / taken);
    }
    toMixed = fixedValue(sumMixed);
    toReal = fixedValue(sumReal);
    if (!kHasGlossy) {
        // The Lambertian f, once: evaluateBsdf's (the direction only needs to face the normal).
        float pdf;
        vec3 lambert = evaluateBsdf(bp, wo, vec3(0.0, 0.0, 1.0), pdf);
        toMixed *= lambert;
        toReal *= lambert;
    }
}

// Where a path stands with respect to the photon map's paths (shared/photon_records.h's rule).
#define CAUSTIC_NONE 0u            // the path tracer's own: from the camera, or after a delta lobe
#define CAUSTIC_LEFT_GATHER 1u     // the last gather vertex scattered through a non-delta lobe
#define CAUSTIC_SPECULAR_CHAIN 2u  // ... then only vertices that carry caustics (causticBounces)

// The sample's indirect light so far (part of lm and lr): all but the light the camera sees
// directly (an emitter or the environment, also in mirrors and through glass) and the first rough
// surface's direct light (its light samples and the emitters its scattered ray meets next). The
// preview's clamps scale this part alone (addSample): the fireflies are there — a lamp found
// through a rare path, a caustic's few photons — while the direct light is sampled well and is
// the picture's brightest detail (a lamp in the chrome ball, a sunlit floor), which a clamp of
// the whole sample would dim.
vec3 gIndirectMixed;
vec3 gIndirectReal;

// Adds radiance to the solutions the path carries in `mode`, in the same order for both, so that
// where the two solutions followed the same path L_om − L_or is exactly zero; `indirect`: also to
// the indirect part.
void addRadiance(uint mode, vec3 l, bool indirect, inout vec3 lm, inout vec3 lr) {
    if (mode != MODE_REAL) lm += l;
    if (mode != MODE_MIXED) lr += l;
    if (!indirect) return;
    if (mode != MODE_REAL) gIndirectMixed += l;
    if (mode != MODE_MIXED) gIndirectReal += l;
}

// The same for light that differs between the solutions (`toMixed`, `toReal`: a vertex's sampled
// or gathered light).
void addLight(uint mode, vec3 toMixed, vec3 toReal, bool indirect, inout vec3 lm, inout vec3 lr) {
    if (mode != MODE_REAL) lm += toMixed;
    if (mode != MODE_MIXED) lr += toReal;
    if (!indirect) return;
    if (mode != MODE_REAL) gIndirectMixed += toMixed;
    if (mode != MODE_MIXED) gIndirectReal += toReal;
}

struct PathState {
    Ray ray;
    vec3 throughput;
    float prevPdf;
    bool prevDelta;     // the last scattering was a delta lobe (or the camera): no MIS
    vec3 prevPosition;
    // Russian roulette decides on throughput·rouletteScale: the product of the η² factors of
    // the refractions so far, so radiance compressed inside glass does not get paths killed
    // (pbrt), over the share of a split's branch, so a split changes no path's survival.
    float rouletteScale;
    uint depth;         // scattering events so far
    uint causticState;  // CAUSTIC_*: which emitters the photon map already carries
    uint causticBounces;
    // The next gather vertex gathers level-1 photons: none before it, or the last one scattered
    // through a delta lobe (shared/photon_records.h).
    bool gatherLevel1;
    // Vertices left through a lobe that is neither a delta nor one that carries caustics
    // (bsdfCarriesCaustics), and whether the last vertex was one: light found with none is seen
    // directly (through mirrors and glass), the emitters reached straight from the first are its
    // direct light; the rest is indirect (gIndirectMixed).
    uint roughVertices;
    bool lastScatterRough;
    // The vertex the path left last resampled its distant light (resampleDistantLight), which
    // its BSDF candidate already weighs: the environment and the cone lights this ray meets are
    // counted there.
    bool distantResampled;
};

// The light the path adds at its hit (an emitter, the environment) is indirect.
bool emissionIsIndirect(PathState st) {
    return !(st.roughVertices == 0u || (st.roughVertices == 1u && st.lastScatterRough));
}
// The light a vertex samples is indirect.
bool vertexLightIsIndirect(PathState st) { return st.roughVertices > 0u; }

// An emitter of a photon light reached now is light the photon map carries: the path tracer
// leaves it out.
bool photonMapCarries(PathState st) {
    return kPhotons && st.causticState == CAUSTIC_SPECULAR_CHAIN &&
           st.causticBounces <= params.photonMaxBounces;
}

// Moves path `st` across the scattering `bs` sampled at `s`: throughput, roulette scale, the
// photon map's bookkeeping, the next ray and Russian roulette (uRoulette). `share` is a split
// branch's share (1 without a split): the throughput carries share × the sample's weight.
// False when the path ends here.
bool scatter(inout PathState st, Surface s, Frame frame, BsdfParams bp, BsdfSample bs,
             bool gatherVertex, float uRoulette, float share) {
    vec3 wi = toWorld(frame, bs.wi);
    if (!consistentSide(s, wi, bs.wi)) {
        // The adapted normal keeps every mirror direction above the surface; a smooth
        // refraction leaving at grazing angles can still point back into its facet. A delta
        // direction is moved to the nearest one on its promised side (its weight stays exact); a
        // sampled non-delta direction would break its pdf, so it ends.
        if (!bs.isDelta) return false;
        wi = nearestDirectionOnSide(wi, s.geometricNormal, bs.wi.z > 0.0 ? 1.0 : -1.0);
    }
    st.throughput *= share * bs.weight;
    st.rouletteScale /= share;
    st.distantResampled = false;
    st.lastScatterRough = !bs.isDelta && !bsdfCarriesCaustics(bp);
    if (st.lastScatterRough) st.roughVertices += 1u;
    if (bs.lobe == PV_LOBE_TRANSMISSION && !bp.thinWalled)
        st.rouletteScale *= bp.etaRel * bp.etaRel;
    if (gatherVertex) {
        st.causticState = bs.isDelta ? CAUSTIC_NONE : CAUSTIC_LEFT_GATHER;
        st.causticBounces = 0u;
        st.gatherLevel1 = bs.isDelta;
    }
    st.prevPdf = bs.pdf;
    st.prevDelta = bs.isDelta;
    st.prevPosition = s.position;
    st.ray = directionRay(s.position, s.geometricNormal * (bs.wi.z > 0.0 ? 1.0 : -1.0), wi,
                          PV_FLOAT_MAX);
    st.depth += 1u;
    if (st.depth >= params.rouletteStartDepth) {
        // Russian roulette: unbiased, keeps paths whose throughput is still large. The square
        // root (as Cycles' path_state_continuation_probability) ends paths later than the
        // throughput itself would: 5-9 % less variance per sample on the bunny and area-light
        // benchmarks at no measured cost in time (BENCHMARKS.md, "Issue 8: the fixed cost of a
        // render, and Russian roulette").
        float pContinue = min(1.0, sqrt(maxComponent(st.throughput) * st.rouletteScale));
        if (uRoulette >= pContinue) return false;
        st.throughput /= pContinue;
    }
    return true;
}

// The pixel's sums over this dispatch's samples (tracePaths adds to them, main adds them to the
// accumulation). Compensated, within the dispatch and across dispatches: the mean stays exact
// over millions of samples in 32-bit floats (the paper's running average, Eq. 3, drifts).
vec4 gSum[PV_ACCUM_COUNT];
vec4 gComp[PV_ACCUM_COUNT];
vec4 gGuideSum[PV_GUIDE_COUNT];

// Kahan-compensated sum (`precise` forbids the compiler from reassociating it away).
void kahanAdd(inout vec4 sum, inout vec4 c, vec4 x) {
    precise vec4 y = x - c;
    precise vec4 t = sum + y;
    precise vec4 newC = (t - sum) - y;
    c = newC;
    sum = t;
}

// The held view's sample (FrameParams::heldWidth): in the output pixel the sample's jitter
// (gCameraJitter) landed in. At a fraction that is not a whole one, an output pixel on a traced
// pixel's edge is written only by the traced pixel that holds its centre (the one whose owner is
// this pixel), so no two invocations add to one pixel; the other's samples there are not kept.
void addHeldSample(uvec2 pixel, vec3 composite, float mask) {
    uvec2 size = uvec2(params.heldWidth, params.heldHeight);
    vec2 scale = vec2(size) / vec2(params.width, params.height);
    vec2 p = (vec2(pixel) + gCameraJitter) * scale;
    uvec2 at = min(uvec2(p), size - 1u);
    uvec2 owner = min(uvec2((vec2(at) + 0.5) / scale), uvec2(params.width, params.height) - 1u);
    if (owner != pixel) return;
    uint i = 2u * (at.y * size.x + at.x);
    vec4 sums = heldSamples[i];
    vec4 counts = heldSamples[i + 1u];
    // Samples moved from the last camera are kept only where this one's first sample meets their
    // surface (shared/held_reprojection_params.h); the rest of its frame's samples add to them.
    if (counts.w == PV_HELD_MOVED &&
        !heldHistoryAgrees(sums, counts, gFirstHitDistanceM, gFirstHitNormal, mask)) {
        sums = vec4(0.0);
        counts = vec4(0.0);
    }
    heldSamples[i] = sums + vec4(composite, mask);
    heldSamples[i + 1u] = vec4(counts.x + 1.0, counts.y + gFirstHitDistanceM,
                               heldNormalCode(gFirstHitNormal), 0.0);
}

// Adds sample `sampleIndex`'s radiances to the pixel's sums; `nonFiniteRay`: one of its rays had
// a NaN or infinite origin or direction.
void addSample(uint sampleIndex, uint pixelIndex, vec3 lm, vec3 lr, bool firstHitVirtual,
               bool nonFiniteRay, uvec2 pixel) {
    if (nonFiniteRay || any(isnan(lm)) || any(isinf(lm)) ||
        any(isnan(lr)) || any(isinf(lr))) {
        // Counted, and the host reports it: never silently part of the image. Dropped
        // samples are not in the pixel's sample count (the mixed sum's w), so the mean is
        // over the samples that count and the pixel is not darkened.
        atomicAdd(stats.nonFiniteSamples, 1u);
        return;
    }
    // The iteration's splats, once, with its one sample (a photon iteration is one sample a
    // dispatch): its light seen directly in each solution, and the real light no virtual object
    // hides, which the composite subtracts (where one does, the pixel shows it: M = 1).
    vec3 splatMixed = vec3(0.0);
    vec3 splatReal = vec3(0.0);
    vec3 splatUnhidden = vec3(0.0);
    if (photonSplatsActive() && sampleIndex == params.sampleBase) {
        splatMixed = splattedLight(PV_SPLAT_MIXED, pixelIndex);
        if (kDifferential) {
            splatReal = splattedLight(PV_SPLAT_REAL, pixelIndex);
            splatUnhidden = splattedLight(PV_SPLAT_REAL_UNHIDDEN, pixelIndex);
        }
    }
    if (params.fireflyClamp > 0.0) {
        // One factor for both solutions, so their difference stays consistent; the splats are
        // part of the sample, as the first vertex's gather they replace was.
        float lum = max(luminance(lm + splatMixed), luminance(lr + splatReal));
        if (lum > params.fireflyClamp) {
            float k = params.fireflyClamp / lum;
            lm *= k;
            lr *= k;
            splatMixed *= k;
            splatReal *= k;
            splatUnhidden *= k;
        }
    }
    float mask = firstHitVirtual ? 1.0 : 0.0;
    // Eq. 1 per sample, without the plate term (1 − M)·L_oc, which the host adds from the
    // mean mask: where both solutions followed the same path lm − lr is exactly 0.
    vec3 composite = (firstHitVirtual ? lm : lm - lr) + splatMixed - splatUnhidden;
    lm += splatMixed;
    lr += splatReal;
    // The preview's clamps: one factor for both solutions and their difference, as
    // fireflyClamp's, so where the solutions followed the same path their difference stays
    // exactly zero. The held view's samples, each kept in the output pixel it landed in, have
    // their indirect light scaled (gIndirectMixed says why), the splats (the caustics the camera
    // sees) with it; the frame's estimate, which the denoiser and the upsampling spread over
    // many output pixels, the whole sample: a lamp in the chrome ball, right in its own pixel,
    // would light a blotch around it.
    if (params.heldWidth != 0u) {
        vec3 compositeIndirect = (firstHitVirtual ? gIndirectMixed : gIndirectMixed - gIndirectReal) +
                                 splatMixed - splatUnhidden;
        float lum = max(luminance(gIndirectMixed + splatMixed), luminance(gIndirectReal + splatReal));
        float k = params.heldClamp > 0.0 && lum > params.heldClamp ? params.heldClamp / lum : 1.0;
        // Then the whole sample to a bound the monitor shows as white in any case, so that a lamp
        // in the chrome ball does not flicker in the held view.
        float whole = max(luminance(lm - (1.0 - k) * (gIndirectMixed + splatMixed)),
                          luminance(lr - (1.0 - k) * (gIndirectReal + splatReal)));
        float wholeClamp = PV_HELD_DIRECT_CLAMP_RATIO * params.heldClamp;
        float kWhole = params.heldClamp > 0.0 && whole > wholeClamp ? wholeClamp / whole : 1.0;
        addHeldSample(pixel, kWhole * (composite - (1.0 - k) * compositeIndirect), mask);
    }
    float lum = max(luminance(lm), luminance(lr));
    if (params.estimateClamp > 0.0) {
        if (lum > params.estimateClamp) {
            float k = params.estimateClamp / lum;
            lm *= k;
            lr *= k;
            composite *= k;
        }
    }
    kahanAdd(gSum[PV_ACCUM_COMPOSITE], gComp[PV_ACCUM_COMPOSITE], vec4(composite, mask));
    kahanAdd(gSum[PV_ACCUM_MIXED], gComp[PV_ACCUM_MIXED], vec4(lm, 1.0));
    float realHit = gFirstHitReal ? 1.0 : 0.0;
    if (kDifferential) kahanAdd(gSum[PV_ACCUM_REAL], gComp[PV_ACCUM_REAL], vec4(lr, realHit));
    // Replicate 1's samples (sampler.h) also into its own sums: the convergence meter
    // compares the two replicates' means.
    if (sampleIndex % params.replicates == 1u) {
        const uint r = PV_ACCUM_REPLICATE_1;
        kahanAdd(gSum[r + PV_ACCUM_COMPOSITE], gComp[r + PV_ACCUM_COMPOSITE],
                 vec4(composite, mask));
        kahanAdd(gSum[r + PV_ACCUM_MIXED], gComp[r + PV_ACCUM_MIXED], vec4(lm, 1.0));
        if (kDifferential)
            kahanAdd(gSum[r + PV_ACCUM_REAL], gComp[r + PV_ACCUM_REAL], vec4(lr, realHit));
    }
    if (kDenoiseGuides) {
        gGuideSum[PV_GUIDE_ALBEDO_DEPTH] += vec4(gGuideAlbedo, gGuideDepthM);
        gGuideSum[PV_GUIDE_NORMAL] += vec4(gGuideNormal, 1.0);
        vec3 y = vec3(luminance(composite), luminance(lm), luminance(lr));
        gGuideSum[PV_GUIDE_MOMENTS] += vec4(y * y, mask);
    }
}

// Starts sample `key` of `pixel`: the camera ray, and the sample's mixed radiance lm (L_om), real
// radiance lr (L_or) and whether the camera ray's first hit is virtual (its mask M) at zero.
void beginPath(uvec2 pixel, uint pixelIndex, uint sampleIndex, SampleKey key, out PathState st,
               out vec3 lm, out vec3 lr, out bool firstHitVirtual) {
    gCameraJitter = cameraJitter(pixelIndex, sampleIndex, key);
    st.ray = cameraRay(pixel, gCameraJitter, key);
    st.throughput = vec3(1.0);
    st.prevPdf = 0.0;
    st.prevDelta = true;
    st.prevPosition = st.ray.origin;
    st.rouletteScale = 1.0;
    st.depth = 0u;
    st.causticState = CAUSTIC_NONE;
    st.causticBounces = 0u;
    st.gatherLevel1 = true;
    st.roughVertices = 0u;
    st.lastScatterRough = false;
    st.distantResampled = false;
    if (kResampling && params.resampling != 0u) clearReservoir(pixel);
    gIndirectMixed = vec3(0.0);
    gIndirectReal = vec3(0.0);
    lm = vec3(0.0);
    lr = vec3(0.0);
    firstHitVirtual = false;
    gFirstHitReal = false;
    gFirstHitDistanceM = PV_GUIDE_MISS_DEPTH_M;
    gFirstHitNormal = vec3(0.0);
    if (kDenoiseGuides) {
        gGuideAlbedo = vec3(1.0);
        gGuideNormal = -st.ray.direction;
        gGuideDepthM = PV_GUIDE_MISS_DEPTH_M;
    }
}

// The branches of a sample still to trace after the path in hand ends: the real solution behind
// a virtual object, and the reflection of a split at smooth glass (mixed only), which is traced
// first.
struct PendingBranches {
    PathState realContinuation;
    bool haveRealContinuation;
    PathState reflected;
    bool haveReflected;
};

// The light a ray that leaves the scene sees: the environment, and the cone lights, which are
// seen where they are (camera rays, mirrors, and the BSDF half of their multiple importance
// sampling).
void addEscapedLight(PathState st, uint mode, inout vec3 lm, inout vec3 lr) {
    if (kResampling && st.distantResampled) return;
    if (kHasEnv && params.envWidth > 0u && !(params.photonEnvironment != 0u && photonMapCarries(st))) {
        vec2 rotation = vec2(params.envRotationCos, params.envRotationSin);
        vec3 le = params.envScale *
                  envRadiance(st.ray.direction, params.envWidth, params.envHeight, rotation);
        float w = st.prevDelta ? 1.0
                               : powerHeuristic(st.prevPdf,
                                                envPdf(st.ray.direction, params.envWidth,
                                                       params.envHeight, rotation));
        addRadiance(mode, st.throughput * le * w, emissionIsIndirect(st), lm, lr);
    }
    if (kHasConeLights) {
        for (uint i = params.coneLightFirst; i < params.lightCount; ++i) {
            PV_COUNT_LOOP_ITERATION();
            GpuLight light = lightAt(i);
            float pdf = coneLightPdf(light, st.ray.direction);
            if (!(pdf > 0.0) || photonMapCarries(st)) continue;
            float w = st.prevDelta ? 1.0 : powerHeuristic(st.prevPdf, pdf);
            // Estimated lights are part of the captured (real) environment; a cone
            // light without PV_LIGHT_REAL lights only the mixed solution.
            vec3 l = st.throughput * light.intensity * w;
            bool indirect = emissionIsIndirect(st);
            if ((light.type & PV_LIGHT_REAL) != 0u) addRadiance(mode, l, indirect, lm, lr);
            else if (mode != MODE_REAL) addRadiance(MODE_MIXED, l, indirect, lm, lr);
        }
    }
}

// The photon map's estimate at a vertex of the camera path. Returns whether the vertex is a
// gather vertex (one that does not carry caustics); one that does extends a caustic chain.
bool gatherAtVertex(SampleKey key, inout PathState st, uint mode, Surface s, BsdfParams bp,
                    Frame frame, vec3 wo, inout vec3 lm, inout vec3 lr) {
    if (bsdfCarriesCaustics(bp)) {
        if (st.causticState != CAUSTIC_NONE) {
            st.causticState = CAUSTIC_SPECULAR_CHAIN;
            st.causticBounces += 1u;
        }
        return false;
    }
    // Every vertex that does not carry caustics gathers: level 2 always, level 1 where the rule
    // allows (shared/photon_records.h), so the light a caustic throws onward (the wall beside a
    // glass) is a density estimate, not the path tracer's rare, bright samples.
    // The light set's fourth number is otherwise unused.
    float u = draw(key, vertexSet(st.depth, PV_SET_VERTEX_LIGHT)).w;
    // A gather of level 2 alone (the caustic's light after a diffuse bounce seen after another)
    // adds little and costs a full grid lookup: it runs with a probability, weighted by its
    // inverse (unbiased); u, rescaled, still places the window.
    float pGather = st.gatherLevel1 ? 1.0 : PV_PHOTON_LEVEL_2_GATHER_PROBABILITY;
    // The first vertex's photons reach the pixel as the photon pass's splats.
    bool splatted = photonSplatsActive() && st.depth == 0u;
    if (u < pGather && !splatted) {
        vec3 causticMixed;
        vec3 causticReal;
        gatherPhotons(s, bp, frame, wo, st.depth, u / pGather, st.gatherLevel1, causticMixed,
                      causticReal);
        vec3 weight = st.throughput / pGather;
        // A caustic is light that a mirror or glass sent on: indirect.
        addLight(mode, weight * causticMixed, weight * causticReal, true, lm, lr);
    }
    return true;
}

// The scattered ray from the vertex, into `st`; at smooth glass the camera sees, also the
// reflected branch, into `pending`. Returns true when the path has ended (absorbed).
bool scatterFromVertex(SampleKey key, inout PathState st, uint mode, Surface s, BsdfParams bp,
                       Frame frame, vec3 wo, bool gatherVertex, inout PendingBranches pending) {
    BsdfSample bs;
    vec4 uBsdf = draw(key, vertexSet(st.depth, PV_SET_VERTEX_BSDF));
    float pReflect;
    if (kHasTransmission && st.depth == 0u && mode == MODE_MIXED &&
        bsdfSplitsAtSmoothGlass(bp, wo, pReflect)) {
        // Smooth glass the camera sees: both branches are followed, each weighted by its
        // coefficient (unbiased). A Fresnel choice would show the reflection — a caustic
        // or a light in the glass's grazing rim — in few samples, brightly: the noisiest
        // pixels of a glass object. The reflection is traced after this path, mixed only (the
        // split happens where the solutions have parted, or in a plain render).
        BsdfSample reflection;
        if (smoothDielectricReflection(bp, wo, pReflect, reflection)) {
            pending.reflected = st;
            pending.haveReflected = scatter(pending.reflected, s, frame, bp, reflection,
                                            gatherVertex, uBsdf.w, pReflect);
        }
        return !smoothDielectricRefraction(bp, wo, 1.0 - pReflect, bs) ||
               !scatter(st, s, frame, bp, bs, gatherVertex, uBsdf.w, 1.0 - pReflect);
    }
    return !sampleBsdf(bp, wo, uBsdf, bs) ||
           !scatter(st, s, frame, bp, bs, gatherVertex, uBsdf.w, 1.0);
}

// One segment of the path in `st` (solution `mode`): the ray to its next hit, the light found
// there, and the scattered ray. Returns true when the path has ended. Where the camera path's
// solutions part behind a virtual object, or it splits at smooth glass, the branch to trace
// after it is stored in `pending`.
bool extendPath(SampleKey key, inout PathState st, inout uint mode, inout vec3 lm,
                inout vec3 lr, inout bool firstHitVirtual, inout PendingBranches pending) {
    Hit hit;
    bool found = intersectScene(st.ray, mode, hit);
    bool hitVirtual = found && hit.triangle >= params.realTriangleCount;
    if (hitVirtual && st.depth == 0u) firstHitVirtual = true;
    if (found && !hitVirtual && st.depth == 0u && mode != MODE_REAL) gFirstHitReal = true;
    if (found && st.depth == 0u && mode != MODE_REAL) gFirstHitDistanceM = hit.t;
    if (hitVirtual && mode == MODE_SHARED) {
        // The solutions part here: the real one continues this ray behind the virtual
        // object (traced after the mixed part), the mixed one shades the virtual hit.
        pending.realContinuation = st;
        pending.haveRealContinuation = true;
        mode = MODE_MIXED;
    }
    if (!found) {
        addEscapedLight(st, mode, lm, lr);
        return true;
    }
    Surface s = surfaceAt(st.ray, hit);
    if (st.depth == 0u && mode != MODE_REAL) gFirstHitNormal = s.geometricNormal;
    GpuMaterial m = materialAt(s.material);
    if (kHasTransmission && !s.frontFace && maxComponent(m.attenuation) > 0.0) {
        // Beer–Lambert (KHR_materials_volume): the segment just travelled ran inside
        // this material's volume, from where the path entered it to this back face.
        st.throughput *= exp(-m.attenuation * hit.t);
    }
    if (kHasEmissive && maxComponent(m.emission) > 0.0 && emitsToward(m, s.frontFace) &&
        !photonMapCarries(st)) {
        float w = st.prevDelta ? 1.0
                               : powerHeuristic(st.prevPdf,
                                                emissiveLightPdf(hit.triangle,
                                                                 st.prevPosition, s));
        addRadiance(mode, st.throughput * emittedRadiance(m, s.uv) * w, emissionIsIndirect(st), lm,
                    lr);
    }
    if (st.depth >= params.maxDepth) return true;

    Frame frame;
    frame.n = s.shadingNormal;
    buildBasis(frame.n, frame.t, frame.b);
    vec3 wo = toLocal(frame, -st.ray.direction);
    BsdfParams bp = bsdfParamsAt(m, s);
    if (kDenoiseGuides && mode != MODE_REAL && st.depth == 0u) {
        // An emitter's light is not modulated by its base colour: albedo 1, as a miss.
        gGuideAlbedo = maxComponent(m.emission) > 0.0 ? vec3(1.0) : bp.baseColor;
        gGuideNormal = faceforward(s.shadingNormal, st.ray.direction, s.shadingNormal);
        gGuideDepthM = hit.t;  // the camera ray's direction is unit: metres
    }
    bool gatherVertex = kPhotons && gatherAtVertex(key, st, mode, s, bp, frame, wo, lm, lr);
    bool resampled = false;
    // Light sampling only where some lobe is not a delta (a smooth mirror or glass
    // can only see lights through its one reflected or refracted ray).
    if (!(kHasSpecular || kHasTransmission) || !bsdfIsDelta(bp) ||
        bsdfLobeProbabilities(bp, wo).z > 0.0) {
        vec3 directMixed = vec3(0.0);
        vec3 directReal = vec3(0.0);
        // At a vertex that carries caustics on a chain the photons carry, the lights it samples
        // end such a chain; at a gather vertex the state is still the chain's that reached it,
        // and its lights are its own direct light.
        bool carried = !gatherVertex && photonMapCarries(st);
        // The preview resamples the distant light at the camera ray's first rough hit.
        resampled = kResampling && params.resampling != 0u && st.depth == 0u &&
                    mode != MODE_REAL && !bsdfCarriesCaustics(bp) && hasDistantLight();
        if (resampled)
            resampleDistantLight(s, bp, frame, wo, mode, gPixel, hit.t, key, directMixed,
                                 directReal);
        sampleDirectLight(s, bp, frame, wo, mode, key, st.depth, carried, resampled,
                          directMixed, directReal);
        addLight(mode, st.throughput * directMixed, st.throughput * directReal,
                 vertexLightIsIndirect(st), lm, lr);
    }
    bool ended = scatterFromVertex(key, st, mode, s, bp, frame, wo, gatherVertex, pending);
    // A delta lobe's direction is no candidate of the reservoir: what it meets counts.
    st.distantResampled = resampled && !st.prevDelta;
    return ended;
}

// The pixel's samples sampleBase .. sampleBase + samplesPerDispatch − 1, each added to the sums by
// addSample as it ends. Every vertex draws the dimension sets of its depth, so the real pass after
// a split draws what a real-only render would.
//
// One loop traces, per sample, the camera path (both solutions until they part), then the
// reflected branch of a split at smooth glass, then the real solution behind a virtual object;
// then the lane starts its next sample (path regeneration, Novák et al. 2010). Each starts where
// the one before ended, so a lane whose path ended early does not idle until the longest path of
// its SIMD batch ends, and the loop's body (traversal and shading) is compiled once.
//
// The loop's exit is tested at the end of its body, after the segment. llvmpipe runs both sides
// of every branch under a mask and tests a loop's mask only where the body ends: a break at the
// top would run one more whole segment, masked, for every SIMD batch (about 90 ms a dispatch at
// 640×480, measured).
void tracePaths(uvec2 pixel, uint pixelIndex) {
    gPixel = pixel;
    uint nth = 0u;
    SampleKey key;
    PathState st;
    vec3 lm;
    vec3 lr;
    bool firstHitVirtual;
    uint nonFiniteRaysBefore;
    uint mode;
    PendingBranches pending;
    pending.haveRealContinuation = false;
    pending.haveReflected = false;
    bool sampleBegins = true;
    for (;;) {
        PV_COUNT_LOOP_ITERATION();
        if (sampleBegins) {
            key = interleavedSampleKey(pixelIndex, params.sampleBase + nth, params.seed,
                                       params.replicates);
            beginPath(pixel, pixelIndex, params.sampleBase + nth, key, st, lm, lr,
                      firstHitVirtual);
            nonFiniteRaysBefore = gNonFiniteRays;
            mode = kDifferential ? MODE_SHARED : MODE_MIXED;
            sampleBegins = false;
        }
        bool ended = extendPath(key, st, mode, lm, lr, firstHitVirtual, pending);
        if (ended) {
            if (pending.haveReflected) {
                st = pending.reflected;
                mode = MODE_MIXED;
                pending.haveReflected = false;
            } else if (pending.haveRealContinuation) {
                st = pending.realContinuation;
                mode = MODE_REAL;
                pending.haveRealContinuation = false;
            } else {
                addSample(params.sampleBase + nth, pixelIndex, lm, lr, firstHitVirtual,
                          gNonFiniteRays != nonFiniteRaysBefore, pixel);
                nth += 1u;
                if (nth >= params.samplesPerDispatch) break;
                sampleBegins = true;
            }
        }
    }
}

void main() {
    params = paramsBuffer;  // before any branch (scene_access.glsl)
    uvec2 pixel = gl_GlobalInvocationID.xy + uvec2(params.columnFirst, params.rowFirst);
    if (pixel.x >= params.columnEnd || pixel.y >= params.rowEnd) return;
    uint pixelIndex = pixel.y * params.width + pixel.x;
    for (uint k = 0u; k < PV_ACCUM_COUNT; ++k) {
        PV_COUNT_LOOP_ITERATION();
        gSum[k] = vec4(0.0);
        gComp[k] = vec4(0.0);
    }
    for (uint k = 0u; k < PV_GUIDE_COUNT; ++k) gGuideSum[k] = vec4(0.0);
    tracePaths(pixel, pixelIndex);
    atomicAdd(stats.raysTraced, gRaysTraced);
    if (gNonFiniteRays > 0u) atomicAdd(stats.nonFiniteRays, gNonFiniteRays);
    for (uint k = 0u; k < PV_ACCUM_COUNT; ++k) {
        PV_COUNT_LOOP_ITERATION();
        // The accumulation is bound from this band's first row on.
        uint at = (pixelIndex - params.bandFirstRow * params.width) * PV_ACCUM_COUNT + k;
        vec4 total = accumSum[at];
        vec4 c = accumCompensation[at];
        kahanAdd(total, c, gSum[k] - gComp[k]);
        accumSum[at] = total;
        accumCompensation[at] = c;
    }
    float kept = gGuideSum[PV_GUIDE_NORMAL].w;
    if (kDenoiseGuides && kept > 0.0) {
        // Running means over the pixel's kept samples (shared/denoise.h says why not sums).
        // Bound from this band's first row on, as the accumulation.
        uint at = (pixelIndex - params.bandFirstRow * params.width) * PV_GUIDE_COUNT;
        float total = guides[at + PV_GUIDE_NORMAL].w + kept;
        for (uint k = 0u; k < PV_GUIDE_COUNT; ++k) {
            vec4 mean = guides[at + k];
            guides[at + k] = mean + (gGuideSum[k] - kept * mean) / total;
        }
        guides[at + PV_GUIDE_NORMAL].w = total;
    }
    // The renderer sizes later dispatches from this (lavapipe's loop budget).
    if (kCountLoops) atomicMax(stats.maxLoopIterations, gLoopIterations);
}
