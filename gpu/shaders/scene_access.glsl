// Scene access shared by the compute shaders that trace rays through the scene (trace_paths,
// trace_photons): the specialisation constants of scene features, the scene's bindings and their
// texel loaders, ray casting against the real and virtual BVHs, surface interaction and the
// material's BSDF. GLSL only; the including shader declares its own workgroup size and outputs.

// Loop iterations this invocation ran, all loops together (shared/prelude.h says why); counted
// only where kCountLoops (a CPU device).
uint gLoopIterations = 0u;
#define PV_COUNT_LOOP_ITERATION() (kCountLoops ? ++gLoopIterations : 0u)
#include "gpu/shaders/shared/scene_types.h"
#include "gpu/shaders/shared/texture_sampling.h"
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
// Caustics from the photon map (shared/photon_records.h).
layout(constant_id = PV_SPEC_PHOTONS) const bool kPhotons = true;
// Some material is neither Lambertian nor purely specular (else evaluateBsdf is Lambert's, and
// photon gathers apply baseColor/π once).
layout(constant_id = PV_SPEC_HAS_GLOSSY) const bool kHasGlossy = true;
// The host allows splatting the photons the camera sees directly (scene_types.h).
layout(constant_id = PV_SPEC_PHOTON_SPLAT) const bool kPhotonSplat = true;

layout(binding = PV_BINDING_PARAMS, scalar) readonly buffer ParamsBuffer { FrameParams paramsBuffer; };
// The including shader's main() copies the parameters here before any branch: llvmpipe loads a
// storage-buffer value once for all lanes only outside control flow (inside a branch or loop
// it loops over the active lanes), and a uniform or push-constant block would make lavapipe
// recompile the shader whenever a value a branch depends on changes (BENCHMARKS.md).
FrameParams params;

// The photon pass splats the light the camera sees directly, and the camera path does not gather
// at its first vertex: only through a pinhole, whose pixels light tracing projects onto exactly
// (a thin lens's aperture or a calibrated lens grid keep the gather there).
bool photonSplatsActive() {
    return kPhotons && kPhotonSplat && !kHasLensGrid &&
           !(kHasThinLens && params.apertureRadiusM > 0.0) && params.objectSamples == 0u;
}

// The first of the PV_SPLAT_WORDS words of sum `sum` (PV_SPLAT_*) of pixel `pixelIndex` in the
// splat buffer (scene_types.h): the photon pass writes there, the camera pass reads.
uint splatWord(uint sum, uint pixelIndex) {
    return (sum * params.width * params.height + pixelIndex) * PV_SPLAT_WORDS;
}

// RGB in 32.32 fixed point, the photon gather's and splats' sums: integer additions give the
// same total in any order. Values are clamped to [0, 2^31).
struct FixedRgb {
    uvec3 whole;
    uvec3 fraction;
};

FixedRgb fixedFromValue(vec3 v) {
    v = clamp(v, vec3(0.0), vec3(2147483520.0));
    vec3 w = floor(v);
    return FixedRgb(uvec3(w), uvec3((v - w) * 4294967296.0));
}

vec3 fixedValue(FixedRgb sum) { return vec3(sum.whole) + vec3(sum.fraction) * 2.3283064365386963e-10; }
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
#include "gpu/shaders/shared/specular_albedo.h"
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
#define PV_BVH_NODE(i) loadBvhNode(i)
#define PV_BVH_NODE_CHILDREN(i) texelFetch(bvhNodeTexels, int(7u * (i) + 6u))
#define PV_TRIANGLE_VERTEX(i, k) \
    uintBitsToFloat(texelFetch(triangleVertexTexels, int(3u * (i) + (k))).xyz)
#include "gpu/shaders/shared/ray_tracing.h"

#define PV_ENV_RADIANCE(i) envRadianceAt(i)
#define PV_ENV_MARGINAL_CDF(i) wordAsFloat(envMarginalWords, i)
#define PV_ENV_CONDITIONAL_CDF(i) wordAsFloat(envConditionalWords, i)
#include "gpu/shaders/shared/env_sampling.h"

#include "gpu/shaders/shared/bsdf.h"
#include "gpu/shaders/shared/sampling.h"
#include "gpu/shaders/shared/sampler.h"
#include "gpu/shaders/shared/triangle_light.h"
#define NO_HIT 0xffffffffu

// Rays this invocation traced, added to stats.raysTraced once at the end (one atomic per pixel).
uint gRaysTraced = 0u;
// Rays with a NaN or infinite origin or direction (a NaN material parameter, say), culled
// before traversal; a camera sample that cast one is dropped (trace_paths.comp).
uint gNonFiniteRays = 0u;

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
    if (!rayIsFinite(ray.origin, ray.direction)) {
        ++gNonFiniteRays;
        return false;
    }
    return traceClosest(params.realRoot, mode != MODE_REAL ? params.virtualRoot : PV_BVH_NO_ROOT,
                        ray, hit);
}

// What blocks a shadow ray: OCCLUDER_NONE, OCCLUDER_REAL (real geometry, which blocks both
// solutions) or OCCLUDER_VIRTUAL (only virtual geometry: the real solution sees the light).
// Real rays test the phantoms only.
#define OCCLUDER_NONE 0u
#define OCCLUDER_REAL 1u
#define OCCLUDER_VIRTUAL 2u
uint occluder(Ray ray, uint mode) {
    ++gRaysTraced;
    if (!rayIsFinite(ray.origin, ray.direction)) {
        ++gNonFiniteRays;
        return OCCLUDER_REAL;  // no light through it; its sample is dropped anyway
    }
    uint blocker = traceAny(params.realRoot,
                            mode != MODE_REAL ? params.virtualRoot : PV_BVH_NO_ROOT, ray);
    if (blocker == PV_BVH_NO_TRIANGLE) return OCCLUDER_NONE;
    return blocker < params.realTriangleCount ? OCCLUDER_REAL : OCCLUDER_VIRTUAL;
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

// The glTF sampler's wrap modes and filter (shared/texture_sampling.h); sRGB decoded before
// filtering.
vec4 sampleTexture(uint index, vec2 uv) {
    uvec4 word = texelFetch(textureInfoTexels, int(index));
    uint offset = word.x;
    ivec2 size = ivec2(word.y, word.z);
    uint flags = word.w;
    bool srgb = (flags & PV_TEXTURE_SRGB) != 0u;
    uint wrapS = (flags >> PV_TEXTURE_WRAP_S_SHIFT) & 3u;
    uint wrapT = (flags >> PV_TEXTURE_WRAP_T_SHIFT) & 3u;
    if ((flags & PV_TEXTURE_NEAREST) != 0u) {
        ivec2 q = ivec2(nearestTexel(uv.x, size.x, wrapS), nearestTexel(uv.y, size.y, wrapT));
        return unpackTexel(texelFetch(textureTexels, int(offset + uint(q.y * size.x + q.x))).x,
                           srgb);
    }
    ivec2 i0;
    ivec2 i1;
    vec2 f;
    linearTexels(uv.x, size.x, wrapS, i0.x, i1.x, f.x);
    linearTexels(uv.y, size.y, wrapT, i0.y, i1.y, f.y);
    vec4 c = vec4(0.0);
    for (int dy = 0; dy < 2; ++dy) {
        PV_COUNT_LOOP_ITERATION();
        for (int dx = 0; dx < 2; ++dx) {
            PV_COUNT_LOOP_ITERATION();
            ivec2 q = ivec2(dx == 1 ? i1.x : i0.x, dy == 1 ? i1.y : i0.y);
            float w = (dx == 1 ? f.x : 1.0 - f.x) * (dy == 1 ? f.y : 1.0 - f.y);
            c += w * unpackTexel(texelFetch(textureTexels, int(offset + uint(q.y * size.x + q.x))).x,
                                 srgb);
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

// f(wo, wi) and its sampling pdf. A scene of Lambertian materials only runs the first branch;
// one of Lambertian and purely specular materials (a mirror or smooth glass among diffuse
// surfaces) the second: bsdfEvaluate's diffuse term, or nothing at a delta vertex.
vec3 evaluateBsdf(BsdfParams p, vec3 wo, vec3 wi, out float pdf) {
    if (!kHasSpecular && !kHasTransmission) {
        pdf = wi.z > 0.0 ? wi.z * PV_INV_PI : 0.0;
        return wi.z > 0.0 ? p.baseColor * PV_INV_PI : vec3(0.0);
    }
    if (!kHasGlossy) {
        bool diffuse = !bsdfIsPurelySpecular(p) && wo.z >= PV_MIN_COSINE && wi.z >= PV_MIN_COSINE;
        pdf = diffuse ? wi.z * PV_INV_PI : 0.0;
        return diffuse ? p.baseColor * PV_INV_PI : vec3(0.0);
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
    // The exit test at the end, as in PV_ENV_SEARCH_CDF (shared/env_sampling.h).
    if (lo < hi) {
        for (;;) {
            PV_COUNT_LOOP_ITERATION();
            uint mid = (lo + hi) / 2u;
            if (u < emissiveTriangleAt(mid).cdf) hi = mid; else lo = mid + 1u;
            if (lo >= hi) break;
        }
    }
    return lo;
}
