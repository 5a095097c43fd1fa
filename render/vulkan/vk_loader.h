// Private to libmr: the Vulkan loader, opened at run time (dlopen of libvulkan.so.1), so that
// libmr starts, and falls back to the CPU backend, on systems without Vulkan.
#pragma once

#define VK_NO_PROTOTYPES
#include <vulkan/vulkan.h>

#include <string>

namespace mr::render::vulkan {

/// The entry points (see vk_functions.inc), filled in stages: global (load_global), then per
/// instance and per device. One table per Context.
struct Functions {
  PFN_vkGetInstanceProcAddr vkGetInstanceProcAddr = nullptr;
#define MR_VK_GLOBAL(name) PFN_##name name = nullptr;
#define MR_VK_INSTANCE(name) PFN_##name name = nullptr;
#define MR_VK_INSTANCE_OPTIONAL(name) PFN_##name name = nullptr;
#define MR_VK_DEVICE(name) PFN_##name name = nullptr;
#include "render/vulkan/vk_functions.inc"
#undef MR_VK_GLOBAL
#undef MR_VK_INSTANCE
#undef MR_VK_INSTANCE_OPTIONAL
#undef MR_VK_DEVICE

  /// Opens the loader library (once per process) and loads the global entry points. Throws
  /// Unavailable when there is no loader.
  void load_global();
  void load_instance(VkInstance instance);
  void load_device(VkDevice device);
};

/// "VK_ERROR_OUT_OF_DEVICE_MEMORY" etc.
const char* result_name(VkResult r);

/// Throws Unavailable (for results that mean "no usable Vulkan here": no driver, no device,
/// out of memory, device lost) or mr::Error(internal) naming `what` and the result.
void check(VkResult r, const char* what);

}  // namespace mr::render::vulkan
