#include "gpu/compute_pipeline.h"

namespace previs {

Result<ComputePipeline> ComputePipeline::create(GpuContext& ctx, std::span<const uint32_t> spirv,
                                                uint32_t bindingCount,
                                                std::span<const uint32_t> boolSpecConstants,
                                                const char* label) {
    ComputePipeline p;
    p.ctx_ = &ctx;
    p.label_ = label;
    try {
        const auto& device = ctx.device();
        std::vector<vk::DescriptorSetLayoutBinding> bindings;
        for (uint32_t i = 0; i < bindingCount; ++i)
            bindings.emplace_back(i, vk::DescriptorType::eStorageBuffer, 1,
                                  vk::ShaderStageFlagBits::eCompute);
        p.setLayout_ = vk::raii::DescriptorSetLayout(
            device, vk::DescriptorSetLayoutCreateInfo({}, bindings));
        vk::DescriptorSetLayout setLayout = *p.setLayout_;
        p.layout_ = vk::raii::PipelineLayout(device, vk::PipelineLayoutCreateInfo({}, setLayout));
        p.module_ = vk::raii::ShaderModule(
            device, vk::ShaderModuleCreateInfo({}, spirv.size_bytes(), spirv.data()));

        // VkBool32 specialization constants, ids in order.
        std::vector<vk::SpecializationMapEntry> entries;
        for (uint32_t i = 0; i < boolSpecConstants.size(); ++i)
            entries.emplace_back(i, i * sizeof(uint32_t), sizeof(uint32_t));
        vk::SpecializationInfo spec(static_cast<uint32_t>(entries.size()), entries.data(),
                                    boolSpecConstants.size_bytes(), boolSpecConstants.data());
        vk::PipelineShaderStageCreateInfo stage({}, vk::ShaderStageFlagBits::eCompute, *p.module_,
                                                "main", &spec);
        p.pipeline_ = vk::raii::Pipeline(device, nullptr,
                                         vk::ComputePipelineCreateInfo({}, stage, *p.layout_));

        vk::DescriptorPoolSize poolSize(vk::DescriptorType::eStorageBuffer, bindingCount);
        p.pool_ = vk::raii::DescriptorPool(
            device, vk::DescriptorPoolCreateInfo(
                        vk::DescriptorPoolCreateFlagBits::eFreeDescriptorSet, 1, poolSize));
        vk::raii::DescriptorSets sets(device, vk::DescriptorSetAllocateInfo(*p.pool_, setLayout));
        p.set_ = std::move(sets[0]);
        if (ctx.timestampPeriodNs() > 0.0)
            p.queries_ = vk::raii::QueryPool(
                device, vk::QueryPoolCreateInfo({}, vk::QueryType::eTimestamp, 2));
    } catch (const std::exception& e) {
        return makeError("cannot create compute pipeline '{}': {}", label, e.what());
    }
    return p;
}

void ComputePipeline::bind(std::span<const GpuBuffer* const> buffers) {
    std::vector<vk::DescriptorBufferInfo> infos;
    infos.reserve(buffers.size());
    for (const GpuBuffer* b : buffers) infos.emplace_back(b->handle(), 0, VK_WHOLE_SIZE);
    std::vector<vk::WriteDescriptorSet> writes;
    for (uint32_t i = 0; i < infos.size(); ++i)
        writes.emplace_back(*set_, i, 0, 1, vk::DescriptorType::eStorageBuffer, nullptr,
                            &infos[i]);
    ctx_->device().updateDescriptorSets(writes, nullptr);
}

Result<double> ComputePipeline::dispatch(uint32_t groupsX, uint32_t groupsY, uint32_t groupsZ) {
    bool timed = static_cast<VkQueryPool>(*queries_) != VK_NULL_HANDLE;
    Status s = ctx_->submitAndWait([&](const vk::raii::CommandBuffer& cmd) {
        if (timed) {
            cmd.resetQueryPool(*queries_, 0, 2);
            cmd.writeTimestamp(vk::PipelineStageFlagBits::eTopOfPipe, *queries_, 0);
        }
        cmd.bindPipeline(vk::PipelineBindPoint::eCompute, *pipeline_);
        cmd.bindDescriptorSets(vk::PipelineBindPoint::eCompute, *layout_, 0, *set_, nullptr);
        cmd.dispatch(groupsX, groupsY, groupsZ);
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
