#include "render/held_reprojection.h"

#include <array>
#include <glm/glm.hpp>
#include <span>
#include <tuple>
#include <utility>

#include "base/log.h"
#include "held_reprojection.spv.h"

namespace previs {

shader::ReprojectParams reprojectParams(const DenoiseCamera& from, const DenoiseCamera& to,
                                        uint32_t width, uint32_t height, float keep) {
    shader::ReprojectParams p{};
    // In double: the poses are metres from the set's origin, their difference millimetres.
    p.toFromCamera = glm::mat4(glm::inverse(to.worldFromCamera) * from.worldFromCamera);
    p.fromTanHalfFov = from.tanHalfFov;
    p.toTanHalfFov = to.tanHalfFov;
    p.width = width;
    p.height = height;
    p.keep = keep;
    return p;
}

Result<HeldReprojection> HeldReprojection::create(GpuContext& ctx, uint32_t width,
                                                  uint32_t height) {
    HeldReprojection r;
    r.width_ = width;
    r.height_ = height;
    const size_t pixels = size_t(width) * height;
    for (auto [out, bytes, label] :
         {std::tuple{&r.params_, sizeof(shader::ReprojectParams), "reprojectParams"},
          std::tuple{&r.spare_, pixels * 2 * sizeof(glm::vec4), "heldSamples"},
          std::tuple{&r.nearest_, pixels * sizeof(uint32_t), "reprojectNearest"}}) {
        auto b = GpuBuffer::create(ctx, bytes, label);
        if (!b) return b.error();
        out->emplace(std::move(b.value()));
    }
    std::array<BindingKind, PV_REPROJECT_BINDING_COUNT> kinds{};
    kinds.fill(BindingKind::StorageBuffer);
    for (auto [stage, out] : {std::pair{PV_REPROJECT_STAGE_CLAIM, &r.claim_},
                              std::pair{PV_REPROJECT_STAGE_MOVE, &r.move_}}) {
        const std::array<uint32_t, 1> constants{stage};
        auto p = ComputePipeline::create(
            ctx,
            std::span<const uint32_t>(held_reprojection_spv, sizeof(held_reprojection_spv) / 4),
            kinds, constants, "held_reprojection");
        if (!p) return p.error();
        out->emplace(std::move(p.value()));
    }
    return r;
}

Status HeldReprojection::run(GpuBuffer& held, const shader::ReprojectParams& params) {
    PV_ASSERT(params.width == width_ && params.height == height_ && held.size() == spare_->size());
    if (Status s = params_->upload(&params, sizeof(params)); !s) return s;
    if (Status s = nearest_->fill(~0u); !s) return s;
    const std::array<const GpuBuffer*, PV_REPROJECT_BINDING_COUNT> buffers{&*params_, &held,
                                                                           &*spare_, &*nearest_};
    const uint32_t groupsX = (width_ + PV_REPROJECT_GROUP - 1) / PV_REPROJECT_GROUP;
    const uint32_t groupsY = (height_ + PV_REPROJECT_GROUP - 1) / PV_REPROJECT_GROUP;
    for (ComputePipeline* stage : {&*claim_, &*move_}) {
        if (Status s = stage->bind(buffers); !s) return s;
        if (auto ms = stage->dispatch(groupsX, groupsY); !ms) return ms.error();
    }
    std::swap(held, *spare_);
    return {};
}

uint64_t HeldReprojection::deviceBytes() const {
    return params_->size() + spare_->size() + nearest_->size();
}

}  // namespace previs
