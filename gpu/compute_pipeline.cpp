#include "gpu/compute_pipeline.h"

#include <xxhash.h>

#include <algorithm>
#include <map>
#include <mutex>
#include <unordered_map>

#include "base/log.h"
#include "gpu/spirv_cache.h"

namespace previs {

struct CompiledPipeline {
    vk::raii::DescriptorSetLayout setLayout{nullptr};
    vk::raii::PipelineLayout layout{nullptr};
    vk::raii::Pipeline pipeline{nullptr};
};

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

// What a compiled pipeline is made from, whole (no two differing keys share a pipeline): the
// module's words, where its constants are specialised, the constants and the binding kinds.
struct PipelineKey {
    std::vector<uint32_t> words;
    bool operator==(const PipelineKey&) const = default;
};
struct PipelineKeyHash {
    size_t operator()(const PipelineKey& k) const {
        return size_t(XXH3_64bits(k.words.data(), k.words.size() * sizeof(uint32_t)));
    }
};
PipelineKey pipelineKey(std::span<const uint32_t> spirv, std::span<const BindingKind> bindings,
                        std::span<const uint32_t> specConstants, Specialise specialise) {
    PipelineKey key;
    key.words.reserve(spirv.size() + specConstants.size() + bindings.size() + 3);
    key.words.assign(spirv.begin(), spirv.end());
    key.words.push_back(uint32_t(specialise));
    key.words.push_back(uint32_t(specConstants.size()));
    key.words.insert(key.words.end(), specConstants.begin(), specConstants.end());
    key.words.push_back(uint32_t(bindings.size()));
    for (BindingKind b : bindings) key.words.push_back(uint32_t(b));
    return key;
}

// A compiled pipeline and when it was last asked for (a count of requests).
struct KeptPipeline {
    std::shared_ptr<const CompiledPipeline> pipeline;
    uint64_t lastUse = 0;
};
using PipelinesByKey = std::unordered_map<PipelineKey, KeptPipeline, PipelineKeyHash>;

// Pipelines no ComputePipeline uses that a context keeps, the most recently asked for: a
// renderer's variants (environment, lights, photons on or off), so a service switching between
// them, or made again, does not compile them again; bounded, so a long run does not keep every
// variant it ever saw (each is the driver's machine code, megabytes on lavapipe).
constexpr size_t kKeptUnused = 16;

// Drops the least recently asked-for pipelines nothing uses, past kKeptUnused.
void dropUnused(PipelinesByKey& mine) {
    std::vector<std::pair<uint64_t, const PipelineKey*>> unused;
    for (const auto& [key, kept] : mine)
        if (kept.pipeline.use_count() == 1) unused.emplace_back(kept.lastUse, &key);
    if (unused.size() <= kKeptUnused) return;
    std::sort(unused.begin(), unused.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    std::vector<PipelineKey> dropped;
    for (size_t i = 0; i + kKeptUnused < unused.size(); ++i) dropped.push_back(*unused[i].second);
    for (const PipelineKey& key : dropped) mine.erase(key);
}

// Every context's compiled pipelines. Never destroyed: a context may go at exit, after static
// destruction began (releaseCompiledPipelines then still finds this).
struct CompiledPipelines {
    std::mutex mutex;
    std::map<const GpuContext*, PipelinesByKey> byContext;
    uint64_t requests = 0;  // KeptPipeline::lastUse's clock
};
CompiledPipelines& compiledPipelines() {
    static CompiledPipelines* pipelines = new CompiledPipelines;
    return *pipelines;
}

// Compiles the pipeline (layouts, module, pipeline); throws what vk::raii throws.
Result<std::shared_ptr<const CompiledPipeline>> compile(GpuContext& ctx,
                                                        std::span<const uint32_t> spirv,
                                                        std::span<const BindingKind> bindings,
                                                        std::span<const uint32_t> specConstants,
                                                        const char* label, Specialise specialise) {
    // The driver's compile may be the longest thing the render thread does (GpuContext::stage).
    if (Stage* stage = ctx.stage()) stage->allowLonger(GpuContext::kCompileAllowance);
    auto c = std::make_shared<CompiledPipeline>();
    const auto& device = ctx.device();
    std::vector<vk::DescriptorSetLayoutBinding> layoutBindings;
    for (uint32_t i = 0; i < bindings.size(); ++i)
        layoutBindings.emplace_back(i, descriptorType(bindings[i]), 1,
                                    vk::ShaderStageFlagBits::eCompute);
    c->setLayout = vk::raii::DescriptorSetLayout(
        device, vk::DescriptorSetLayoutCreateInfo({}, layoutBindings));
    vk::DescriptorSetLayout setLayout = *c->setLayout;
    c->layout = vk::raii::PipelineLayout(device, vk::PipelineLayoutCreateInfo({}, setLayout));
    std::vector<uint32_t> specialised;
    if (specialise == Specialise::OnHost && !specConstants.empty()) {
        auto module = SpirvCache::fromEnvironment().specialise(spirv, specConstants);
        if (!module)
            return makeError("cannot create compute pipeline '{}': {}", label,
                             module.error().message);
        specialised = std::move(module.value());
        spirv = specialised;
    }
    // The module is needed only while the pipeline is made.
    vk::raii::ShaderModule module(device,
                                  vk::ShaderModuleCreateInfo({}, spirv.size_bytes(), spirv.data()));

    // 32-bit specialization constants, ids in order (none left in a module specialised on the
    // host).
    std::vector<vk::SpecializationMapEntry> entries;
    if (specialised.empty())
        for (uint32_t i = 0; i < specConstants.size(); ++i)
            entries.emplace_back(i, i * sizeof(uint32_t), sizeof(uint32_t));
    vk::SpecializationInfo spec(static_cast<uint32_t>(entries.size()), entries.data(),
                                entries.empty() ? 0 : specConstants.size_bytes(),
                                specConstants.data());
    vk::PipelineShaderStageCreateInfo stage({}, vk::ShaderStageFlagBits::eCompute, *module, "main",
                                            &spec);
    // Dispatch base (core since Vulkan 1.1): dispatchPart() splits a dispatch.
    c->pipeline =
        vk::raii::Pipeline(device, nullptr,
                           vk::ComputePipelineCreateInfo(vk::PipelineCreateFlagBits::eDispatchBase,
                                                         stage, *c->layout));
    return std::shared_ptr<const CompiledPipeline>(std::move(c));
}

// The context's pipeline for the key, compiled if it has none yet.
Result<std::shared_ptr<const CompiledPipeline>> compiledFor(
    GpuContext& ctx, std::span<const uint32_t> spirv, std::span<const BindingKind> bindings,
    std::span<const uint32_t> specConstants, const char* label, Specialise specialise) {
    PipelineKey key = pipelineKey(spirv, bindings, specConstants, specialise);
    CompiledPipelines& all = compiledPipelines();
    {
        std::lock_guard lock(all.mutex);
        auto& mine = all.byContext[&ctx];
        if (auto found = mine.find(key); found != mine.end()) {
            found->second.lastUse = ++all.requests;
            return found->second.pipeline;
        }
    }
    Result<std::shared_ptr<const CompiledPipeline>> made =
        compile(ctx, spirv, bindings, specConstants, label, specialise);
    if (!made) return made;
    std::lock_guard lock(all.mutex);
    PipelinesByKey& mine = all.byContext[&ctx];
    // Another thread may have compiled the same meanwhile: one of the two is kept.
    KeptPipeline& kept = mine.try_emplace(std::move(key), KeptPipeline{*made}).first->second;
    kept.lastUse = ++all.requests;
    std::shared_ptr<const CompiledPipeline> pipeline = kept.pipeline;  // in use from here on
    dropUnused(mine);
    return pipeline;
}

}  // namespace

size_t compiledPipelinesKept(const GpuContext& ctx) {
    CompiledPipelines& all = compiledPipelines();
    std::lock_guard lock(all.mutex);
    const auto mine = all.byContext.find(&ctx);
    return mine == all.byContext.end() ? 0 : mine->second.size();
}

void releaseCompiledPipelines(const GpuContext& ctx) {
    PipelinesByKey released;
    CompiledPipelines& all = compiledPipelines();
    std::lock_guard lock(all.mutex);
    if (auto mine = all.byContext.find(&ctx); mine != all.byContext.end()) {
        released = std::move(mine->second);
        all.byContext.erase(mine);
    }
    // A ComputePipeline still holding one would destroy it after the device: a bug.
    for (const auto& [key, kept] : released)
        if (kept.pipeline.use_count() > 1)
            logError("Vulkan: a compute pipeline outlives its device's context");
}

Result<ComputePipeline> ComputePipeline::create(GpuContext& ctx, std::span<const uint32_t> spirv,
                                                std::span<const BindingKind> bindings,
                                                std::span<const uint32_t> specConstants,
                                                const char* label, Specialise specialise) {
    ComputePipeline p;
    p.ctx_ = &ctx;
    p.label_ = label;
    p.bindings_.assign(bindings.begin(), bindings.end());
    try {
        const auto& device = ctx.device();
        Result<std::shared_ptr<const CompiledPipeline>> compiled =
            compiledFor(ctx, spirv, bindings, specConstants, label, specialise);
        if (!compiled) return compiled.error();
        p.compiled_ = std::move(compiled.value());
        uint32_t storageCount = 0;
        uint32_t texelCount = 0;
        for (BindingKind kind : bindings)
            (descriptorType(kind) == vk::DescriptorType::eStorageBuffer ? storageCount
                                                                        : texelCount) += 1;
        std::vector<vk::DescriptorPoolSize> poolSizes;
        if (storageCount) poolSizes.emplace_back(vk::DescriptorType::eStorageBuffer, storageCount);
        if (texelCount) poolSizes.emplace_back(vk::DescriptorType::eUniformTexelBuffer, texelCount);
        p.pool_ = vk::raii::DescriptorPool(
            device, vk::DescriptorPoolCreateInfo(
                        vk::DescriptorPoolCreateFlagBits::eFreeDescriptorSet, 1, poolSizes));
        vk::DescriptorSetLayout setLayout = *p.compiled_->setLayout;
        vk::raii::DescriptorSets sets(device, vk::DescriptorSetAllocateInfo(*p.pool_, setLayout));
        p.set_ = std::move(sets[0]);
        if (ctx.timestampPeriodNs() > 0.0)
            p.queries_ = vk::raii::QueryPool(
                device, vk::QueryPoolCreateInfo({}, vk::QueryType::eTimestamp, 2));
    } catch (const std::exception& e) {
        return makeError("cannot create compute pipeline '{}': {}", label, e.what());
    }
    // Counted whether compiled now or before: whoever waits for a batch of pipelines counts
    // each one it asked for (GpuContext::setCompileListener).
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
        cmd.bindPipeline(vk::PipelineBindPoint::eCompute, *compiled_->pipeline);
        cmd.bindDescriptorSets(vk::PipelineBindPoint::eCompute, *compiled_->layout, 0, *set_,
                               nullptr);
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
