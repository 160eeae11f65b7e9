// Sampling a point on an emissive triangle as seen from a shading point, and the solid-angle
// density of that choice: uniform in the solid angle the triangle subtends (Arvo 1995,
// "Stratified Sampling of Spherical Triangles"), or uniform in area where the spherical triangle
// is too small for float precision. The sampler and the pdf that
// multiple importance sampling evaluates for a BSDF-sampled hit make the same choice from the
// same inputs, so the two strategies' densities agree exactly.
#ifndef PREVIS_SHARED_TRIANGLE_LIGHT_H
#define PREVIS_SHARED_TRIANGLE_LIGHT_H

#include "gpu/shaders/shared/prelude.h"
#include "gpu/shaders/shared/sampling.h"

PV_BEGIN

// Spherical sampling runs above this solid angle (steradians); below it, area sampling. Arvo's
// inversion as written in the paper finds the arc b' from cos b' = q ≈ 1 − b'²/2 and forms u, v
// and q as O(Â) differences of O(1) terms, so in float a triangle's samples drift measurably
// from uniform below ~5e-4 sr (chi-square, 4M samples); with those differences rewritten
// (sampleSphericalTriangle) they stay uniform down to 1e-8 sr and fail at 1.3e-9 sr. 1e-6 sr
// keeps two decades of margin; a 0.2 m quad is that small only from ~140 m, where area
// sampling is as good (its density varies by under 0.3% across the triangle). There is no upper
// bound: the sampler stays uniform up to 2π − 0.001 sr (a point almost in the plane of a
// large emitter), exactly where area sampling's variance is worst.
#define PV_SPHERICAL_MIN_SOLID_ANGLE 1e-6f

// Solid angle of triangle (p0, p1, p2) seen from p (Van Oosterom & Strackee 1983):
// tan(Ω/2) = |d0·(d1×d2)| / (l0 l1 l2 + (d0·d1) l2 + (d0·d2) l1 + (d1·d2) l0), di = pi − p,
// li = |di|. The triple product is taken as d0·(e1×e2) with the triangle's own edges, which
// equals it exactly and has no cancellation for a small or distant triangle.
PV_INLINE float triangleSolidAngle(vec3 p, vec3 p0, vec3 p1, vec3 p2) {
    vec3 d0 = p0 - p;
    vec3 d1 = p1 - p;
    vec3 d2 = p2 - p;
    float l0 = length(d0);
    float l1 = length(d1);
    float l2 = length(d2);
    float num = abs(dot(d0, cross(p1 - p0, p2 - p0)));
    float den = l0 * l1 * l2 + dot(d0, d1) * l2 + dot(d0, d2) * l1 + dot(d1, d2) * l0;
    return 2.0f * atan(num, den);
}

// The solid angle over which the triangle is sampled uniformly from p, or 0 where it is sampled
// by area. Area sampling is kept where the triangle is small against its distance: where its
// longest edge is shorter than p's distance to its plane (Cycles' criterion), r² and the
// emitter's cosine vary little across it, so area sampling's density is already close to
// uniform in solid angle and the spherical construction (three transcendentals more, here and
// in the MIS pdf) would cost time for no less noise; it is also kept below the precision
// threshold, and where the solid angle is not finite.
PV_INLINE float sphericalSamplingSolidAngle(vec3 p, vec3 p0, vec3 p1, vec3 p2) {
    vec3 e1 = p1 - p0;
    vec3 e2 = p2 - p0;
    vec3 e3 = p2 - p1;
    vec3 n = cross(e1, e2);
    float planeDistance = dot(p0 - p, n);  // × |n|
    float longestEdge2 = max(dot(e1, e1), max(dot(e2, e2), dot(e3, e3)));
    if (!(longestEdge2 * dot(n, n) > planeDistance * planeDistance)) return 0.0f;
    float omega = triangleSolidAngle(p, p0, p1, p2);
    return omega >= PV_SPHERICAL_MIN_SOLID_ANGLE && omega <= PV_TWO_PI ? omega : 0.0f;
}

// The component of v orthogonal to unit vector n, normalised (0 if v is parallel to n).
PV_INLINE vec3 orthogonalUnit(vec3 v, vec3 n) {
    vec3 o = v - dot(v, n) * n;
    float len = length(o);
    return len > 0.0f ? o / len : vec3(0.0f);
}

// A direction uniform in the spherical triangle of unit vectors (a, b, c) whose area is
// `solidAngle` (Arvo 1995, §2). u.x chooses the area Â = u.x·Ω of the sub-triangle A B C' with
// C' on arc AC, u.y the point on arc B C' at cos θ = 1 − u.y(1 − B·C'). `edgeAc` is any vector
// along the triangle's edge from A's vertex to C's (its component orthogonal to a points from A
// toward C on the sphere without the cancellation of c − (c·a)a for a small triangle).
PV_INLINE vec3 sampleSphericalTriangle(vec3 a, vec3 b, vec3 c, vec3 edgeAc, float solidAngle,
                                       vec2 u) {
    // Angle α at A, between the great circles AB and AC.
    vec3 nAb = cross(a, b);
    vec3 nAc = cross(a, c);
    float lenAb = length(nAb);
    float lenAc = length(nAc);
    if (!(lenAb > 0.0f) || !(lenAc > 0.0f)) return a;
    nAb /= lenAb;
    nAc /= lenAc;
    float cosAlpha = clamp(dot(nAb, nAc), -1.0f, 1.0f);
    float sinAlpha = length(cross(nAb, nAc));
    // Arvo's s = sin(Â − α), t = cos(Â − α), u = t − cos α, v = s + sin α cos c (c the arc AB)
    // and q = cos b' of the arc from A to C', q = ((v t − u s) cos α − v) / ((v s + u t) sin α).
    // For a small triangle u, v and 1 − q are O(Â) differences of O(1) terms, so they are
    // rewritten by angle-sum identities: u = 2 sin(Â/2) sin(α − Â/2),
    // v = 2 sin(Â/2) cos(Â/2 − α) − sin α (1 − cos c) with 1 − cos c = |a − b|²/2, and
    // 1 − q = (v (1 − cos Â) + u sin Â) / ((v s + u t) sin α).
    float halfArea = 0.5f * u.x * solidAngle;
    float sh = sin(halfArea);
    float ch = cos(halfArea);
    float sinArea = 2.0f * sh * ch;
    float oneMinusCosArea = 2.0f * sh * sh;
    float s = sinArea * cosAlpha - (1.0f - oneMinusCosArea) * sinAlpha;
    float t = (1.0f - oneMinusCosArea) * cosAlpha + sinArea * sinAlpha;
    float uu = 2.0f * sh * (sinAlpha * ch - cosAlpha * sh);
    vec3 ab = a - b;
    float v = 2.0f * sh * (ch * cosAlpha + sh * sinAlpha) - sinAlpha * 0.5f * dot(ab, ab);
    float den = (v * s + uu * t) * sinAlpha;
    float oneMinusQ =
        den != 0.0f ? clamp((v * oneMinusCosArea + uu * sinArea) / den, 0.0f, 2.0f) : 0.0f;
    float sinB = sqrt(max(0.0f, oneMinusQ * (2.0f - oneMinusQ)));
    vec3 cHat = (1.0f - oneMinusQ) * a + sinB * orthogonalUnit(edgeAc, a);
    // 1 − cos θ of arc B C' as |C' − b|²/2, exact for unit vectors and free of cancellation.
    vec3 bc = cHat - b;
    float oneMinusCos = u.y * 0.5f * dot(bc, bc);
    float cosTheta = 1.0f - oneMinusCos;
    float sinTheta = sqrt(max(0.0f, oneMinusCos * (2.0f - oneMinusCos)));
    return cosTheta * b + sinTheta * orthogonalUnit(bc, b);
}

// Barycentrics (b1, b2) of vertices 1 and 2 where the ray from p along w meets the plane of the
// triangle (Möller & Trumbore 1997), clamped onto the triangle: a direction sampled inside the
// spherical triangle can land a rounding error outside it.
PV_INLINE vec2 triangleBarycentricsAlong(vec3 p, vec3 w, vec3 p0, vec3 p1, vec3 p2) {
    vec3 e1 = p1 - p0;
    vec3 e2 = p2 - p0;
    vec3 s1 = cross(w, e2);
    float div = dot(s1, e1);
    if (div == 0.0f) return vec2(1.0f / 3.0f);
    vec3 sv = p - p0;
    float b1 = max(0.0f, dot(sv, s1) / div);
    float b2 = max(0.0f, dot(w, cross(sv, e1)) / div);
    float sum = b1 + b2;
    if (sum > 1.0f) {
        b1 /= sum;
        b2 /= sum;
    }
    return vec2(b1, b2);
}

// Solid-angle density of light point q on triangle (p0, p1, p2), seen from p, given the
// triangle was chosen: 1/Ω where the triangle is sampled by solid angle (`spherical` and
// sphericalSamplingSolidAngle > 0), else area sampling's dist² / (area |cos θ_light|).
PV_INLINE float triangleLightDirectionPdf(vec3 p, vec3 p0, vec3 p1, vec3 p2, vec3 q,
                                          bool spherical) {
    float omega = spherical ? sphericalSamplingSolidAngle(p, p0, p1, p2) : 0.0f;
    if (omega > 0.0f) return 1.0f / omega;
    vec3 n = cross(p1 - p0, p2 - p0);
    float twiceArea = length(n);
    vec3 d = q - p;
    float dist2 = dot(d, d);
    float cosLight = abs(dot(d, n)) / (sqrt(dist2) * twiceArea);
    if (!(twiceArea > 0.0f) || !(cosLight > 0.0f) || !(dist2 > 0.0f)) return 0.0f;
    return dist2 / (0.5f * twiceArea * cosLight);
}

// Barycentrics (b1, b2) of a point on triangle (p0, p1, p2) uniform in the solid angle `omega`
// (triangleSolidAngle) it subtends from p.
PV_INLINE vec2 sampleSphericalTriangleLight(vec3 p, vec3 p0, vec3 p1, vec3 p2, float omega,
                                            vec2 u) {
    vec3 a = normalize(p0 - p);
    vec3 b = normalize(p1 - p);
    vec3 c = normalize(p2 - p);
    vec3 w = sampleSphericalTriangle(a, b, c, p2 - p0, omega, u);
    return triangleBarycentricsAlong(p, w, p0, p1, p2);
}

// Barycentrics (b1, b2) of a point on triangle (p0, p1, p2) sampled from p with u, and in `pdf`
// its solid-angle density given the triangle (as triangleLightDirectionPdf), 0 if none.
// `spherical` off: area sampling only (the ablation baseline).
PV_INLINE vec2 sampleTriangleLight(vec3 p, vec3 p0, vec3 p1, vec3 p2, vec2 u, bool spherical,
                                   PV_OUT(float) pdf) {
    float omega = spherical ? sphericalSamplingSolidAngle(p, p0, p1, p2) : 0.0f;
    if (omega > 0.0f) {
        pdf = 1.0f / omega;
        return sampleSphericalTriangleLight(p, p0, p1, p2, omega, u);
    }
    vec2 bary = sampleUniformTriangle(u);
    vec3 q = (1.0f - bary.x - bary.y) * p0 + bary.x * p1 + bary.y * p2;
    pdf = triangleLightDirectionPdf(p, p0, p1, p2, q, false);
    return bary;
}

PV_END

#endif
