#pragma once

// A compute pipeline whose descriptor set 0 holds `bindingCount` storage buffers at bindings
// 0..bindingCount-1, with boolean specialization constants (ids 0..n-1) selecting the variant,
// and timestamp queries around its dispatches so benchmarks can report GPU time per pass.

#include <span>
#include <vector>

#include <vulkan/vulkan_raii.hpp>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/context.h"

namespace previs {

class ComputePipeline {
public:
    static Result<ComputePipeline> create(GpuContext& ctx, std::span<const uint32_t> spirv,
                                          uint32_t bindingCount,
                                          std::span<const uint32_t> boolSpecConstants,
                                          const char* label);

    ComputePipeline(ComputePipeline&&) = default;
    ComputePipeline& operator=(ComputePipeline&&) = default;

    // Binds buffers[i] at binding i.
    void bind(std::span<const GpuBuffer* const> buffers);

    // Dispatches groups and waits; returns the GPU time of the dispatch in milliseconds
    // (0 when the device has no timestamps).
    Result<double> dispatch(uint32_t groupsX, uint32_t groupsY, uint32_t groupsZ = 1);

    const std::string& label() const { return label_; }

private:
    ComputePipeline() = default;
    GpuContext* ctx_ = nullptr;
    std::string label_;
    vk::raii::DescriptorSetLayout setLayout_{nullptr};
    vk::raii::PipelineLayout layout_{nullptr};
    vk::raii::ShaderModule module_{nullptr};
    vk::raii::Pipeline pipeline_{nullptr};
    vk::raii::DescriptorPool pool_{nullptr};
    vk::raii::DescriptorSet set_{nullptr};
    vk::raii::QueryPool queries_{nullptr};
};

}  // namespace previs
