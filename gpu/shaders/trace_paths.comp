// trace_paths: unidirectional path tracing with next-event estimation and multiple importance
// sampling (environment map, emissive triangles, punctual lights), Russian roulette, thin-lens
// camera and jittered box-filter supersampling. Each invocation traces samplesPerDispatch paths
// for one pixel and adds their sum to the pixel's compensated (Kahan) running sum.
#version 460
#extension GL_EXT_scalar_block_layout : require
#extension GL_GOOGLE_include_directive : require

// Loop iterations this invocation ran, all loops together (shared/prelude.h says why); counted
// only where kCountLoops (a CPU device).
uint gLoopIterations = 0u;
#define PV_COUNT_LOOP_ITERATION() (kCountLoops ? ++gLoopIterations : 0u)

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
layout(constant_id = PV_SPEC_DIFFERENTIAL) const bool kDifferential = true;
layout(constant_id = PV_SPEC_HAS_LENS_GRID) const bool kHasLensGrid = true;
layout(constant_id = PV_SPEC_HAS_CONE_LIGHTS) const bool kHasConeLights = true;
// The sample generator (PV_SAMPLER_* in shared/sampler.h; the dimension layout is there).
layout(constant_id = PV_SPEC_SAMPLER) const uint kSampler = 0u;
layout(constant_id = PV_SPEC_COUNT_LOOPS) const bool kCountLoops = true;
// Emissive triangles sampled by solid angle (shared/triangle_light.h); off: by area (ablation).
layout(constant_id = PV_SPEC_LIGHT_SOLID_ANGLE) const bool kLightSolidAngle = true;

layout(binding = PV_BINDING_PARAMS, scalar) readonly buffer ParamsBuffer { FrameParams params; };
// Every read-only scene array indexed per lane is a texel buffer (BindingKind::TexelBufferUint4):
// on llvmpipe a texel fetch is a gather, while a storage-buffer load whose address differs per
// lane is a loop over the lanes with a bounds check each. A BVH node is seven texels
// (WideBvhNode's layout), a triangle's vertices three (xyz, w unused); shared structs are read texel by texel
// in their C++ layout (gpu/gpu_layout.cpp checks that they are whole texels).
layout(binding = PV_BINDING_BVH_NODES) uniform usamplerBuffer bvhNodeTexels;
layout(binding = PV_BINDING_TRIANGLE_VERTICES) uniform usamplerBuffer triangleVertexTexels;
layout(binding = PV_BINDING_TRIANGLES) uniform usamplerBuffer triangleTexels;
layout(binding = PV_BINDING_NORMALS) uniform usamplerBuffer normalTexels;
layout(binding = PV_BINDING_UVS) uniform usamplerBuffer uvTexels;
layout(binding = PV_BINDING_MATERIALS) uniform usamplerBuffer materialTexels;
// The materials buffer starts with the specular albedo table (render/renderer.cpp).
#define PV_SPECULAR_ALBEDO(index) \
    uintBitsToFloat(texelFetch(materialTexels, (index) / 4)[(index) % 4])
#include "shared/specular_albedo.h"
layout(binding = PV_BINDING_LIGHTS) uniform usamplerBuffer lightTexels;
layout(binding = PV_BINDING_EMISSIVE_TRIANGLES) uniform usamplerBuffer emissiveTriangleTexels;

// Vertex indices (xyz) and material (w) of triangle i in BVH order.
uvec4 triangleAt(uint i) { return texelFetch(triangleTexels, int(i)); }
vec3 normalAt(uint vertex) { return uintBitsToFloat(texelFetch(normalTexels, int(vertex)).xyz); }
vec2 uvAt(uint vertex) { return uintBitsToFloat(texelFetch(uvTexels, int(vertex)).xy); }

GpuMaterial materialAt(uint i) {
    int at = PV_SPECULAR_ALBEDO_TEXELS + int(6u * i);
    uvec4 t0 = texelFetch(materialTexels, at);
    uvec4 t1 = texelFetch(materialTexels, at + 1);
    uvec4 t2 = texelFetch(materialTexels, at + 2);
    uvec4 t3 = texelFetch(materialTexels, at + 3);
    uvec4 t4 = texelFetch(materialTexels, at + 4);
    uvec4 t5 = texelFetch(materialTexels, at + 5);
    GpuMaterial m;
    m.baseColor = uintBitsToFloat(t0);
    m.emission = uintBitsToFloat(t1.xyz);
    m.metallic = uintBitsToFloat(t1.w);
    m.specularColor = uintBitsToFloat(t2.xyz);
    m.roughness = uintBitsToFloat(t2.w);
    m.transmission = uintBitsToFloat(t3.x);
    m.ior = uintBitsToFloat(t3.y);
    m.specular = uintBitsToFloat(t3.z);
    m.baseColorTexture = t3.w;
    m.metallicRoughnessTexture = t4.x;
    m.normalTexture = t4.y;
    m.emissiveTexture = t4.z;
    m.flags = t4.w;
    m.attenuation = uintBitsToFloat(t5.xyz);
    m.reserved = t5.w;
    return m;
}

GpuLight lightAt(uint i) {
    uvec4 t0 = texelFetch(lightTexels, int(3u * i));
    uvec4 t1 = texelFetch(lightTexels, int(3u * i + 1u));
    uvec4 t2 = texelFetch(lightTexels, int(3u * i + 2u));
    GpuLight l;
    l.position = uintBitsToFloat(t0.xyz);
    l.type = t0.w;
    l.direction = uintBitsToFloat(t1.xyz);
    l.cosOuterCone = uintBitsToFloat(t1.w);
    l.intensity = uintBitsToFloat(t2.xyz);
    l.cosInnerCone = uintBitsToFloat(t2.w);
    return l;
}

EmissiveTriangle emissiveTriangleAt(uint i) {
    uvec4 t = texelFetch(emissiveTriangleTexels, int(i));
    EmissiveTriangle e;
    e.triangle = t.x;
    e.area = uintBitsToFloat(t.y);
    e.cdf = uintBitsToFloat(t.z);
    e.pdf = uintBitsToFloat(t.w);
    return e;
}
WideBvhNode loadBvhNode(uint i) {
    WideBvhNode n;
    n.loX = uintBitsToFloat(texelFetch(bvhNodeTexels, int(7u * i)));
    n.loY = uintBitsToFloat(texelFetch(bvhNodeTexels, int(7u * i + 1u)));
    n.loZ = uintBitsToFloat(texelFetch(bvhNodeTexels, int(7u * i + 2u)));
    n.hiX = uintBitsToFloat(texelFetch(bvhNodeTexels, int(7u * i + 3u)));
    n.hiY = uintBitsToFloat(texelFetch(bvhNodeTexels, int(7u * i + 4u)));
    n.hiZ = uintBitsToFloat(texelFetch(bvhNodeTexels, int(7u * i + 5u)));
    n.child = texelFetch(bvhNodeTexels, int(7u * i + 6u));
    return n;
}
// Arrays of 4-byte words read one word per fetch (BindingKind::TexelBufferUint).
layout(binding = PV_BINDING_TEXTURES) uniform usamplerBuffer textureInfoTexels;  // uint4
layout(binding = PV_BINDING_TEXELS) uniform usamplerBuffer textureTexels;        // RGBA8 words
layout(binding = PV_BINDING_ENV_RADIANCE) uniform usamplerBuffer envRadianceWords;  // 3 per texel
layout(binding = PV_BINDING_ENV_MARGINAL_CDF) uniform usamplerBuffer envMarginalWords;
layout(binding = PV_BINDING_ENV_CONDITIONAL_CDF) uniform usamplerBuffer envConditionalWords;
layout(binding = PV_BINDING_TRIANGLE_LIGHT_PDF) uniform usamplerBuffer triangleLightPdfWords;
layout(binding = PV_BINDING_LENS_GRID) uniform usamplerBuffer lensGridWords;  // 2 per corner

float wordAsFloat(usamplerBuffer words, uint i) {
    return uintBitsToFloat(texelFetch(words, int(i)).x);
}
vec3 envRadianceAt(uint texel) {
    return vec3(wordAsFloat(envRadianceWords, 3u * texel),
                wordAsFloat(envRadianceWords, 3u * texel + 1u),
                wordAsFloat(envRadianceWords, 3u * texel + 2u));
}
vec2 lensGridAt(uint corner) {
    return vec2(wordAsFloat(lensGridWords, 2u * corner), wordAsFloat(lensGridWords, 2u * corner + 1u));
}
layout(binding = PV_BINDING_ACCUM_SUM, scalar) buffer AccumSum { vec4 accumSum[]; };
layout(binding = PV_BINDING_ACCUM_COMPENSATION, scalar) buffer AccumCompensation {
    vec4 accumCompensation[];
};
layout(binding = PV_BINDING_STATS, scalar) buffer Stats { RenderStats stats; };

#define PV_BVH_NODE(i) loadBvhNode(i)
#define PV_TRIANGLE_VERTEX(i, k) \
    uintBitsToFloat(texelFetch(triangleVertexTexels, int(3u * (i) + (k))).xyz)
#include "shared/ray_tracing.h"

#define PV_ENV_RADIANCE(i) envRadianceAt(i)
#define PV_ENV_MARGINAL_CDF(i) wordAsFloat(envMarginalWords, i)
#define PV_ENV_CONDITIONAL_CDF(i) wordAsFloat(envConditionalWords, i)
#include "shared/env_sampling.h"

#include "shared/bsdf.h"
#include "shared/sampling.h"
#include "shared/sampler.h"
#include "shared/triangle_light.h"

// Four random numbers of dimension set `set` (shared/sampler.h's table) for sample `key`.
vec4 draw(SampleKey key, uint set) { return sampleSet(kSampler, key, set); }

#define NO_HIT 0xffffffffu

// Rays this invocation traced, added to stats.raysTraced once at the end (one atomic per pixel).
uint gRaysTraced = 0u;

// The paper's ray types. A path starts SHARED (a mixed radiance ray carrying both solutions)
// while it only meets real surfaces; where it first meets a virtual object it splits: the mixed
// solution goes on from the virtual surface (MIXED), and the real solution continues the same
// ray to the real surface behind it (REAL, a real radiance ray), traced after the mixed part.
#define MODE_SHARED 0u
#define MODE_MIXED 1u
#define MODE_REAL 2u

// Closest hit: real rays see the phantoms only, mixed and shared rays both BVHs.
bool intersectScene(Ray ray, uint mode, out Hit hit) {
    ++gRaysTraced;
    hit.t = ray.tMax;
    hit.triangle = NO_HIT;
    hit.b1 = 0.0;
    hit.b2 = 0.0;
    bool found = traceClosest(params.realRoot, ray, hit);
    if (mode != MODE_REAL) found = traceClosest(params.virtualRoot, ray, hit) || found;
    return found;
}

bool occludedBy(uint root, Ray ray) {
    ++gRaysTraced;
    return traceAny(root, ray);
}

// Adds a light sample's contribution `c` along shadow ray `ray` to the solutions that see it:
// the real shadow ray first (real geometry), and only if that is clear the mixed shadow ray
// (virtual geometry). A virtual light exists only in the mixed scene.
void addLightSample(vec3 c, bool lightIsReal, Ray ray, uint mode, inout vec3 toMixed,
                    inout vec3 toReal) {
    if (mode == MODE_REAL) {
        if (lightIsReal && !occludedBy(params.realRoot, ray)) toReal += c;
        return;
    }
    if (occludedBy(params.realRoot, ray)) return;
    if (mode == MODE_SHARED && lightIsReal) toReal += c;
    if (!occludedBy(params.virtualRoot, ray)) toMixed += c;
}

// Shadow ray between two surface points, each offset off its surface toward the other.
Ray segmentRay(vec3 from, vec3 fromNormal, vec3 to, vec3 toNormal) {
    vec3 d = to - from;
    vec3 origin = offsetRayOrigin(from, dot(d, fromNormal) >= 0.0 ? fromNormal : -fromNormal);
    vec3 target = offsetRayOrigin(to, dot(d, toNormal) <= 0.0 ? toNormal : -toNormal);
    vec3 dir = target - origin;
    float len = length(dir);
    Ray ray;
    ray.origin = origin;
    ray.direction = len > 0.0 ? dir / len : vec3(0.0, 1.0, 0.0);
    ray.tMin = 0.0;
    ray.tMax = len > 0.0 ? len : 0.0;
    return ray;
}

Ray directionRay(vec3 from, vec3 fromNormal, vec3 dir, float tMax) {
    Ray ray;
    ray.origin = offsetRayOrigin(from, dot(dir, fromNormal) >= 0.0 ? fromNormal : -fromNormal);
    ray.direction = dir;
    ray.tMin = 0.0;
    ray.tMax = tMax;
    return ray;
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
    uvec4 word = texelFetch(textureInfoTexels, int(index));
    TextureInfo info;
    info.offset = word.x;
    info.width = word.y;
    info.height = word.z;
    info.srgb = word.w;
    vec2 p = uv * vec2(info.width, info.height) - 0.5;
    vec2 f = fract(p);
    ivec2 size = ivec2(info.width, info.height);
    ivec2 i0 = ivec2(floor(p));
    vec4 c = vec4(0.0);
    for (int dy = 0; dy < 2; ++dy) {
        PV_COUNT_LOOP_ITERATION();
        for (int dx = 0; dx < 2; ++dx) {
            PV_COUNT_LOOP_ITERATION();
            ivec2 q = (i0 + ivec2(dx, dy)) % size;
            q += size * ivec2(lessThan(q, ivec2(0)));
            float w = (dx == 1 ? f.x : 1.0 - f.x) * (dy == 1 ? f.y : 1.0 - f.y);
            c += w * unpackTexel(texelFetch(textureTexels, int(info.offset + uint(q.y * size.x + q.x))).x,
                                 info.srgb != 0u);
        }
    }
    return c;
}

struct Surface {
    vec3 position;
    vec3 geometricNormal;  // faces the side the ray came from
    vec3 shadingNormal;    // same side as geometricNormal, adapted to the ray (bsdf.h)
    vec2 uv;
    bool frontFace;        // the ray hit the side the triangle's winding faces
    uint material;
};

Surface surfaceAt(Ray ray, Hit hit) {
    Surface s;
    uvec4 tri = triangleAt(hit.triangle);
    vec3 p0 = PV_TRIANGLE_VERTEX(hit.triangle, 0u);
    vec3 p1 = PV_TRIANGLE_VERTEX(hit.triangle, 1u);
    vec3 p2 = PV_TRIANGLE_VERTEX(hit.triangle, 2u);
    float b0 = 1.0 - hit.b1 - hit.b2;
    s.position = b0 * p0 + hit.b1 * p1 + hit.b2 * p2;
    vec3 ng = cross(p1 - p0, p2 - p0);
    float len = length(ng);
    ng = len > 0.0 ? ng / len : -ray.direction;
    vec3 ns = b0 * normalAt(tri.x) + hit.b1 * normalAt(tri.y) + hit.b2 * normalAt(tri.z);
    float nsLen = length(ns);
    ns = (nsLen > 0.0 && !isnan(nsLen) && !isinf(nsLen)) ? ns / nsLen : ng;
    s.uv = b0 * uvAt(tri.x) + hit.b1 * uvAt(tri.y) + hit.b2 * uvAt(tri.z);
    s.material = tri.w;
    if (kHasTextures && materialAt(s.material).normalTexture != PV_NO_TEXTURE) {
        // Tangent frame from the triangle's uv parametrisation.
        vec2 duv1 = uvAt(tri.y) - uvAt(tri.x);
        vec2 duv2 = uvAt(tri.z) - uvAt(tri.x);
        float det = duv1.x * duv2.y - duv1.y * duv2.x;
        if (abs(det) > 0.0) {
            vec3 t = ((p1 - p0) * duv2.y - (p2 - p0) * duv1.y) / det;
            vec3 b = ((p2 - p0) * duv1.x - (p1 - p0) * duv2.x) / det;
            t = t - ns * dot(ns, t);
            float tLen = length(t);
            if (tLen > 0.0) {
                t /= tLen;
                vec3 bt = cross(ns, t) * (dot(cross(ns, t), b) < 0.0 ? -1.0 : 1.0);
                vec3 m = sampleTexture(materialAt(s.material).normalTexture, s.uv).xyz * 2.0 - 1.0;
                vec3 mapped = normalize(m.x * t + m.y * bt + m.z * ns);
                if (!any(isnan(mapped))) ns = mapped;
            }
        }
    }
    s.frontFace = dot(ray.direction, ng) < 0.0;
    s.geometricNormal = s.frontFace ? ng : -ng;
    s.shadingNormal = adaptShadingNormal(-ray.direction, s.geometricNormal,
                                         dot(ns, s.geometricNormal) < 0.0 ? -ns : ns);
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
    p.thinWalled = (m.flags & PV_MATERIAL_THIN_WALLED) != 0u;
    // A transmissive surface hit from inside sees the inverse relative IOR; opaque surfaces and
    // thin walls are shaded the same from both sides.
    p.etaRel = (s.frontFace || p.transmission == 0.0 || p.thinWalled) ? m.ior : 1.0 / m.ior;
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

// `uSet` is the vertex's PV_SET_VERTEX_BSDF set: .xy the direction, .z the lobe.
bool sampleBsdf(BsdfParams p, vec3 wo, vec4 uSet, out BsdfSample s) {
    float uLobe = uSet.z;
    vec2 u = uSet.xy;
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
        PV_COUNT_LOOP_ITERATION();
        uint mid = (lo + hi) / 2u;
        if (u < emissiveTriangleAt(mid).cdf) hi = mid; else lo = mid + 1u;
    }
    return lo;
}

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
// one light of the lights buffer (punctual or cone), each added (without the path throughput) to the solutions that see it.
void sampleDirectLight(Surface s, BsdfParams bp, Frame frame, vec3 wo, uint mode, SampleKey key,
                       uint depth, inout vec3 toMixed, inout vec3 toReal) {
    if (kHasEnv && params.envWidth > 0u) {
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
        if (kHasConeLights && type == PV_LIGHT_CONE) {
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

Ray cameraRay(uvec2 pixel, SampleKey key) {
    vec2 jitter = draw(key, PV_SET_CAMERA_JITTER).xy;
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

// Adds radiance to the solutions the path carries in `mode`, in the same order for both, so that
// where the two solutions followed the same path L_om − L_or is exactly zero.
void addRadiance(uint mode, vec3 l, inout vec3 lm, inout vec3 lr) {
    if (mode != MODE_REAL) lm += l;
    if (mode != MODE_MIXED) lr += l;
}

struct PathState {
    Ray ray;
    vec3 throughput;
    float prevPdf;
    bool prevDelta;     // the last scattering was a delta lobe (or the camera): no MIS
    vec3 prevPosition;
    // Product of the η² factors of the refractions so far: Russian roulette decides on
    // throughput·etaScale, so radiance compressed inside glass does not get paths killed (pbrt).
    float etaScale;
    uint depth;         // scattering events so far
};

// One camera sample: the mixed radiance lm (L_om), the real radiance lr (L_or), and whether the
// camera ray's first hit is virtual (the sample's mask M). Every vertex draws the dimension sets
// of its depth, so the real pass after a split draws what a real-only render would.
void tracePath(uvec2 pixel, SampleKey key, out vec3 lm, out vec3 lr, out bool firstHitVirtual) {
    PathState st;
    st.ray = cameraRay(pixel, key);
    st.throughput = vec3(1.0);
    st.prevPdf = 0.0;
    st.prevDelta = true;
    st.prevPosition = st.ray.origin;
    st.etaScale = 1.0;
    st.depth = 0u;
    lm = vec3(0.0);
    lr = vec3(0.0);
    firstHitVirtual = false;
    uint mode = kDifferential ? MODE_SHARED : MODE_MIXED;
    PathState realContinuation = st;
    bool haveRealContinuation = false;
    for (uint pass = 0u; pass < 2u; ++pass) {
        PV_COUNT_LOOP_ITERATION();
        if (pass == 1u) {
            if (!haveRealContinuation) break;
            st = realContinuation;
            mode = MODE_REAL;
        }
        for (;;) {
            PV_COUNT_LOOP_ITERATION();
            Hit hit;
            bool found = intersectScene(st.ray, mode, hit);
            bool hitVirtual = found && hit.triangle >= params.realTriangleCount;
            if (hitVirtual && st.depth == 0u) firstHitVirtual = true;
            if (hitVirtual && mode == MODE_SHARED) {
                // The solutions part here: the real one continues this ray behind the virtual
                // object (traced after the mixed part), the mixed one shades the virtual hit.
                realContinuation = st;
                haveRealContinuation = true;
                mode = MODE_MIXED;
            }
            if (!found) {
                if (kHasEnv && params.envWidth > 0u) {
                    vec3 le = params.envScale * envRadiance(st.ray.direction, params.envWidth,
                                                            params.envHeight, vec2(params.envRotationCos, params.envRotationSin));
                    float w = st.prevDelta
                                  ? 1.0
                                  : powerHeuristic(st.prevPdf,
                                                   envPdf(st.ray.direction, params.envWidth,
                                                          params.envHeight, vec2(params.envRotationCos, params.envRotationSin)));
                    addRadiance(mode, st.throughput * le * w, lm, lr);
                }
                if (kHasConeLights) {
                    // Cone lights are seen where they are (camera rays, mirrors, and the BSDF
                    // half of their multiple importance sampling).
                    for (uint i = params.coneLightFirst; i < params.lightCount; ++i) {
                        PV_COUNT_LOOP_ITERATION();
                        GpuLight light = lightAt(i);
                        float pdf = coneLightPdf(light, st.ray.direction);
                        if (!(pdf > 0.0)) continue;
                        float w = st.prevDelta ? 1.0 : powerHeuristic(st.prevPdf, pdf);
                        // Estimated lights are part of the captured (real) environment; a cone
                        // light without PV_LIGHT_REAL lights only the mixed solution.
                        vec3 l = st.throughput * light.intensity * w;
                        if ((light.type & PV_LIGHT_REAL) != 0u) addRadiance(mode, l, lm, lr);
                        else if (mode != MODE_REAL) lm += l;
                    }
                }
                break;
            }
            Surface s = surfaceAt(st.ray, hit);
            GpuMaterial m = materialAt(s.material);
            if (kHasTransmission && !s.frontFace && maxComponent(m.attenuation) > 0.0) {
                // Beer–Lambert (KHR_materials_volume): the segment just travelled ran inside
                // this material's volume, from where the path entered it to this back face.
                st.throughput *= exp(-m.attenuation * hit.t);
            }
            if (kHasEmissive && maxComponent(m.emission) > 0.0 && emitsToward(m, s.frontFace)) {
                float w = st.prevDelta ? 1.0
                                       : powerHeuristic(st.prevPdf,
                                                        emissiveLightPdf(hit.triangle,
                                                                         st.prevPosition, s));
                addRadiance(mode, st.throughput * emittedRadiance(m, s.uv) * w, lm, lr);
            }
            if (st.depth >= params.maxDepth) break;

            Frame frame;
            frame.n = s.shadingNormal;
            buildBasis(frame.n, frame.t, frame.b);
            vec3 wo = toLocal(frame, -st.ray.direction);
            BsdfParams bp = bsdfParamsAt(m, s);
            // Light sampling only where some lobe is not a delta (a smooth mirror or glass
            // can only see lights through its one reflected or refracted ray).
            if (!(kHasSpecular || kHasTransmission) || !bsdfIsDelta(bp) ||
                bsdfLobeProbabilities(bp, wo).z > 0.0) {
                vec3 directMixed = vec3(0.0);
                vec3 directReal = vec3(0.0);
                sampleDirectLight(s, bp, frame, wo, mode, key, st.depth, directMixed, directReal);
                if (mode != MODE_REAL) lm += st.throughput * directMixed;
                if (mode != MODE_MIXED) lr += st.throughput * directReal;
            }

            BsdfSample bs;
            vec4 uBsdf = draw(key, vertexSet(st.depth, PV_SET_VERTEX_BSDF));
            if (!sampleBsdf(bp, wo, uBsdf, bs)) break;
            vec3 wi = toWorld(frame, bs.wi);
            if (!consistentSide(s, wi, bs.wi)) {
                // The adapted normal keeps every mirror direction above the surface; a smooth
                // refraction leaving at grazing angles can still point back into its facet. A
                // delta direction is moved to the nearest one on its promised side (its weight
                // stays exact); a sampled non-delta direction would break its pdf, so it ends.
                if (!bs.isDelta) break;
                wi = nearestDirectionOnSide(wi, s.geometricNormal, bs.wi.z > 0.0 ? 1.0 : -1.0);
            }
            st.throughput *= bs.weight;
            if (bs.lobe == PV_LOBE_TRANSMISSION && !bp.thinWalled)
                st.etaScale *= bp.etaRel * bp.etaRel;
            st.prevPdf = bs.pdf;
            st.prevDelta = bs.isDelta;
            st.prevPosition = s.position;
            st.ray = directionRay(s.position, s.geometricNormal * (bs.wi.z > 0.0 ? 1.0 : -1.0),
                                  wi, PV_FLOAT_MAX);
            st.depth += 1u;
            if (st.depth >= params.rouletteStartDepth) {
                // Russian roulette: unbiased, keeps paths whose throughput is still large.
                float pContinue = min(1.0, maxComponent(st.throughput) * st.etaScale);
                if (uBsdf.w >= pContinue) break;
                st.throughput /= pContinue;
            }
        }
    }
}

// Kahan-compensated sum (`precise` forbids the compiler from reassociating it away).
void kahanAdd(inout vec4 sum, inout vec4 c, vec4 x) {
    precise vec4 y = x - c;
    precise vec4 t = sum + y;
    precise vec4 newC = (t - sum) - y;
    c = newC;
    sum = t;
}

void main() {
    uvec2 pixel = gl_GlobalInvocationID.xy;
    if (pixel.x >= params.width || pixel.y >= params.height) return;
    uint pixelIndex = pixel.y * params.width + pixel.x;
    // Compensated sums, within the dispatch and across dispatches: the mean stays exact over
    // millions of samples in 32-bit floats (the paper's running average, Eq. 3, drifts).
    vec4 sum[PV_ACCUM_COUNT];
    vec4 comp[PV_ACCUM_COUNT];
    for (uint k = 0u; k < PV_ACCUM_COUNT; ++k) {
        PV_COUNT_LOOP_ITERATION();
        sum[k] = vec4(0.0);
        comp[k] = vec4(0.0);
    }
    for (uint i = 0u; i < params.samplesPerDispatch; ++i) {
        PV_COUNT_LOOP_ITERATION();
        SampleKey key = makeSampleKey(pixelIndex, params.sampleBase + i, params.seed);
        vec3 lm;
        vec3 lr;
        bool firstHitVirtual;
        tracePath(pixel, key, lm, lr, firstHitVirtual);
        if (any(isnan(lm)) || any(isinf(lm)) || any(isnan(lr)) || any(isinf(lr))) {
            // Counted, and the host reports it: never silently part of the image.
            atomicAdd(stats.nonFiniteSamples, 1u);
            continue;
        }
        if (params.fireflyClamp > 0.0) {
            // One factor for both solutions, so their difference stays consistent.
            float lum = max(luminance(lm), luminance(lr));
            if (lum > params.fireflyClamp) {
                lm *= params.fireflyClamp / lum;
                lr *= params.fireflyClamp / lum;
            }
        }
        float mask = firstHitVirtual ? 1.0 : 0.0;
        // Eq. 1 per sample, without the plate term (1 − M)·L_oc, which the host adds from the
        // mean mask: where both solutions followed the same path lm − lr is exactly 0.
        vec3 composite = firstHitVirtual ? lm : lm - lr;
        kahanAdd(sum[PV_ACCUM_COMPOSITE], comp[PV_ACCUM_COMPOSITE], vec4(composite, mask));
        kahanAdd(sum[PV_ACCUM_MIXED], comp[PV_ACCUM_MIXED], vec4(lm, 0.0));
        if (kDifferential) kahanAdd(sum[PV_ACCUM_REAL], comp[PV_ACCUM_REAL], vec4(lr, 0.0));
    }
    atomicAdd(stats.raysTraced, gRaysTraced);
    for (uint k = 0u; k < PV_ACCUM_COUNT; ++k) {
        PV_COUNT_LOOP_ITERATION();
        uint at = pixelIndex * PV_ACCUM_COUNT + k;
        vec4 total = accumSum[at];
        vec4 c = accumCompensation[at];
        kahanAdd(total, c, sum[k] - comp[k]);
        accumSum[at] = total;
        accumCompensation[at] = c;
    }
    // The renderer sizes later dispatches from this (lavapipe's loop budget).
    if (kCountLoops) atomicMax(stats.maxLoopIterations, gLoopIterations);
}
