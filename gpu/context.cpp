#include "gpu/context.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <vector>

#include "base/log.h"
#include "base/strings.h"
#include "gpu/compute_pipeline.h"

#if defined(__SANITIZE_ADDRESS__)
#include <dlfcn.h>
#endif

namespace previs {

namespace {

// Mesa's lavapipe (22.3) allocates once per process (a pthread_once in its LLVM set-up) and
// never frees it; when the Vulkan loader unloads the driver at vkDestroyInstance, LeakSanitizer
// reports that block from an "<unknown module>" and fails every GPU test of the ASan build. A
// driver that stays loaded keeps the block reachable. Sanitizer builds only: release builds
// leave the loader's unloading alone.
void keepLavapipeLoadedUnderSanitizers() {
#if defined(__SANITIZE_ADDRESS__)
    // RTLD_NOLOAD: only if the loader already loaded it; RTLD_NODELETE: never unload it.
    if (void* lvp = dlopen("libvulkan_lvp.so", RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE))
        dlclose(lvp);  // drops our reference; NODELETE keeps the library
#endif
}

}  // namespace

namespace {

// Higher is preferred: discrete, integrated, virtual, then CPU.
int deviceTypeRank(vk::PhysicalDeviceType type) {
    switch (type) {
        case vk::PhysicalDeviceType::eDiscreteGpu:
            return 4;
        case vk::PhysicalDeviceType::eIntegratedGpu:
            return 3;
        case vk::PhysicalDeviceType::eVirtualGpu:
            return 2;
        case vk::PhysicalDeviceType::eCpu:
            return 1;
        default:
            return 0;
    }
}

std::optional<uint32_t> computeQueueFamily(const vk::raii::PhysicalDevice& device) {
    auto families = device.getQueueFamilyProperties();
    for (uint32_t i = 0; i < families.size(); ++i) {
        if (families[i].queueFlags & vk::QueueFlagBits::eCompute) return i;
    }
    return std::nullopt;
}

bool supportsRequiredFeatures(const vk::raii::PhysicalDevice& device) {
    auto chain =
        device.getFeatures2<vk::PhysicalDeviceFeatures2, vk::PhysicalDeviceVulkan12Features>();
    const auto& f12 = chain.get<vk::PhysicalDeviceVulkan12Features>();
    return f12.scalarBlockLayout && device.getProperties().apiVersion >= VK_API_VERSION_1_2;
}

bool usable(const vk::raii::PhysicalDevice& device) {
    return computeQueueFamily(device) && supportsRequiredFeatures(device);
}

bool validationLayerInstalled(const vk::raii::Context& context) {
    for (const auto& layer : context.enumerateInstanceLayerProperties())
        if (std::string_view(layer.layerName) == "VK_LAYER_KHRONOS_validation") return true;
    return false;
}

// The device GpuOptions::deviceOverride or PREVIS_VK_DEVICE names, by index or by a part of
// its name.
Result<size_t> deviceNamed(const vk::raii::PhysicalDevices& devices, const std::string& wanted) {
    const bool isIndex =
        std::all_of(wanted.begin(), wanted.end(), [](unsigned char c) { return std::isdigit(c); });
    for (size_t i = 0; i < devices.size(); ++i) {
        std::string name = devices[i].getProperties().deviceName;
        const bool match = isIndex ? std::stoul(wanted) == i
                                   : lowercase(name).find(lowercase(wanted)) != std::string::npos;
        if (!match) continue;
        if (!usable(devices[i]))
            return makeError(
                "Vulkan device '{}' lacks a compute queue or Vulkan 1.2 scalar "
                "block layout; choose another with PREVIS_VK_DEVICE",
                name);
        return i;
    }
    std::string names;
    for (size_t i = 0; i < devices.size(); ++i)
        names += fmt::format(" [{}] {}", i, devices[i].getProperties().deviceName);
    return makeError("PREVIS_VK_DEVICE '{}' matches no Vulkan device; devices:{}", wanted, names);
}

// With no device named: the first usable one of the most preferred type.
Result<size_t> bestDevice(const vk::raii::PhysicalDevices& devices) {
    int bestRank = 0;
    std::optional<size_t> chosen;
    for (size_t i = 0; i < devices.size(); ++i) {
        if (!usable(devices[i])) continue;
        const int rank = deviceTypeRank(devices[i].getProperties().deviceType);
        if (rank > bestRank) {
            bestRank = rank;
            chosen = i;
        }
    }
    if (!chosen)
        return makeError(
            "no Vulkan device with a compute queue and Vulkan 1.2 scalar "
            "block layout was found");
    return *chosen;
}

Result<size_t> chooseDevice(const vk::raii::PhysicalDevices& devices, const GpuOptions& options) {
    if (devices.empty())
        return makeError(
            "no Vulkan device found; install a Vulkan driver (on a machine without a GPU: "
            "Debian package mesa-vulkan-drivers for lavapipe)");
    std::string wanted = options.deviceOverride;
    if (wanted.empty()) {
        if (const char* env = std::getenv("PREVIS_VK_DEVICE")) wanted = env;
    }
    return wanted.empty() ? bestDevice(devices) : deviceNamed(devices, wanted);
}

}  // namespace

VKAPI_ATTR VkBool32 VKAPI_CALL GpuContext::debugCallback(
    VkDebugUtilsMessageSeverityFlagBitsEXT severity, VkDebugUtilsMessageTypeFlagsEXT,
    const VkDebugUtilsMessengerCallbackDataEXT* data, void* user) {
    auto* self = static_cast<GpuContext*>(user);
    if (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT) {
        self->validationErrors_.fetch_add(1);
        logError("Vulkan validation: {}", data->pMessage);
    } else if (severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) {
        logWarning("Vulkan validation: {}", data->pMessage);
    }
    return VK_FALSE;
}

Result<std::unique_ptr<GpuContext>> GpuContext::create(const GpuOptions& options) {
    std::unique_ptr<GpuContext> ctx(new GpuContext());
    ctx->fenceTimeout_ = options.fenceTimeout;
    try {
        std::vector<const char*> layers;
        std::vector<const char*> extensions;
        if (options.validation && validationLayerInstalled(ctx->context_)) {
            layers.push_back("VK_LAYER_KHRONOS_validation");
            extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
            ctx->validationEnabled_ = true;
        } else if (options.validation) {
            logWarning(
                "Vulkan validation requested but VK_LAYER_KHRONOS_validation is not "
                "installed (Debian package vulkan-validationlayers); running without it");
        }
        vk::ApplicationInfo app("previs", 1, "previs", 1, VK_API_VERSION_1_2);
        vk::InstanceCreateInfo instanceInfo({}, &app, layers, extensions);
        ctx->instance_ = vk::raii::Instance(ctx->context_, instanceInfo);
        if (ctx->validationEnabled_) {
            vk::DebugUtilsMessengerCreateInfoEXT messengerInfo(
                {},
                vk::DebugUtilsMessageSeverityFlagBitsEXT::eWarning |
                    vk::DebugUtilsMessageSeverityFlagBitsEXT::eError,
                vk::DebugUtilsMessageTypeFlagBitsEXT::eGeneral |
                    vk::DebugUtilsMessageTypeFlagBitsEXT::eValidation |
                    vk::DebugUtilsMessageTypeFlagBitsEXT::ePerformance,
                &GpuContext::debugCallback, ctx.get());
            ctx->messenger_ = vk::raii::DebugUtilsMessengerEXT(ctx->instance_, messengerInfo);
        }

        vk::raii::PhysicalDevices devices(ctx->instance_);
        keepLavapipeLoadedUnderSanitizers();
        Result<size_t> chosen = chooseDevice(devices, options);
        if (!chosen) return chosen.error();
        ctx->physicalDevice_ = std::move(devices[*chosen]);
        auto props = ctx->physicalDevice_.getProperties();
        ctx->deviceName_ = props.deviceName.data();
        ctx->isCpu_ = props.deviceType == vk::PhysicalDeviceType::eCpu;
        auto properties =
            ctx->physicalDevice_.getProperties2<vk::PhysicalDeviceProperties2,
                                                vk::PhysicalDeviceSubgroupProperties>();
        ctx->subgroupSize_ = properties.get<vk::PhysicalDeviceSubgroupProperties>().subgroupSize;
        ctx->queueFamily_ = *computeQueueFamily(ctx->physicalDevice_);
        auto family = ctx->physicalDevice_.getQueueFamilyProperties()[ctx->queueFamily_];
        if (family.timestampValidBits > 0) ctx->timestampPeriodNs_ = props.limits.timestampPeriod;

        float priority = 1.0f;
        vk::DeviceQueueCreateInfo queueInfo({}, ctx->queueFamily_, 1, &priority);
        vk::StructureChain<vk::DeviceCreateInfo, vk::PhysicalDeviceFeatures2,
                           vk::PhysicalDeviceVulkan12Features>
            chain;
        chain.get<vk::DeviceCreateInfo>().setQueueCreateInfos(queueInfo);
        chain.get<vk::PhysicalDeviceVulkan12Features>().scalarBlockLayout = VK_TRUE;
        ctx->device_ = vk::raii::Device(ctx->physicalDevice_, chain.get<vk::DeviceCreateInfo>());
        ctx->queue_ = vk::raii::Queue(ctx->device_, ctx->queueFamily_, 0);
        ctx->commandPool_ = vk::raii::CommandPool(
            ctx->device_,
            vk::CommandPoolCreateInfo(vk::CommandPoolCreateFlagBits::eResetCommandBuffer,
                                      ctx->queueFamily_));
        ctx->fence_ = vk::raii::Fence(ctx->device_, vk::FenceCreateInfo());
        logDebug("Vulkan device: {}", ctx->deviceName_);
    } catch (const std::exception& e) {
        return makeError("Vulkan initialisation failed: {}", e.what());
    }
    return Result<std::unique_ptr<GpuContext>>(std::move(ctx));
}

GpuContext::~GpuContext() {
    // The C entry point: vk::raii's waitIdle() throws on VK_ERROR_DEVICE_LOST, and a throw from
    // a destructor is std::terminate. A lost or hung device is not waited for: its objects are
    // destroyed as they are (what the driver can still do).
    if (*device_ && !deviceLost_.load()) {
        const VkResult r =
            device_.getDispatcher()->vkDeviceWaitIdle(static_cast<VkDevice>(*device_));
        if (r != VK_SUCCESS)
            logError("Vulkan device '{}': waiting for it to finish failed ({})", deviceName_,
                     vk::to_string(vk::Result(r)));
    }
    // The pipelines kept for reuse (ComputePipeline::create) go before the device.
    releaseCompiledPipelines(*this);
}

uint32_t GpuContext::findMemoryType(uint32_t typeBits, vk::MemoryPropertyFlags required,
                                    vk::MemoryPropertyFlags preferred) const {
    auto memory = physicalDevice_.getMemoryProperties();
    for (auto want : {required | preferred, required}) {
        for (uint32_t i = 0; i < memory.memoryTypeCount; ++i) {
            if ((typeBits & (1u << i)) && (memory.memoryTypes[i].propertyFlags & want) == want)
                return i;
        }
    }
    return UINT32_MAX;
}

Status GpuContext::submitAndWait(
    const std::function<void(const vk::raii::CommandBuffer&)>& record) {
    try {
        vk::raii::CommandBuffers buffers(
            device_,
            vk::CommandBufferAllocateInfo(*commandPool_, vk::CommandBufferLevel::ePrimary, 1));
        const vk::raii::CommandBuffer& cmd = buffers[0];
        cmd.begin(vk::CommandBufferBeginInfo(vk::CommandBufferUsageFlagBits::eOneTimeSubmit));
        record(cmd);
        cmd.end();
        device_.resetFences(*fence_);
        vk::CommandBuffer raw = *cmd;
        queue_.submit(vk::SubmitInfo({}, {}, raw), *fence_);
        const uint64_t timeoutNs =
            uint64_t(std::chrono::duration_cast<std::chrono::nanoseconds>(fenceTimeout_).count());
        if (device_.waitForFences(*fence_, VK_TRUE, timeoutNs) == vk::Result::eTimeout) {
            deviceLost_ = true;
            // The submission still holds its command buffer: freeing it now is invalid, and
            // lavapipe's queue thread read the freed memory (a segfault in 1 of 30 runs of
            // GpuContextTest.ASubmissionThatDoesNotFinishInTimeIsAnError). The pool frees it
            // when the context goes.
            (void)buffers[0].release();
            return makeError(
                "the GPU '{}' did not finish a submission in {} s: the device hangs (a driver or "
                "a shader); previs stops rather than wait forever",
                deviceName_, fenceTimeout_.count() / 1000.0);
        }
    } catch (const vk::DeviceLostError& e) {
        deviceLost_ = true;
        return makeError(
            "the GPU '{}' was lost (VK_ERROR_DEVICE_LOST: a driver reset or a GPU fault): {}",
            deviceName_, e.what());
    } catch (const std::exception& e) {
        return makeError("Vulkan submission failed on '{}': {}", deviceName_, e.what());
    }
    return {};
}

}  // namespace previs
