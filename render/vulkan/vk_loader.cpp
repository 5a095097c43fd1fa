#include "render/vulkan/vk_loader.h"

#include <dlfcn.h>

#include <mutex>

#include "mr/error.h"
#include "render/vulkan/vulkan_backend.h"

namespace mr::render::vulkan {

namespace {

// The loader stays open for the life of the process (closing it while a driver's threads or
// atexit handlers may still run is unsafe).
PFN_vkGetInstanceProcAddr open_loader() {
  static std::once_flag once;
  static PFN_vkGetInstanceProcAddr gipa = nullptr;
  std::call_once(once, [] {
    for (const char* name : {"libvulkan.so.1", "libvulkan.so"}) {
      if (void* lib = dlopen(name, RTLD_NOW | RTLD_LOCAL)) {
        gipa = reinterpret_cast<PFN_vkGetInstanceProcAddr>(dlsym(lib, "vkGetInstanceProcAddr"));
        if (gipa) break;
      }
    }
  });
  return gipa;
}

}  // namespace

void Functions::load_global() {
  vkGetInstanceProcAddr = open_loader();
  if (!vkGetInstanceProcAddr) throw Unavailable("no Vulkan loader (libvulkan.so.1)");
#define MR_VK_GLOBAL(name)                                                         \
  name = reinterpret_cast<PFN_##name>(vkGetInstanceProcAddr(nullptr, #name));      \
  if (!name) throw Unavailable("the Vulkan loader lacks " #name);
#define MR_VK_INSTANCE(name)
#define MR_VK_INSTANCE_OPTIONAL(name)
#define MR_VK_DEVICE(name)
#include "render/vulkan/vk_functions.inc"
#undef MR_VK_GLOBAL
#undef MR_VK_INSTANCE
#undef MR_VK_INSTANCE_OPTIONAL
#undef MR_VK_DEVICE
}

void Functions::load_instance(VkInstance instance) {
#define MR_VK_GLOBAL(name)
#define MR_VK_INSTANCE(name)                                                       \
  name = reinterpret_cast<PFN_##name>(vkGetInstanceProcAddr(instance, #name));     \
  if (!name) throw Unavailable("the Vulkan instance lacks " #name);
#define MR_VK_INSTANCE_OPTIONAL(name) \
  name = reinterpret_cast<PFN_##name>(vkGetInstanceProcAddr(instance, #name));
#define MR_VK_DEVICE(name)
#include "render/vulkan/vk_functions.inc"
#undef MR_VK_GLOBAL
#undef MR_VK_INSTANCE
#undef MR_VK_INSTANCE_OPTIONAL
#undef MR_VK_DEVICE
}

void Functions::load_device(VkDevice device) {
#define MR_VK_GLOBAL(name)
#define MR_VK_INSTANCE(name)
#define MR_VK_INSTANCE_OPTIONAL(name)
#define MR_VK_DEVICE(name)                                                       \
  name = reinterpret_cast<PFN_##name>(vkGetDeviceProcAddr(device, #name));       \
  if (!name) throw Unavailable("the Vulkan device lacks " #name);
#include "render/vulkan/vk_functions.inc"
#undef MR_VK_GLOBAL
#undef MR_VK_INSTANCE
#undef MR_VK_INSTANCE_OPTIONAL
#undef MR_VK_DEVICE
}

const char* result_name(VkResult r) {
  switch (r) {
    case VK_SUCCESS: return "VK_SUCCESS";
    case VK_NOT_READY: return "VK_NOT_READY";
    case VK_TIMEOUT: return "VK_TIMEOUT";
    case VK_INCOMPLETE: return "VK_INCOMPLETE";
    case VK_ERROR_OUT_OF_HOST_MEMORY: return "VK_ERROR_OUT_OF_HOST_MEMORY";
    case VK_ERROR_OUT_OF_DEVICE_MEMORY: return "VK_ERROR_OUT_OF_DEVICE_MEMORY";
    case VK_ERROR_INITIALIZATION_FAILED: return "VK_ERROR_INITIALIZATION_FAILED";
    case VK_ERROR_DEVICE_LOST: return "VK_ERROR_DEVICE_LOST";
    case VK_ERROR_MEMORY_MAP_FAILED: return "VK_ERROR_MEMORY_MAP_FAILED";
    case VK_ERROR_LAYER_NOT_PRESENT: return "VK_ERROR_LAYER_NOT_PRESENT";
    case VK_ERROR_EXTENSION_NOT_PRESENT: return "VK_ERROR_EXTENSION_NOT_PRESENT";
    case VK_ERROR_FEATURE_NOT_PRESENT: return "VK_ERROR_FEATURE_NOT_PRESENT";
    case VK_ERROR_INCOMPATIBLE_DRIVER: return "VK_ERROR_INCOMPATIBLE_DRIVER";
    case VK_ERROR_TOO_MANY_OBJECTS: return "VK_ERROR_TOO_MANY_OBJECTS";
    case VK_ERROR_FORMAT_NOT_SUPPORTED: return "VK_ERROR_FORMAT_NOT_SUPPORTED";
    case VK_ERROR_OUT_OF_POOL_MEMORY: return "VK_ERROR_OUT_OF_POOL_MEMORY";
    default: return "VkResult error";
  }
}

void check(VkResult r, const char* what) {
  if (r == VK_SUCCESS) return;
  const std::string message = std::string(what) + " failed: " + result_name(r) + " (" + std::to_string(int(r)) + ")";
  switch (r) {
    case VK_ERROR_OUT_OF_HOST_MEMORY:
    case VK_ERROR_OUT_OF_DEVICE_MEMORY:
    case VK_ERROR_INITIALIZATION_FAILED:
    case VK_ERROR_DEVICE_LOST:
    case VK_ERROR_INCOMPATIBLE_DRIVER:
    case VK_ERROR_FEATURE_NOT_PRESENT:
    case VK_ERROR_EXTENSION_NOT_PRESENT:
    case VK_ERROR_TOO_MANY_OBJECTS:
      throw Unavailable(message);
    default:
      throw Error(ErrorCode::internal, "vulkan: " + message);
  }
}

}  // namespace mr::render::vulkan
