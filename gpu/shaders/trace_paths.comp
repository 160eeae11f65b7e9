// trace_paths: unidirectional path tracing with next-event estimation and multiple importance
// sampling (environment map, emissive triangles, punctual lights), Russian roulette, thin-lens
// camera and jittered box-filter supersampling. Each invocation traces samplesPerDispatch paths
// for one pixel and adds their sum to the pixel's compensated (Kahan) running sum.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

#include "shared/scene_types.h"

layout(local_size_x = PV_WORKGROUP_SIZE_X, local_size_y = PV_WORKGROUP_SIZE_Y) in;

// Scene features: a variant compiled with a feature off runs none of its code.
layout(constant_id = PV_SPEC_HAS_ENV) const bool kHasEnv = true;
layout(constant_id = PV_SPEC_HAS_EMISSIVE) const bool kHasEmissive = true;
layout(constant_id = PV_SPEC_HAS_PUNCTUAL) const bool kHasPunctual = true;
layout(constant_id = PV_SPEC_HAS_SPECULAR) const bool kHasSpecular = true;
layout(constant_id = PV_SPEC_HAS_TRANSMISSION) const bool kHasTransmission = true;
layout(constant_id = PV_SPEC_HAS_THIN_LENS) const bool kHasThinLens = true;
layout(constant_id = PV_SPEC_HAS_TEXTURES) const bool kHasTextures = true;

layout(binding = PV_BINDING_PARAMS, scalar) readonly buffer ParamsBuffer { FrameParams params; };
layout(binding = PV_BINDING_POSITIONS, scalar) readonly buffer Positions { vec3 positions[]; };
layout(binding = PV_BINDING_NORMALS, scalar) readonly buffer Normals { vec3 normals[]; };
layout(binding = PV_BINDING_UVS, scalar) readonly buffer Uvs { vec2 uvs[]; };
layout(binding = PV_BINDING_TRIANGLES, scalar) readonly buffer Triangles { uvec3 triangles[]; };
layout(binding = PV_BINDING_TRIANGLE_MATERIALS, scalar) readonly buffer TriangleMaterials {
    uint triangleMaterials[];
};
layout(binding = PV_BINDING_BVH_NODES, scalar) readonly buffer Nodes { BvhNode bvhNodes[]; };
layout(binding = PV_BINDING_MATERIALS, scalar) readonly buffer Materials {
    GpuMaterial materials[];
};
layout(binding = PV_BINDING_TEXTURES, scalar) readonly buffer Textures {
    TextureInfo textures[];
};
layout(binding = PV_BINDING_TEXELS, scalar) readonly buffer Texels { uint texels[]; };
layout(binding = PV_BINDING_LIGHTS, scalar) readonly buffer Lights { GpuLight lights[]; };
layout(binding = PV_BINDING_EMISSIVE_TRIANGLES, scalar) readonly buffer EmissiveTriangles {
    EmissiveTriangle emissiveTriangles[];
};
layout(binding = PV_BINDING_ENV_RADIANCE, scalar) readonly buffer EnvRadiance {
    vec3 envRadianceTexels[];
};
layout(binding = PV_BINDING_ENV_MARGINAL_CDF, scalar) readonly buffer EnvMarginal {
    float envMarginalCdf[];
};
layout(binding = PV_BINDING_ENV_CONDITIONAL_CDF, scalar) readonly buffer EnvConditional {
    float envConditionalCdf[];
};
layout(binding = PV_BINDING_ACCUM_SUM, scalar) buffer AccumSum { vec4 accumSum[]; };
layout(binding = PV_BINDING_ACCUM_COMPENSATION, scalar) buffer AccumCompensation {
    vec4 accumCompensation[];
};
layout(binding = PV_BINDING_STATS, scalar) buffer Stats { RenderStats stats; };
layout(binding = PV_BINDING_TRIANGLE_LIGHT_PDF, scalar) readonly buffer TriangleLightPdf {
    float triangleLightPdf[];
};

#define PV_BVH_NODE(i) bvhNodes[i]
#define PV_TRIANGLE(i) triangles[i]
#define PV_POSITION(i) positions[i]
#include "shared/ray_tracing.h"

#define PV_ENV_RADIANCE(i) envRadianceTexels[i]
#define PV_ENV_MARGINAL_CDF(i) envMarginalCdf[i]
#define PV_ENV_CONDITIONAL_CDF(i) envConditionalCdf[i]
#include "shared/env_sampling.h"

#include "shared/bsdf.h"
#include "shared/sampling.h"

#define NO_HIT 0xffffffffu

// Rays this invocation traced, added to stats.raysTraced once at the end (one atomic per pixel).
uint gRaysTraced = 0u;

// Closest hit against all geometry (both BVHs: real phantoms and virtual objects).
bool intersectScene(Ray ray, out Hit hit) {
    ++gRaysTraced;
    hit.t = ray.tMax;
    hit.triangle = NO_HIT;
    hit.b1 = 0.0;
    hit.b2 = 0.0;
    bool found = traceClosest(params.realRoot, ray, hit);
    found = traceClosest(params.virtualRoot, ray, hit) || found;
    return found;
}

bool occluded(Ray ray) {
    ++gRaysTraced;
    return traceAny(params.realRoot, ray) || traceAny(params.virtualRoot, ray);
}

// Shadow ray between two surface points, each offset off its surface toward the other.
bool segmentOccluded(vec3 from, vec3 fromNormal, vec3 to, vec3 toNormal) {
    vec3 d = to - from;
    vec3 origin = offsetRayOrigin(from, dot(d, fromNormal) >= 0.0 ? fromNormal : -fromNormal);
    vec3 target = offsetRayOrigin(to, dot(d, toNormal) <= 0.0 ? toNormal : -toNormal);
    vec3 dir = target - origin;
    float len = length(dir);
    if (!(len > 0.0)) return false;
    Ray ray;
    ray.origin = origin;
    ray.direction = dir / len;
    ray.tMin = 0.0;
    ray.tMax = len;
    return occluded(ray);
}

bool rayOccluded(vec3 from, vec3 fromNormal, vec3 dir) {
    Ray ray;
    ray.origin = offsetRayOrigin(from, dot(dir, fromNormal) >= 0.0 ? fromNormal : -fromNormal);
    ray.direction = dir;
    ray.tMin = 0.0;
    ray.tMax = PV_FLOAT_MAX;
    return occluded(ray);
}

vec4 unpackTexel(uint texel, bool srgb) {
    vec4 c = vec4(texel & 0xffu, (texel >> 8) & 0xffu, (texel >> 16) & 0xffu, texel >> 24) / 255.0;
    if (srgb) {
        bvec3 low = lessThanEqual(c.rgb, vec3(0.04045));
        c.rgb = mix(pow((c.rgb + 0.055) / 1.055, vec3(2.4)), c.rgb / 12.92, low);
    }
    return c;
}

// Bilinear, repeat wrap (glTF's default sampler); sRGB decoded before filtering.
vec4 sampleTexture(uint index, vec2 uv) {
    TextureInfo info = textures[index];
    vec2 p = uv * vec2(info.width, info.height) - 0.5;
    vec2 f = fract(p);
    ivec2 size = ivec2(info.width, info.height);
    ivec2 i0 = ivec2(floor(p));
    vec4 c = vec4(0.0);
    for (int dy = 0; dy < 2; ++dy) {
        for (int dx = 0; dx < 2; ++dx) {
            ivec2 q = (i0 + ivec2(dx, dy)) % size;
            q += size * ivec2(lessThan(q, ivec2(0)));
            float w = (dx == 1 ? f.x : 1.0 - f.x) * (dy == 1 ? f.y : 1.0 - f.y);
            c += w * unpackTexel(texels[info.offset + uint(q.y * size.x + q.x)], info.srgb != 0u);
        }
    }
    return c;
}

struct Surface {
    vec3 position;
    vec3 geometricNormal;  // faces the side the ray came from
    vec3 shadingNormal;    // same side as geometricNormal
    vec2 uv;
    bool frontFace;        // the ray hit the side the triangle's winding faces
    uint material;
};

Surface surfaceAt(Ray ray, Hit hit) {
    Surface s;
    uvec3 tri = triangles[hit.triangle];
    vec3 p0 = positions[tri.x];
    vec3 p1 = positions[tri.y];
    vec3 p2 = positions[tri.z];
    float b0 = 1.0 - hit.b1 - hit.b2;
    s.position = b0 * p0 + hit.b1 * p1 + hit.b2 * p2;
    vec3 ng = cross(p1 - p0, p2 - p0);
    float len = length(ng);
    ng = len > 0.0 ? ng / len : -ray.direction;
    vec3 ns = b0 * normals[tri.x] + hit.b1 * normals[tri.y] + hit.b2 * normals[tri.z];
    float nsLen = length(ns);
    ns = (nsLen > 0.0 && !isnan(nsLen) && !isinf(nsLen)) ? ns / nsLen : ng;
    s.uv = b0 * uvs[tri.x] + hit.b1 * uvs[tri.y] + hit.b2 * uvs[tri.z];
    s.material = triangleMaterials[hit.triangle];
    if (kHasTextures && materials[s.material].normalTexture != PV_NO_TEXTURE) {
        // Tangent frame from the triangle's uv parametrisation.
        vec2 duv1 = uvs[tri.y] - uvs[tri.x];
        vec2 duv2 = uvs[tri.z] - uvs[tri.x];
        float det = duv1.x * duv2.y - duv1.y * duv2.x;
        if (abs(det) > 0.0) {
            vec3 t = ((p1 - p0) * duv2.y - (p2 - p0) * duv1.y) / det;
            vec3 b = ((p2 - p0) * duv1.x - (p1 - p0) * duv2.x) / det;
            t = t - ns * dot(ns, t);
            float tLen = length(t);
            if (tLen > 0.0) {
                t /= tLen;
                vec3 bt = cross(ns, t) * (dot(cross(ns, t), b) < 0.0 ? -1.0 : 1.0);
                vec3 m = sampleTexture(materials[s.material].normalTexture, s.uv).xyz * 2.0 - 1.0;
                vec3 mapped = normalize(m.x * t + m.y * bt + m.z * ns);
                if (!any(isnan(mapped))) ns = mapped;
            }
        }
    }
    s.frontFace = dot(ray.direction, ng) < 0.0;
    s.geometricNormal = s.frontFace ? ng : -ng;
    s.shadingNormal = dot(ns, s.geometricNormal) < 0.0 ? -ns : ns;
    return s;
}

vec3 emittedRadiance(GpuMaterial m, vec2 uv) {
    vec3 e = m.emission;
    if (kHasTextures && m.emissiveTexture != PV_NO_TEXTURE) e *= sampleTexture(m.emissiveTexture, uv).rgb;
    return e;
}

bool emitsToward(GpuMaterial m, bool frontFace) {
    return frontFace || (m.flags & PV_MATERIAL_DOUBLE_SIDED) != 0u;
}

BsdfParams bsdfParamsAt(GpuMaterial m, Surface s) {
    BsdfParams p;
    p.baseColor = m.baseColor.rgb;
    p.metallic = m.metallic;
    float roughness = m.roughness;
    if (kHasTextures) {
        if (m.baseColorTexture != PV_NO_TEXTURE)
            p.baseColor *= sampleTexture(m.baseColorTexture, s.uv).rgb;
        if (m.metallicRoughnessTexture != PV_NO_TEXTURE) {
            vec4 mr = sampleTexture(m.metallicRoughnessTexture, s.uv);
            roughness *= mr.g;  // glTF: roughness in G, metalness in B
            p.metallic *= mr.b;
        }
    }
    p.alpha = roughness * roughness;
    p.transmission = kHasTransmission ? m.transmission : 0.0;
    p.specular = kHasSpecular ? m.specular : 0.0;
    p.specularColor = m.specularColor;
    if (!kHasSpecular) p.metallic = 0.0;
    // A transmissive surface hit from inside sees the inverse relative IOR; opaque surfaces are
    // shaded the same from both sides.
    p.etaRel = (s.frontFace || p.transmission == 0.0) ? m.ior : 1.0 / m.ior;
    return p;
}

// f(wo, wi) and its sampling pdf. A scene of Lambertian materials only runs the first branch.
vec3 evaluateBsdf(BsdfParams p, vec3 wo, vec3 wi, out float pdf) {
    if (!kHasSpecular && !kHasTransmission) {
        pdf = wi.z > 0.0 ? wi.z * PV_INV_PI : 0.0;
        return wi.z > 0.0 ? p.baseColor * PV_INV_PI : vec3(0.0);
    }
    return bsdfEvaluate(p, wo, wi, pdf);
}

bool sampleBsdf(BsdfParams p, vec3 wo, inout uint rng, out BsdfSample s) {
    float uLobe = rngNext(rng);
    vec2 u = rngNext2(rng);
    if (!kHasSpecular && !kHasTransmission) {
        s.wi = sampleCosineHemisphere(u);
        s.pdf = s.wi.z * PV_INV_PI;
        s.weight = p.baseColor;
        s.lobe = PV_LOBE_DIFFUSE;
        s.isDelta = false;
        return s.pdf > 0.0 && maxComponent(p.baseColor) > 0.0;
    }
    return bsdfSample(p, wo, uLobe, u, s);
}

struct Frame {
    vec3 t;
    vec3 b;
    vec3 n;
};

vec3 toLocal(Frame f, vec3 v) { return vec3(dot(v, f.t), dot(v, f.b), dot(v, f.n)); }
vec3 toWorld(Frame f, vec3 v) { return v.x * f.t + v.y * f.b + v.z * f.n; }

// A direction is usable only on the geometric side its local z promises; shading normals would
// otherwise let light leak through surfaces.
bool consistentSide(Surface s, vec3 wiWorld, vec3 wiLocal) {
    float g = dot(wiWorld, s.geometricNormal);
    return wiLocal.z > 0.0 ? g > 0.0 : g < 0.0;
}

uint pickEmissiveTriangle(float u) {
    uint lo = 0u;
    uint hi = params.emissiveTriangleCount - 1u;
    while (lo < hi) {
        uint mid = (lo + hi) / 2u;
        if (u < emissiveTriangles[mid].cdf) hi = mid; else lo = mid + 1u;
    }
    return lo;
}

// Solid-angle pdf with which emissive-triangle sampling picks the point `hit` seen from `from`.
float emissiveLightPdf(uint triangle, vec3 from, Surface lightSurface) {
    uvec3 tri = triangles[triangle];
    vec3 p0 = positions[tri.x];
    float area = 0.5 * length(cross(positions[tri.y] - p0, positions[tri.z] - p0));
    vec3 d = lightSurface.position - from;
    float dist2 = dot(d, d);
    float cosLight = abs(dot(normalize(d), lightSurface.geometricNormal));
    if (!(area > 0.0) || !(cosLight > 0.0)) return 0.0;
    return triangleLightPdf[triangle] * dist2 / (area * cosLight);
}

vec3 sampleDirectLight(Surface s, BsdfParams bp, Frame frame, vec3 wo, inout uint rng) {
    vec3 result = vec3(0.0);
    if (kHasEnv && params.envWidth > 0u) {
        float envPdfValue;
        uint texel;
        vec3 wi = envSampleTexel(rngNext2(rng), params.envWidth, params.envHeight,
                                 params.envRotationRad, envPdfValue, texel);
        vec3 wiLocal = toLocal(frame, wi);
        if (envPdfValue > 0.0 && consistentSide(s, wi, wiLocal)) {
            float bsdfPdf;
            vec3 f = evaluateBsdf(bp, wo, wiLocal, bsdfPdf);
            if (maxComponent(f) > 0.0 && !rayOccluded(s.position, s.geometricNormal, wi)) {
                // The sampled texel's radiance (see envSampleTexel).
                vec3 le = params.envScale * envRadianceTexels[texel];
                result += f * abs(wiLocal.z) * le * powerHeuristic(envPdfValue, bsdfPdf) / envPdfValue;
            }
        }
    }
    if (kHasEmissive && params.emissiveTriangleCount > 0u) {
        float uPick = rngNext(rng);
        vec2 uPoint = rngNext2(rng);
        EmissiveTriangle et = emissiveTriangles[pickEmissiveTriangle(uPick)];
        uvec3 tri = triangles[et.triangle];
        vec2 b = sampleUniformTriangle(uPoint);
        vec3 p0 = positions[tri.x];
        vec3 p1 = positions[tri.y];
        vec3 p2 = positions[tri.z];
        vec3 lightPoint = (1.0 - b.x - b.y) * p0 + b.x * p1 + b.y * p2;
        vec3 ng = normalize(cross(p1 - p0, p2 - p0));
        vec3 d = lightPoint - s.position;
        float dist2 = dot(d, d);
        vec3 wi = d * inversesqrt(dist2);
        float cosLight = dot(-wi, ng);
        GpuMaterial lm = materials[triangleMaterials[et.triangle]];
        bool facing = cosLight > 0.0 || (cosLight < 0.0 && emitsToward(lm, false));
        vec3 wiLocal = toLocal(frame, wi);
        if (facing && dist2 > 0.0 && consistentSide(s, wi, wiLocal)) {
            float lightPdf = et.pdf * dist2 / (et.area * abs(cosLight));
            float bsdfPdf;
            vec3 f = evaluateBsdf(bp, wo, wiLocal, bsdfPdf);
            if (maxComponent(f) > 0.0 && lightPdf > 0.0 &&
                !segmentOccluded(s.position, s.geometricNormal, lightPoint, ng)) {
                vec2 uv = (1.0 - b.x - b.y) * uvs[tri.x] + b.x * uvs[tri.y] + b.y * uvs[tri.z];
                vec3 le = emittedRadiance(lm, uv);
                result += f * abs(wiLocal.z) * le * powerHeuristic(lightPdf, bsdfPdf) / lightPdf;
            }
        }
    }
    if (kHasPunctual && params.lightCount > 0u) {
        uint index = min(uint(rngNext(rng) * float(params.lightCount)), params.lightCount - 1u);
        GpuLight light = lights[index];
        vec3 wi;
        vec3 li;
        bool occ;
        if (light.type == PV_LIGHT_DIRECTIONAL) {
            wi = -light.direction;
            li = light.intensity;  // illuminance (lux) from a delta direction
            occ = false;
        } else {
            vec3 d = light.position - s.position;
            float dist2 = dot(d, d);
            wi = d * inversesqrt(dist2);
            li = light.intensity / dist2;  // inverse-square law
            if (light.type == PV_LIGHT_SPOT) {
                // glTF KHR_lights_punctual's recommended smooth cone falloff.
                float cd = dot(light.direction, -wi);
                float scale = 1.0 / max(0.001, light.cosInnerCone - light.cosOuterCone);
                float a = clamp((cd - light.cosOuterCone) * scale, 0.0, 1.0);
                li *= a * a;
            }
            occ = false;
        }
        vec3 wiLocal = toLocal(frame, wi);
        if (maxComponent(li) > 0.0 && consistentSide(s, wi, wiLocal)) {
            float bsdfPdf;
            vec3 f = evaluateBsdf(bp, wo, wiLocal, bsdfPdf);
            if (maxComponent(f) > 0.0) {
                if (light.type == PV_LIGHT_DIRECTIONAL) {
                    occ = rayOccluded(s.position, s.geometricNormal, wi);
                } else {
                    Ray r;
                    r.origin = offsetRayOrigin(s.position, s.geometricNormal *
                                               (dot(wi, s.geometricNormal) >= 0.0 ? 1.0 : -1.0));
                    vec3 toLight = light.position - r.origin;
                    r.tMax = length(toLight);
                    r.direction = toLight / r.tMax;
                    r.tMin = 0.0;
                    occ = occluded(r);
                }
                if (!occ) result += f * abs(wiLocal.z) * li * float(params.lightCount);
            }
        }
    }
    return result;
}

Ray cameraRay(uvec2 pixel, inout uint rng) {
    vec2 jitter = rngNext2(rng);
    vec2 ndc = vec2((float(pixel.x) + jitter.x) / float(params.width) * 2.0 - 1.0,
                    1.0 - (float(pixel.y) + jitter.y) / float(params.height) * 2.0);
    vec3 dir = vec3(ndc * params.tanHalfFov, -1.0);
    vec3 origin = vec3(0.0);
    if (kHasThinLens && params.apertureRadiusM > 0.0) {
        // Thin lens: the lens sits at the camera position, perpendicular to the optical axis;
        // all rays through a pixel meet on the focal plane z = -focusDistance.
        vec3 focus = dir * params.focusDistanceM;
        origin = vec3(params.apertureRadiusM * sampleUniformDiskConcentric(rngNext2(rng)), 0.0);
        dir = focus - origin;
    }
    Ray ray;
    ray.origin = (params.worldFromCamera * vec4(origin, 1.0)).xyz;
    ray.direction = normalize(mat3(params.worldFromCamera) * dir);
    ray.tMin = 0.0;
    ray.tMax = PV_FLOAT_MAX;
    return ray;
}

vec3 tracePath(uvec2 pixel, inout uint rng) {
    Ray ray = cameraRay(pixel, rng);
    vec3 radiance = vec3(0.0);
    vec3 throughput = vec3(1.0);
    float prevPdf = 0.0;
    bool prevDelta = true;  // the camera ray: emitters seen directly get full weight
    vec3 prevPosition = ray.origin;
    // Product of the η² factors of the refractions so far: Russian roulette decides on
    // throughput·etaScale, so radiance compressed inside glass does not get paths killed (pbrt).
    float etaScale = 1.0;
    for (uint depth = 0u;; ++depth) {
        Hit hit;
        if (!intersectScene(ray, hit)) {
            if (kHasEnv && params.envWidth > 0u) {
                vec3 le = params.envScale * envRadiance(ray.direction, params.envWidth,
                                                        params.envHeight, params.envRotationRad);
                float w = prevDelta ? 1.0
                                    : powerHeuristic(prevPdf, envPdf(ray.direction, params.envWidth,
                                                                     params.envHeight,
                                                                     params.envRotationRad));
                radiance += throughput * le * w;
            }
            break;
        }
        Surface s = surfaceAt(ray, hit);
        GpuMaterial m = materials[s.material];
        if (kHasEmissive && maxComponent(m.emission) > 0.0 && emitsToward(m, s.frontFace)) {
            float w = prevDelta ? 1.0
                                : powerHeuristic(prevPdf, emissiveLightPdf(hit.triangle,
                                                                           prevPosition, s));
            radiance += throughput * emittedRadiance(m, s.uv) * w;
        }
        if (depth >= params.maxDepth) break;

        Frame frame;
        frame.n = s.shadingNormal;
        buildBasis(frame.n, frame.t, frame.b);
        vec3 wo = toLocal(frame, -ray.direction);
        if (wo.z <= 0.0) {
            // Seen from below its shading normal: shade with the geometric normal instead.
            frame.n = s.geometricNormal;
            buildBasis(frame.n, frame.t, frame.b);
            wo = toLocal(frame, -ray.direction);
        }
        BsdfParams bp = bsdfParamsAt(m, s);
        // Light sampling only where some lobe is not a delta (a smooth mirror or glass cannot
        // use it: it can only see lights through its one reflected or refracted ray).
        if (!(kHasSpecular || kHasTransmission) || !bsdfIsDelta(bp) ||
            bsdfLobeProbabilities(bp, wo).z > 0.0) {
            radiance += throughput * sampleDirectLight(s, bp, frame, wo, rng);
        }

        BsdfSample bs;
        if (!sampleBsdf(bp, wo, rng, bs)) break;
        vec3 wi = toWorld(frame, bs.wi);
        if (!consistentSide(s, wi, bs.wi)) break;
        throughput *= bs.weight;
        if (bs.lobe == PV_LOBE_TRANSMISSION) etaScale *= bp.etaRel * bp.etaRel;
        prevPdf = bs.pdf;
        prevDelta = bs.isDelta;
        prevPosition = s.position;
        ray.origin = offsetRayOrigin(s.position, bs.wi.z > 0.0 ? s.geometricNormal
                                                               : -s.geometricNormal);
        ray.direction = wi;
        ray.tMin = 0.0;
        ray.tMax = PV_FLOAT_MAX;

        if (depth + 1u >= params.rouletteStartDepth) {
            // Russian roulette: unbiased, keeps paths whose throughput is still large.
            float pContinue = min(1.0, maxComponent(throughput) * etaScale);
            if (rngNext(rng) >= pContinue) break;
            throughput /= pContinue;
        }
    }
    return radiance;
}

void main() {
    uvec2 pixel = gl_GlobalInvocationID.xy;
    if (pixel.x >= params.width || pixel.y >= params.height) return;
    uint pixelIndex = pixel.y * params.width + pixel.x;
    // Kahan-compensated sums, within the dispatch and across dispatches: the mean stays exact
    // over millions of samples in 32-bit floats (the paper's running average, Eq. 3, drifts).
    // `precise` forbids the compiler from reassociating the compensation away.
    precise vec3 sum = vec3(0.0);
    precise vec3 sumC = vec3(0.0);
    for (uint i = 0u; i < params.samplesPerDispatch; ++i) {
        uint rng = rngSeed(pixelIndex, params.sampleBase + i, params.seed);
        vec3 l = tracePath(pixel, rng);
        if (any(isnan(l)) || any(isinf(l))) {
            // Counted, and the host reports it: never silently part of the image.
            atomicAdd(stats.nonFiniteSamples, 1u);
            continue;
        }
        if (params.fireflyClamp > 0.0) {
            float lum = luminance(l);
            if (lum > params.fireflyClamp) l *= params.fireflyClamp / lum;
        }
        precise vec3 y = l - sumC;
        precise vec3 t = sum + y;
        sumC = (t - sum) - y;
        sum = t;
    }
    sum -= sumC;
    atomicAdd(stats.raysTraced, gRaysTraced);
    vec4 total = accumSum[pixelIndex];
    vec4 c = accumCompensation[pixelIndex];
    precise vec4 y = vec4(sum, 0.0) - c;
    precise vec4 t = total + y;
    precise vec4 newC = (t - total) - y;
    accumSum[pixelIndex] = t;
    accumCompensation[pixelIndex] = newC;
}
