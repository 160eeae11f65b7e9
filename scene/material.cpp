#include "scene/material.h"

#include "gpu/shaders/shared/bsdf.h"

namespace previs {

bool glossyMaterial(const Material& m) {
    const bool lambertian = m.metallic <= 0.0f && m.specular <= 0.0f && m.transmission <= 0.0f;
    const bool smooth = m.roughness * m.roughness < PV_DELTA_ALPHA;
    const bool purelySpecular = smooth && (m.transmission >= 1.0f ||
                                           (m.metallic >= 1.0f && m.metallicRoughnessTexture < 0));
    return !lambertian && !purelySpecular;
}

}  // namespace previs
