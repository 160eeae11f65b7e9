#include "gpu/compute_pipeline.h"

#include <algorithm>

#include "base/log.h"
#include "gpu/spirv_cache.h"

namespace previs {

namespace {

vk::DescriptorType descriptorType(BindingKind kind) {
    return kind == BindingKind::StorageBuffer ? vk::DescriptorType::eStorageBuffer
                                              : vk::DescriptorType::eUniformTexelBuffer;
}

size_t texelBytes(BindingKind kind) { return kind == BindingKind::TexelBufferUint4 ? 16 : 4; }

vk::Format texelFormat(BindingKind kind) {
    return kind == BindingKind::TexelBufferUint4 ? vk::Format::eR32G32B32A32Uint
                                                 : vk::Format::eR32Uint;
}

}  // namespace

Result<ComputePipeline> ComputePipeline::create(GpuContext& ctx, std::span<const uint32_t> spirv,
                                                std::span<const BindingKind> bindings,
                                                std::span<const uint32_t> specConstants,
                                                const char* label, Specialise specialise) {
    // The driver's compile may be the longest thing the render thread does (GpuContext::stage).
    if (Stage* stage = ctx.stage()) stage->allowLonger(GpuContext::kCompileAllowance);
    ComputePipeline p;
    p.ctx_ = &ctx;
    p.label_ = label;
    p.bindings_.assign(bindings.begin(), bindings.end());
    try {
        const auto& device = ctx.device();
        std::vector<vk::DescriptorSetLayoutBinding> layoutBindings;
        uint32_t storageCount = 0;
        uint32_t texelCount = 0;
        for (uint32_t i = 0; i < bindings.size(); ++i) {
            vk::DescriptorType type = descriptorType(bindings[i]);
            (type == vk::DescriptorType::eStorageBuffer ? storageCount : texelCount) += 1;
            layoutBindings.emplace_back(i, type, 1, vk::ShaderStageFlagBits::eCompute);
        }
        p.setLayout_ = vk::raii::DescriptorSetLayout(
            device, vk::DescriptorSetLayoutCreateInfo({}, layoutBindings));
        vk::DescriptorSetLayout setLayout = *p.setLayout_;
        p.layout_ = vk::raii::PipelineLayout(device, vk::PipelineLayoutCreateInfo({}, setLayout));
        std::vector<uint32_t> specialised;
        if (specialise == Specialise::OnHost && !specConstants.empty()) {
            auto module = SpirvCache::fromEnvironment().specialise(spirv, specConstants);
            if (!module)
                return makeError("cannot create compute pipeline '{}': {}", label,
                                 module.error().message);
            specialised = std::move(module.value());
            spirv = specialised;
        }
        p.module_ = vk::raii::ShaderModule(
            device, vk::ShaderModuleCreateInfo({}, spirv.size_bytes(), spirv.data()));

        // 32-bit specialization constants, ids in order (none left in a module specialised
        // on the host).
        std::vector<vk::SpecializationMapEntry> entries;
        if (specialised.empty())
            for (uint32_t i = 0; i < specConstants.size(); ++i)
                entries.emplace_back(i, i * sizeof(uint32_t), sizeof(uint32_t));
        vk::SpecializationInfo spec(static_cast<uint32_t>(entries.size()), entries.data(),
                                    entries.empty() ? 0 : specConstants.size_bytes(),
                                    specConstants.data());
        vk::PipelineShaderStageCreateInfo stage({}, vk::ShaderStageFlagBits::eCompute, *p.module_,
                                                "main", &spec);
        // Dispatch base (core since Vulkan 1.1): dispatchPart() splits a dispatch.
        p.pipeline_ =
            vk::raii::Pipeline(device, nullptr,
                               vk::ComputePipelineCreateInfo(
                                   vk::PipelineCreateFlagBits::eDispatchBase, stage, *p.layout_));

        std::vector<vk::DescriptorPoolSize> poolSizes;
        if (storageCount) poolSizes.emplace_back(vk::DescriptorType::eStorageBuffer, storageCount);
        if (texelCount) poolSizes.emplace_back(vk::DescriptorType::eUniformTexelBuffer, texelCount);
        p.pool_ = vk::raii::DescriptorPool(
            device, vk::DescriptorPoolCreateInfo(
                        vk::DescriptorPoolCreateFlagBits::eFreeDescriptorSet, 1, poolSizes));
        vk::raii::DescriptorSets sets(device, vk::DescriptorSetAllocateInfo(*p.pool_, setLayout));
        p.set_ = std::move(sets[0]);
        if (ctx.timestampPeriodNs() > 0.0)
            p.queries_ = vk::raii::QueryPool(
                device, vk::QueryPoolCreateInfo({}, vk::QueryType::eTimestamp, 2));
    } catch (const std::exception& e) {
        return makeError("cannot create compute pipeline '{}': {}", label, e.what());
    }
    ctx.pipelineCompiled();
    return p;
}

Status ComputePipeline::bind(std::span<const GpuBuffer* const> buffers,
                             std::span<const BufferRange> ranges) {
    PV_ASSERT(buffers.size() == bindings_.size());
    PV_ASSERT(ranges.empty() || ranges.size() == buffers.size());
    const uint32_t maxTexels = ctx_->physicalDevice().getProperties().limits.maxTexelBufferElements;
    std::vector<vk::DescriptorBufferInfo> infos;
    std::vector<vk::raii::BufferView> views;
    infos.reserve(buffers.size());
    views.reserve(buffers.size());
    std::vector<vk::BufferView> viewHandles(buffers.size());
    for (uint32_t i = 0; i < buffers.size(); ++i) {
        const BufferRange range = ranges.empty() ? BufferRange{} : ranges[i];
        infos.emplace_back(buffers[i]->handle(), range.offset, range.size);
        if (bindings_[i] == BindingKind::StorageBuffer) continue;
        // GpuBuffer allocates at least 16 bytes, so an empty array still has one texel.
        const size_t bytesPerTexel = texelBytes(bindings_[i]);
        const size_t texels = std::max<size_t>(1, buffers[i]->size() / bytesPerTexel);
        if (texels > maxTexels)
            return makeError(
                "'{}' binding {} needs {} texels, more than this device's "
                "maxTexelBufferElements ({}): use a smaller scene or another device",
                label_, i, texels, maxTexels);
        try {
            views.emplace_back(ctx_->device(), vk::BufferViewCreateInfo({}, buffers[i]->handle(),
                                                                        texelFormat(bindings_[i]),
                                                                        0, texels * bytesPerTexel));
        } catch (const std::exception& e) {
            return makeError("cannot create texel buffer view for '{}' binding {}: {}", label_, i,
                             e.what());
        }
        viewHandles[i] = *views.back();
    }
    std::vector<vk::WriteDescriptorSet> writes;
    for (uint32_t i = 0; i < buffers.size(); ++i) {
        if (bindings_[i] != BindingKind::StorageBuffer)
            writes.emplace_back(*set_, i, 0, 1, vk::DescriptorType::eUniformTexelBuffer, nullptr,
                                nullptr, &viewHandles[i]);
        else
            writes.emplace_back(*set_, i, 0, 1, vk::DescriptorType::eStorageBuffer, nullptr,
                                &infos[i]);
    }
    ctx_->device().updateDescriptorSets(writes, nullptr);
    // Dispatches wait for completion, so no submission still uses the views replaced here.
    texelViews_ = std::move(views);
    return {};
}

Result<double> ComputePipeline::dispatch(uint32_t groupsX, uint32_t groupsY, uint32_t groupsZ) {
    return record(0, 0, groupsX, groupsY, groupsZ);
}

Result<double> ComputePipeline::dispatchPart(uint32_t baseX, uint32_t baseY, uint32_t groupsX,
                                             uint32_t groupsY) {
    return record(baseX, baseY, groupsX, groupsY, 1);
}

Result<double> ComputePipeline::record(uint32_t baseX, uint32_t baseY, uint32_t groupsX,
                                       uint32_t groupsY, uint32_t groupsZ) {
    bool timed = static_cast<VkQueryPool>(*queries_) != VK_NULL_HANDLE;
    Status s = ctx_->submitAndWait([&](const vk::raii::CommandBuffer& cmd) {
        if (timed) {
            cmd.resetQueryPool(*queries_, 0, 2);
            cmd.writeTimestamp(vk::PipelineStageFlagBits::eTopOfPipe, *queries_, 0);
        }
        cmd.bindPipeline(vk::PipelineBindPoint::eCompute, *pipeline_);
        cmd.bindDescriptorSets(vk::PipelineBindPoint::eCompute, *layout_, 0, *set_, nullptr);
        if (baseX == 0 && baseY == 0)
            cmd.dispatch(groupsX, groupsY, groupsZ);
        else
            cmd.dispatchBase(baseX, baseY, 0, groupsX, groupsY, groupsZ);
        if (timed) cmd.writeTimestamp(vk::PipelineStageFlagBits::eBottomOfPipe, *queries_, 1);
    });
    if (!s) return s.error();
    if (!timed) return 0.0;
    try {
        auto [result, stamps] = queries_.getResults<uint64_t>(
            0, 2, 2 * sizeof(uint64_t), sizeof(uint64_t),
            vk::QueryResultFlagBits::e64 | vk::QueryResultFlagBits::eWait);
        if (result != vk::Result::eSuccess) return 0.0;
        return double(stamps[1] - stamps[0]) * ctx_->timestampPeriodNs() * 1e-6;
    } catch (const std::exception& e) {
        return makeError("timestamp query of '{}' failed: {}", label_, e.what());
    }
}

}  // namespace previs
