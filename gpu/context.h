#pragma once

// The Vulkan compute context: instance, device choice, one compute queue, validation messages.
// Runs on any conformant device; prefers a discrete GPU, then integrated, then virtual, then a CPU
// implementation (lavapipe). PREVIS_VK_DEVICE (index or name substring) overrides the choice.

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vulkan/vulkan_raii.hpp>

#include "base/result.h"
#include "base/stage_watch.h"

namespace previs {

struct GpuOptions {
    // Enable VK_LAYER_KHRONOS_validation when installed. Tests turn it on; a validation error
    // is then counted (validationErrorCount) and logged.
    bool validation = false;
    // Index into the device list or a case-insensitive substring of the device name;
    // empty = automatic (also read from PREVIS_VK_DEVICE when empty).
    std::string deviceOverride;
    // The longest one submission may run before it counts as a hung device (its fence never
    // signalled): an error, never a wait forever. Far above any dispatch previs makes (the
    // service's are ~250 ms parts, gpu/interruptible_dispatch.h; a render's whole frames take
    // seconds on lavapipe).
    std::chrono::milliseconds fenceTimeout{std::chrono::minutes(5)};
};

class GpuContext {
public:
    static Result<std::unique_ptr<GpuContext>> create(const GpuOptions& options);
    ~GpuContext();
    GpuContext(const GpuContext&) = delete;
    GpuContext& operator=(const GpuContext&) = delete;

    const vk::raii::Device& device() const { return device_; }
    const vk::raii::PhysicalDevice& physicalDevice() const { return physicalDevice_; }
    const vk::raii::Queue& queue() const { return queue_; }
    uint32_t queueFamily() const { return queueFamily_; }
    const std::string& deviceName() const { return deviceName_; }
    bool isCpuDevice() const { return isCpu_; }
    // Invocations that run in lockstep (a CPU device's SIMD width).
    uint32_t subgroupSize() const { return subgroupSize_; }
    // Nanoseconds per timestamp tick; 0 when the queue has no timestamps.
    double timestampPeriodNs() const { return timestampPeriodNs_; }
    uint32_t findMemoryType(uint32_t typeBits, vk::MemoryPropertyFlags required,
                            vk::MemoryPropertyFlags preferred) const;

    // Records commands into a one-time command buffer, submits them and waits, at most
    // GpuOptions::fenceTimeout. A lost device (VK_ERROR_DEVICE_LOST: a driver reset, a GPU
    // fault) or a fence that never signals is an error naming the device; deviceLost() then
    // stays true and nothing waits on the device again (the destructor included).
    Status submitAndWait(const std::function<void(const vk::raii::CommandBuffer&)>& record);
    bool deviceLost() const { return deviceLost_.load(); }

    uint32_t validationErrorCount() const { return validationErrors_.load(); }
    bool validationEnabled() const { return validationEnabled_; }

    // The stage (base/stage_watch.h) of the thread that compiles and submits on this context,
    // when a service watches it: a pipeline compile may take minutes on a slow CPU, so each one
    // extends that thread's step by kCompileAllowance (ComputePipeline::create) instead of
    // counting as a hang. Null: nobody watches.
    void setStage(Stage* stage) { stage_ = stage; }
    Stage* stage() const { return stage_; }
    static constexpr std::chrono::minutes kCompileAllowance{10};
    // Called after each pipeline made on this context (ComputePipeline::create), compiled or
    // reused from an earlier compile, on the making thread: whoever waits for a batch counts
    // them (Renderer::create's progress). One listener at a time; empty: none.
    void setCompileListener(std::function<void()> listener) {
        compileListener_ = std::move(listener);
    }
    void pipelineCompiled() const {
        if (compileListener_) compileListener_();
    }

private:
    GpuContext() = default;
    static VKAPI_ATTR VkBool32 VKAPI_CALL debugCallback(
        VkDebugUtilsMessageSeverityFlagBitsEXT severity, VkDebugUtilsMessageTypeFlagsEXT types,
        const VkDebugUtilsMessengerCallbackDataEXT* data, void* user);

    // Declared in creation order so they are destroyed in reverse.
    vk::raii::Context context_;
    vk::raii::Instance instance_{nullptr};
    vk::raii::DebugUtilsMessengerEXT messenger_{nullptr};
    vk::raii::PhysicalDevice physicalDevice_{nullptr};
    vk::raii::Device device_{nullptr};
    vk::raii::Queue queue_{nullptr};
    vk::raii::CommandPool commandPool_{nullptr};
    vk::raii::Fence fence_{nullptr};
    uint32_t queueFamily_ = 0;
    std::string deviceName_;
    bool isCpu_ = false;
    uint32_t subgroupSize_ = 1;
    bool validationEnabled_ = false;
    double timestampPeriodNs_ = 0.0;
    std::atomic<uint32_t> validationErrors_{0};
    Stage* stage_ = nullptr;
    std::function<void()> compileListener_;
    std::chrono::milliseconds fenceTimeout_{};
    std::atomic<bool> deviceLost_{false};
};

}  // namespace previs
