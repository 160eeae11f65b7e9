#pragma once

// What a material's parameters say about its BSDF, for choosing the code a scene needs.

#include "scene/scene.h"

namespace previs {

// Neither Lambertian (no metal, specular layer or transmission: f = baseColor/π whatever the
// textures, which only scale metalness) nor purely specular on every texel (textures only lower
// the roughness, but may lower a metal's metalness). Errs on the side of yes: with none in the
// scene, BSDF evaluations are Lambert's and the photon gather evaluates none per photon
// (PV_SPEC_HAS_GLOSSY).
bool glossyMaterial(const Material& m);

}  // namespace previs
