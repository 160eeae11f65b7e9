#include "render/path_pipelines.h"

#include "trace_paths.spv.h"

namespace previs {

namespace {

// Every read-only array the shader indexes per lane is a texel buffer (see BindingKind); params
// (uniform reads), the accumulators and the stats stay storage buffers.
std::array<BindingKind, PV_BINDING_COUNT> pathBindings() {
    std::array<BindingKind, PV_BINDING_COUNT> bindings{};
    bindings.fill(BindingKind::StorageBuffer);
    bindings[PV_BINDING_BVH_NODES] = BindingKind::TexelBufferUint4;
    for (int b : {PV_BINDING_TEXTURES, PV_BINDING_TRIANGLE_VERTICES, PV_BINDING_TRIANGLES,
                  PV_BINDING_NORMALS, PV_BINDING_UVS, PV_BINDING_MATERIALS, PV_BINDING_LIGHTS,
                  PV_BINDING_EMISSIVE_TRIANGLES, PV_BINDING_PHOTON_LIGHTS, PV_BINDING_PHOTON_SORTED,
                  PV_BINDING_PHOTON_CELLS})
        bindings[b] = BindingKind::TexelBufferUint4;
    for (int b :
         {PV_BINDING_TEXELS, PV_BINDING_ENV_RADIANCE, PV_BINDING_ENV_MARGINAL_CDF,
          PV_BINDING_ENV_CONDITIONAL_CDF, PV_BINDING_TRIANGLE_LIGHT_PDF, PV_BINDING_LENS_GRID})
        bindings[b] = BindingKind::TexelBufferUint;
    return bindings;
}

}  // namespace

bool PathPipelines::current(const PipelineConstants& constants) const {
    const bool photonsComplete = !constants[PV_SPEC_PHOTONS] || photons_;
    return paths_ && photonsComplete && constants == constants_;
}

size_t PathPipelines::pipelineCount(const PipelineConstants& constants) {
    return 1 + (constants[PV_SPEC_PHOTONS] ? PhotonPasses::kPipelineCount : 0);
}

Status PathPipelines::ensure(const PipelineConstants& constants) {
    if (current(constants)) return {};
    return compile(constants);
}

Status PathPipelines::compile(const PipelineConstants& constants) {
    ++compiles_;
    // No half-made set: whatever fails below leaves none, and the next ensure() compiles again.
    paths_.reset();
    photons_.reset();
    bound_.clear();
    const std::array<BindingKind, PV_BINDING_COUNT> bindings = pathBindings();
    auto paths = ComputePipeline::create(
        *ctx_, std::span<const uint32_t>(trace_paths_spv, sizeof(trace_paths_spv) / 4), bindings,
        constants, "trace_paths", specialise_);
    if (!paths) return paths.error();
    if (constants[PV_SPEC_PHOTONS]) {
        // trace_photons shares trace_paths' scene bindings and feature constants.
        auto passes = PhotonPasses::create(*ctx_, bindings, constants, specialise_);
        if (!passes) return passes.error();
        photons_.emplace(std::move(passes.value()));
    }
    // Dispatches wait for completion (ComputePipeline::dispatch), so no submission can still use
    // the set this replaces.
    paths_.emplace(std::move(paths.value()));
    constants_ = constants;
    return {};
}

Status PathPipelines::bind(std::span<const GpuBuffer* const> buffers,
                           std::span<const BufferRange> ranges) {
    if (!paths_) return {};
    std::vector<Bound> wanted(buffers.size());
    for (size_t i = 0; i < buffers.size(); ++i) {
        const BufferRange r = ranges.empty() ? BufferRange{} : ranges[i];
        wanted[i] = {buffers[i]->id(), r.offset, r.size};
    }
    if (wanted == bound_) return {};
    bound_.clear();
    if (photons_)
        if (Status s = photons_->bind(buffers, ranges); !s) return s;
    if (Status s = paths_->bind(buffers, ranges); !s) return s;
    bound_ = std::move(wanted);
    return {};
}

}  // namespace previs
