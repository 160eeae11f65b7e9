#pragma once

// A storage buffer with its memory. Host-visible device memory is used when the device has it
// (CPU devices, integrated GPUs, resizable BAR); otherwise uploads and readbacks go through a
// temporary staging buffer.

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>
#include <vulkan/vulkan_raii.hpp>

#include "base/result.h"
#include "gpu/context.h"

namespace previs {

class GpuBuffer {
public:
    // size 0 is allowed (an empty scene array): a 16-byte buffer is created so it can be bound.
    static Result<GpuBuffer> create(GpuContext& ctx, size_t sizeBytes, const char* label);

    template <typename T, size_t N>
    static Result<GpuBuffer> createWith(GpuContext& ctx, std::span<T, N> data, const char* label) {
        auto buffer = create(ctx, data.size_bytes(), label);
        if (!buffer) return buffer;
        if (Status s = buffer->upload(data.data(), data.size_bytes()); !s) return s.error();
        return buffer;
    }

    GpuBuffer(GpuBuffer&&) = default;
    GpuBuffer& operator=(GpuBuffer&&) = default;

    Status upload(const void* data, size_t bytes, size_t offset = 0);
    Status download(void* data, size_t bytes, size_t offset = 0) const;
    Status fill(uint32_t value);
    // Uploads `bytes` from the start, first replacing the buffer by one of that size (made with
    // `label`) when its size differs. Dispatches are synchronous (ComputePipeline::dispatch
    // waits), so the GPU is done with the old buffer; a frame-overlapped renderer would have to
    // defer its deletion.
    Status replaceContents(const void* data, size_t bytes, const char* label);

    vk::Buffer handle() const { return *buffer_; }
    size_t size() const { return size_; }
    // Unique to this buffer among all created in the process (a moved buffer keeps it), unlike a
    // handle, which a new buffer may reuse once this one is destroyed: whoever bound it can tell
    // whether the buffer at a binding is still the one bound.
    uint64_t id() const { return id_; }

private:
    GpuBuffer() = default;
    GpuContext* ctx_ = nullptr;
    vk::raii::Buffer buffer_{nullptr};
    vk::raii::DeviceMemory memory_{nullptr};
    size_t size_ = 0;
    void* mapped_ = nullptr;  // non-null when the memory is host visible and coherent
    uint64_t id_ = 0;
};

}  // namespace previs
