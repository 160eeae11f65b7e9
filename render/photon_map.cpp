#include "render/photon_map.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "gpu/shaders/shared/bsdf.h"
#include "gpu/shaders/shared/photon_records.h"
#include "gpu/shaders/shared/sampling.h"
#include "photon_grid.spv.h"
#include "trace_photons.spv.h"

namespace previs {

namespace {

constexpr float kPi = 3.14159265358979f;

// photon_grid.comp's stages (its constant_id 0) and workgroup sizes (constant_id 1).
enum GridStage : uint32_t {
    kHistogram = 0,
    kScan = 1,
    kScatter = 2,
    kCells = 3,
    kCompactScan = 4,
    kCompact = 5,
};

// Solid angle of the aim sphere seen from p (the whole sphere of directions from inside).
float aimSolidAngle(const PhotonAim& aim, const glm::vec3& p) {
    float d2 = glm::dot(aim.center - p, aim.center - p);
    float r2 = aim.radius * aim.radius;
    if (d2 <= r2) return 4.0f * kPi;
    float sin2 = r2 / d2;
    return 2.0f * kPi * sin2 / (1.0f + std::sqrt(std::max(0.0f, 1.0f - sin2)));
}

uint32_t bits(float f) {
    uint32_t u;
    std::memcpy(&u, &f, sizeof(u));
    return u;
}

}  // namespace

float defaultPhotonRadius(float aimRadius, uint32_t photonsPerIteration) {
    const double scale =
        std::sqrt(double(kDefaultRadiusPhotons) / double(std::max(photonsPerIteration, 1u)));
    return float(double(kDefaultRadiusFraction) * aimRadius * scale);
}

bool mayCarryCaustics(const Material& m) {
    // shader::bsdfCarriesCaustics: alpha = roughness² below PV_CAUSTIC_ALPHA, and no diffuse
    // base. Textures scale roughness, metalness and base colour, so a textured factor may reach it.
    bool smooth = m.roughness * m.roughness < PV_CAUSTIC_ALPHA || m.metallicRoughnessTexture >= 0;
    float base = std::max({m.baseColor.r, m.baseColor.g, m.baseColor.b});
    bool noDiffuse =
        m.metallic >= 1.0f || m.transmission >= 1.0f || base <= 0.0f || m.baseColorTexture >= 0;
    return smooth && noDiffuse;
}

PhotonAim photonAimFor(const Geometry& g, std::span<const Material> materials) {
    PhotonAim aim;
    glm::vec3 lo(INFINITY), hi(-INFINITY), sceneLo(INFINITY), sceneHi(-INFINITY);
    auto isSpecular = [&](size_t t) {
        uint32_t mat = g.triangleMaterials[t];
        return mat < materials.size() && mayCarryCaustics(materials[mat]);
    };
    for (size_t t = 0; t < g.triangles.size(); ++t) {
        bool specular = isSpecular(t);
        for (int k = 0; k < 3; ++k) {
            const glm::vec3& p = g.positions[g.triangles[t][k]];
            sceneLo = glm::min(sceneLo, p);
            sceneHi = glm::max(sceneHi, p);
            if (!specular) continue;
            lo = glm::min(lo, p);
            hi = glm::max(hi, p);
            aim.any = true;
        }
    }
    if (!aim.any) {
        if (g.triangles.empty()) return aim;
        lo = sceneLo;  // photons forced on without a specular object: aim at everything
        hi = sceneHi;
    }
    aim.center = 0.5f * (lo + hi);
    // The farthest aimed vertex bounds every aimed triangle (a triangle is the convex hull of its
    // vertices). For a ball that is its radius, where the box's half-diagonal is √3 times it and
    // would spend two thirds of the photons beside the ball. A little margin: the triangles are
    // in float, so are the photons' rays.
    float farthest2 = 0.0f;
    for (size_t t = 0; t < g.triangles.size(); ++t) {
        if (aim.any && !isSpecular(t)) continue;
        for (int k = 0; k < 3; ++k) {
            glm::vec3 d = g.positions[g.triangles[t][k]] - aim.center;
            farthest2 = std::max(farthest2, glm::dot(d, d));
        }
    }
    aim.radius = std::max(std::sqrt(farthest2) * 1.001f, 1e-6f);
    float scene = 0.0f;
    for (int c = 0; c < 8; ++c) {
        glm::vec3 corner((c & 1) ? sceneHi.x : sceneLo.x, (c & 2) ? sceneHi.y : sceneLo.y,
                         (c & 4) ? sceneHi.z : sceneLo.z);
        scene = std::max(scene, glm::length(corner - aim.center));
    }
    aim.sceneRadius = (std::max(scene, aim.radius) + 1e-3f) * 1.01f;
    return aim;
}

double environmentPhotonLuminance(const EnvironmentMap& map, const EnvironmentDistribution& dist) {
    // ∫ Le dω = 2π² ∫∫ L sin θ du dv (EnvironmentDistribution::integral); the mean over 4π.
    const double power = 2.0 * double(kPi) * double(kPi) * double(dist.integral);
    const double mean = power / (4.0 * double(kPi));
    if (!(power > 0.0) || !std::isfinite(power) ||
        dist.peakLuminance < kEnvironmentLampRatio * mean)
        return 0.0;
    return power * map.scale;
}

std::vector<glm::uvec4> buildPhotonLights(const PhotonAim& aim,
                                          std::span<const EmissivePhotonSource> emissive,
                                          std::span<const shader::GpuLight> lights,
                                          double environmentLuminance) {
    std::vector<glm::uvec4> table;
    std::vector<double> weight;
    const double crossSection = kPi * double(aim.radius) * aim.radius;
    if (environmentLuminance > 0.0 && std::isfinite(environmentLuminance)) {
        // As a distant light over the aim's disk: Φ = ∫ Le dω · π R². The captured environment
        // is real.
        table.emplace_back(PV_PHOTON_LIGHT_ENVIRONMENT | PV_PHOTON_LIGHT_REAL, 0u, 0u, 0u);
        weight.push_back(environmentLuminance * crossSection);
    }
    for (const EmissivePhotonSource& e : emissive) {
        // Flux toward the aim ≈ L · area · Ω (the cosine left out: any positive weight is
        // unbiased, the photon's power divides by the actual probability).
        double w = double(e.luminance) * e.area * aimSolidAngle(aim, e.centroid);
        if (!(w > 0.0)) continue;
        table.emplace_back(PV_PHOTON_LIGHT_TRIANGLE | (e.real ? PV_PHOTON_LIGHT_REAL : 0u),
                           e.triangle, 0u, 0u);
        weight.push_back(w);
    }
    for (uint32_t i = 0; i < lights.size(); ++i) {
        const shader::GpuLight& l = lights[i];
        double lum = shader::luminance(l.intensity);
        uint32_t type = l.type & PV_LIGHT_TYPE_MASK;
        double w = type == PV_LIGHT_DIRECTIONAL ? lum * crossSection
                   : type == PV_LIGHT_CONE      ? lum * 2.0 * kPi * l.cosInnerCone * crossSection
                                                : lum * aimSolidAngle(aim, l.position);
        if (!(w > 0.0) || !std::isfinite(w)) continue;
        table.emplace_back(
            PV_PHOTON_LIGHT_PUNCTUAL | ((l.type & PV_LIGHT_REAL) ? PV_PHOTON_LIGHT_REAL : 0u), i,
            0u, 0u);
        weight.push_back(w);
    }
    double total = 0.0;
    for (double w : weight) total += w;
    double running = 0.0;
    for (size_t k = 0; k < table.size(); ++k) {
        running += weight[k];
        table[k].z = bits(k + 1 == table.size() ? 1.0f : float(running / total));
        table[k].w = bits(float(weight[k] / total));
    }
    return table;
}

size_t photonBufferBytes(int binding, uint32_t photons) {
    const size_t records = size_t(PV_PHOTON_RECORDS_PER_PHOTON) * photons;
    switch (binding) {
        case PV_BINDING_PHOTON_RECORDS:
        case PV_BINDING_PHOTON_SORTED:
            return records * sizeof(shader::PhotonRecord);
        case PV_BINDING_PHOTON_SORT_A:
        case PV_BINDING_PHOTON_SORT_B:
            return records * sizeof(glm::uvec2);
        case PV_BINDING_PHOTON_BLOCK_COUNTS:
            return size_t(PV_PHOTON_SORT_DIGITS) * (records / PV_PHOTON_SORT_BLOCK) *
                   sizeof(uint32_t);
        case PV_BINDING_PHOTON_CELLS:
            // Whole texels of two ranges (the gather reads them as uvec4).
            return photons ? size_t(PV_PHOTON_BUCKETS + 1u) / 2u * 2u * sizeof(glm::uvec2) : 0;
        default:
            return 0;
    }
}

Result<PhotonPasses> PhotonPasses::create(GpuContext& ctx, std::span<const BindingKind> bindings,
                                          std::span<const uint32_t> sceneConstants,
                                          Specialise specialise) {
    PhotonPasses p;
    static_assert(std::tuple_size_v<decltype(p.grid_)> + 1 == kPipelineCount);
    auto trace = ComputePipeline::create(
        ctx, std::span<const uint32_t>(trace_photons_spv, sizeof(trace_photons_spv) / 4), bindings,
        sceneConstants, "trace_photons", specialise);
    if (!trace) return trace.error();
    p.trace_.emplace(std::move(trace.value()));
    std::vector<BindingKind> storage(PV_BINDING_COUNT, BindingKind::StorageBuffer);
    for (uint32_t stage : {kHistogram, kScan, kScatter, kCells, kCompactScan, kCompact}) {
        // Workgroup size: the scan's one group; one invocation a block for the histogram and
        // the scatter (photon_grid.comp); a block's worth for the rest.
        const uint32_t groupSize = stage == kScan || stage == kCompactScan ? PV_PHOTON_SCAN_GROUP
                                   : stage == kHistogram || stage == kScatter
                                       ? 1u
                                       : PV_PHOTON_SORT_BLOCK;
        std::array<uint32_t, 2> constants{stage, groupSize};
        auto grid = ComputePipeline::create(
            ctx, std::span<const uint32_t>(photon_grid_spv, sizeof(photon_grid_spv) / 4), storage,
            constants, "photon_grid", specialise);
        if (!grid) return grid.error();
        p.grid_[stage].emplace(std::move(grid.value()));
    }
    return p;
}

Status PhotonPasses::bind(std::span<const GpuBuffer* const> buffers,
                          std::span<const BufferRange> ranges) {
    if (Status s = trace_->bind(buffers, ranges); !s) return s;
    for (auto& g : grid_)
        if (Status s = g->bind(buffers, ranges); !s) return s;
    return {};
}

Result<double> PhotonPasses::run(shader::FrameParams& params, std::span<GpuBuffer* const> buffers,
                                 const std::atomic<bool>* stop) {
    const uint32_t slotBlocks =
        PV_PHOTON_RECORDS_PER_PHOTON * params.photonCount / PV_PHOTON_SORT_BLOCK;
    double ms = 0.0;
    auto dispatch = [&](ComputePipeline& p, uint32_t groups) -> Status {
        auto t = p.dispatch(groups, 1);
        if (!t) return t.error();
        ms += t.value();
        return {};
    };
    auto uploadParams = [&]() {
        return buffers[PV_BINDING_PARAMS]->upload(&params, sizeof(params));
    };
    params.photonSortShift = 0;
    if (Status s = uploadParams(); !s) return s.error();
    if (Status s = buffers[PV_BINDING_PHOTON_CELLS]->fill(0); !s) return s.error();
    if (buffers[PV_BINDING_PHOTON_SPLATS]->size() > 0)
        if (Status s = buffers[PV_BINDING_PHOTON_SPLATS]->fill(0); !s) return s.error();
    const uint32_t traceGroups = params.photonCount / PV_PHOTON_GROUP_SIZE;
    if (stop) {
        auto t = traceParts_.run(*trace_, traceGroups, 1, *stop);
        if (!t) return t.error();
        ms += t.value();
    } else if (Status s = dispatch(*trace_, traceGroups); !s) {
        return s.error();
    }
    // Gather the stored records' pairs, then sort only those (rounded up to whole blocks).
    if (Status s = dispatch(*grid_[kCompactScan], 1); !s) return s.error();
    if (Status s = dispatch(*grid_[kCompact], slotBlocks); !s) return s.error();
    uint32_t stored = 0;
    if (Status s = buffers[PV_BINDING_PHOTON_BLOCK_COUNTS]->download(
            &stored, sizeof(stored),
            sizeof(uint32_t) * (params.photonCount / PV_PHOTON_GROUP_SIZE));
        !s)
        return s.error();
    params.photonSortRecords =
        (stored + PV_PHOTON_SORT_BLOCK - 1) / PV_PHOTON_SORT_BLOCK * PV_PHOTON_SORT_BLOCK;
    const uint32_t blocks = params.photonSortRecords / PV_PHOTON_SORT_BLOCK;
    if (blocks == 0) return ms;  // no photon stored: the cells stay empty
    for (uint32_t pass = 0; pass < PV_PHOTON_SORT_PASSES; ++pass) {
        params.photonSortShift = 8 * pass;
        if (Status s = uploadParams(); !s) return s.error();
        if (Status s = dispatch(*grid_[kHistogram], blocks); !s) return s.error();
        if (Status s = dispatch(*grid_[kScan], 1); !s) return s.error();
        if (Status s = dispatch(*grid_[kScatter], blocks); !s) return s.error();
    }
    if (Status s = dispatch(*grid_[kCells], blocks); !s) return s.error();
    return ms;
}

}  // namespace previs
