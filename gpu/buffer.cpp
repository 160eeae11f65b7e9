#include "gpu/buffer.h"

#include <atomic>
#include <cstring>

namespace previs {

namespace {

constexpr vk::BufferUsageFlags kUsage =
    vk::BufferUsageFlagBits::eStorageBuffer | vk::BufferUsageFlagBits::eUniformTexelBuffer |
    vk::BufferUsageFlagBits::eTransferSrc | vk::BufferUsageFlagBits::eTransferDst;

struct Staging {
    vk::raii::Buffer buffer{nullptr};
    vk::raii::DeviceMemory memory{nullptr};
    void* mapped = nullptr;
};

Staging makeStaging(GpuContext& ctx, size_t bytes) {
    Staging s;
    s.buffer = vk::raii::Buffer(ctx.device(), vk::BufferCreateInfo({}, bytes, kUsage));
    auto req = s.buffer.getMemoryRequirements();
    uint32_t type = ctx.findMemoryType(
        req.memoryTypeBits,
        vk::MemoryPropertyFlagBits::eHostVisible | vk::MemoryPropertyFlagBits::eHostCoherent,
        vk::MemoryPropertyFlagBits::eHostCached);
    s.memory = vk::raii::DeviceMemory(ctx.device(), vk::MemoryAllocateInfo(req.size, type));
    s.buffer.bindMemory(*s.memory, 0);
    s.mapped = s.memory.mapMemory(0, VK_WHOLE_SIZE);
    return s;
}

}  // namespace

Result<GpuBuffer> GpuBuffer::create(GpuContext& ctx, size_t sizeBytes, const char* label) {
    static std::atomic<uint64_t> nextId{1};
    GpuBuffer b;
    b.ctx_ = &ctx;
    b.size_ = sizeBytes;
    b.id_ = nextId.fetch_add(1, std::memory_order_relaxed);
    try {
        size_t allocSize = std::max<size_t>(sizeBytes, 16);
        b.buffer_ = vk::raii::Buffer(ctx.device(), vk::BufferCreateInfo({}, allocSize, kUsage));
        auto req = b.buffer_.getMemoryRequirements();
        auto hostVisible =
            vk::MemoryPropertyFlagBits::eHostVisible | vk::MemoryPropertyFlagBits::eHostCoherent;
        uint32_t type = ctx.findMemoryType(req.memoryTypeBits,
                                           vk::MemoryPropertyFlagBits::eDeviceLocal, hostVisible);
        if (type == UINT32_MAX) type = ctx.findMemoryType(req.memoryTypeBits, {}, hostVisible);
        if (type == UINT32_MAX)
            return makeError("no memory type for GPU buffer '{}' ({} bytes)", label, sizeBytes);
        b.memory_ = vk::raii::DeviceMemory(ctx.device(), vk::MemoryAllocateInfo(req.size, type));
        b.buffer_.bindMemory(*b.memory_, 0);
        auto flags = ctx.physicalDevice().getMemoryProperties().memoryTypes[type].propertyFlags;
        if ((flags & hostVisible) == hostVisible) b.mapped_ = b.memory_.mapMemory(0, VK_WHOLE_SIZE);
    } catch (const std::exception& e) {
        return makeError("cannot allocate GPU buffer '{}' of {} bytes: {}", label, sizeBytes,
                         e.what());
    }
    return b;
}

Status GpuBuffer::replaceContents(const void* data, size_t bytes, const char* label) {
    if (size_ != bytes) {
        auto fresh = create(*ctx_, bytes, label);
        if (!fresh) return fresh.error();
        *this = std::move(fresh.value());
    }
    if (bytes == 0) return {};
    return upload(data, bytes);
}

Status GpuBuffer::upload(const void* data, size_t bytes, size_t offset) {
    if (bytes == 0) return {};
    if (mapped_) {
        std::memcpy(static_cast<char*>(mapped_) + offset, data, bytes);
        return {};
    }
    try {
        Staging staging = makeStaging(*ctx_, bytes);
        std::memcpy(staging.mapped, data, bytes);
        return ctx_->submitAndWait([&](const vk::raii::CommandBuffer& cmd) {
            cmd.copyBuffer(*staging.buffer, *buffer_, vk::BufferCopy(0, offset, bytes));
        });
    } catch (const std::exception& e) {
        return makeError("GPU upload failed: {}", e.what());
    }
}

Status GpuBuffer::download(void* data, size_t bytes, size_t offset) const {
    if (bytes == 0) return {};
    if (mapped_) {
        std::memcpy(data, static_cast<const char*>(mapped_) + offset, bytes);
        return {};
    }
    try {
        Staging staging = makeStaging(*ctx_, bytes);
        Status s = ctx_->submitAndWait([&](const vk::raii::CommandBuffer& cmd) {
            cmd.copyBuffer(*buffer_, *staging.buffer, vk::BufferCopy(offset, 0, bytes));
        });
        if (!s) return s;
        std::memcpy(data, staging.mapped, bytes);
    } catch (const std::exception& e) {
        return makeError("GPU readback failed: {}", e.what());
    }
    return {};
}

Status GpuBuffer::fill(uint32_t value) {
    return ctx_->submitAndWait([&](const vk::raii::CommandBuffer& cmd) {
        cmd.fillBuffer(*buffer_, 0, VK_WHOLE_SIZE, value);
    });
}

}  // namespace previs
