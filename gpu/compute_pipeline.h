#pragma once

// A compute pipeline whose descriptor set 0 holds one buffer per binding 0..n-1 — a storage
// buffer, or a uniform texel buffer of 16- or 4-byte uint texels (usamplerBuffer) where the
// binding says so — with 32-bit specialization constants (ids 0..n-1) selecting the variant, and
// timestamp queries around its dispatches so benchmarks can report GPU time per pass.

#include <memory>
#include <span>
#include <vector>
#include <vulkan/vulkan_raii.hpp>

#include "base/result.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/specialise_mode.h"

namespace previs {

enum class BindingKind {
    StorageBuffer,
    // A read-only array read with texelFetch as R32G32B32A32_UINT. On llvmpipe a texel fetch is
    // a gather, while a storage-buffer load whose address differs per lane is a loop over the
    // lanes with a bounds check each: hot read-only arrays (BVH nodes, triangles) go here.
    TexelBufferUint4,
    // The same for arrays of 4-byte words (R32_UINT: floats as bits, packed texture texels).
    TexelBufferUint,
};

// The bytes [offset, offset + size) of a buffer; size VK_WHOLE_SIZE: to its end.
struct BufferRange {
    uint64_t offset = 0;
    uint64_t size = VK_WHOLE_SIZE;
};

// The layouts and the pipeline compiled from one module, constants and bindings; the context's
// ComputePipelines made from the same share them (ComputePipeline::create).
struct CompiledPipeline;

class ComputePipeline {
public:
    // bindings[i] is the kind of binding i; specConstants[i] the value of the 32-bit
    // specialization constant with id i. A pipeline this context compiled before from the same
    // module (as specialised), constants and bindings is reused, not compiled again: a renderer
    // made anew, or one switching back to features it had, pays the driver's compile once a
    // process (on lavapipe most of a small render's time). Each ComputePipeline has its own
    // descriptor set and timestamps.
    static Result<ComputePipeline> create(GpuContext& ctx, std::span<const uint32_t> spirv,
                                          std::span<const BindingKind> bindings,
                                          std::span<const uint32_t> specConstants,
                                          const char* label,
                                          Specialise specialise = Specialise::OnHost);

    ComputePipeline(ComputePipeline&&) = default;
    ComputePipeline& operator=(ComputePipeline&&) = default;

    // Binds buffers[i] at binding i: all of it, or for a storage buffer the part `ranges[i]`
    // when `ranges` is given (a buffer larger than the device's maxStorageBufferRange can only
    // be bound in parts). Fails when a texel buffer holds more texels than the device's
    // maxTexelBufferElements.
    Status bind(std::span<const GpuBuffer* const> buffers,
                std::span<const BufferRange> ranges = {});

    // Dispatches groups and waits; returns the GPU time of the dispatch in milliseconds
    // (0 when the device has no timestamps).
    Result<double> dispatch(uint32_t groupsX, uint32_t groupsY, uint32_t groupsZ = 1);
    // The same for the groups from (baseX, baseY) on: gl_WorkGroupID and gl_GlobalInvocationID
    // count from there (vkCmdDispatchBase), so a dispatch split into parts computes what it
    // computes whole.
    Result<double> dispatchPart(uint32_t baseX, uint32_t baseY, uint32_t groupsX, uint32_t groupsY);

    const std::string& label() const { return label_; }
    // Whether both run the one compiled pipeline (made from the same module, constants and
    // bindings on the same context).
    bool sharesCompileWith(const ComputePipeline& other) const {
        return compiled_ == other.compiled_;
    }

private:
    ComputePipeline() = default;
    Result<double> record(uint32_t baseX, uint32_t baseY, uint32_t groupsX, uint32_t groupsY,
                          uint32_t groupsZ);

    GpuContext* ctx_ = nullptr;
    std::string label_;
    std::shared_ptr<const CompiledPipeline> compiled_;  // outlives the set below
    vk::raii::DescriptorPool pool_{nullptr};
    vk::raii::DescriptorSet set_{nullptr};
    vk::raii::QueryPool queries_{nullptr};
    std::vector<BindingKind> bindings_;
    std::vector<vk::raii::BufferView> texelViews_;  // of the buffers bound last
};

// Destroys the pipelines `ctx` keeps for reuse (GpuContext's destructor, before the device goes;
// every ComputePipeline of the context is gone by then).
void releaseCompiledPipelines(const GpuContext& ctx);
// How many compiled pipelines `ctx` keeps, in use or not (at most 16 not in use after a compile).
size_t compiledPipelinesKept(const GpuContext& ctx);

}  // namespace previs
