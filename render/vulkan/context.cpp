#include "render/vulkan/context.h"

#include <cstdio>
#include <cstring>

#include "mr/error.h"

namespace mr::render::vulkan {

namespace {

VKAPI_ATTR VkBool32 VKAPI_CALL on_validation_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                     VkDebugUtilsMessageTypeFlagsEXT,
                                                     const VkDebugUtilsMessengerCallbackDataEXT* data,
                                                     void* user) {
  auto* ctx = static_cast<Context*>(user);
  if (severity >= VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT) {
    const std::size_t n = ctx->validation_count.fetch_add(1);
    if (n < 8) {
      std::lock_guard lock(ctx->log_mutex);
      ctx->validation_log += std::string(data && data->pMessage ? data->pMessage : "?") + "\n";
    }
  }
  return VK_FALSE;
}

int device_rank(VkPhysicalDeviceType type) {
  switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return 4;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return 3;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return 2;
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return 1;
    default: return 0;
  }
}

const char* type_name(VkPhysicalDeviceType type) {
  switch (type) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return "discrete GPU";
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return "integrated GPU";
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return "virtual GPU";
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return "CPU";
    default: return "other";
  }
}

}  // namespace

Context::Context(const ContextOptions& options) {
  vk.load_global();
  std::uint32_t api = VK_API_VERSION_1_0;
  vk.vkEnumerateInstanceVersion(&api);
  if (api < VK_API_VERSION_1_3) throw Unavailable("the Vulkan loader is older than 1.3");

  std::vector<const char*> layers, extensions;
  if (options.validation) {
    std::uint32_t n = 0;
    vk.vkEnumerateInstanceLayerProperties(&n, nullptr);
    std::vector<VkLayerProperties> available(n);
    vk.vkEnumerateInstanceLayerProperties(&n, available.data());
    for (const auto& l : available)
      if (std::strcmp(l.layerName, "VK_LAYER_KHRONOS_validation") == 0) validation = true;
    if (!validation)
      throw Error(ErrorCode::invalid_argument,
                  "vulkan: validation requested but VK_LAYER_KHRONOS_validation is not installed "
                  "(Debian: vulkan-validationlayers)");
    layers.push_back("VK_LAYER_KHRONOS_validation");
    extensions.push_back(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
  }

  VkApplicationInfo app = make<VkApplicationInfo>(VK_STRUCTURE_TYPE_APPLICATION_INFO);
  app.pApplicationName = "libmr";
  app.pEngineName = "libmr";
  app.apiVersion = VK_API_VERSION_1_3;
  VkDebugUtilsMessengerCreateInfoEXT messenger_info = make<VkDebugUtilsMessengerCreateInfoEXT>(VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT);
  messenger_info.messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT |
                                   VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
  messenger_info.messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT |
                               VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                               VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT;
  messenger_info.pfnUserCallback = on_validation_message;
  messenger_info.pUserData = this;
  VkInstanceCreateInfo ici = make<VkInstanceCreateInfo>(VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO);
  ici.pNext = validation ? &messenger_info : nullptr;  // also covers instance creation
  ici.pApplicationInfo = &app;
  ici.enabledLayerCount = std::uint32_t(layers.size());
  ici.ppEnabledLayerNames = layers.data();
  ici.enabledExtensionCount = std::uint32_t(extensions.size());
  ici.ppEnabledExtensionNames = extensions.data();
  check(vk.vkCreateInstance(&ici, nullptr, &instance), "vkCreateInstance");
  try {
    vk.load_instance(instance);
    if (validation) {
      if (!vk.vkCreateDebugUtilsMessengerEXT) throw Unavailable("no VK_EXT_debug_utils");
      check(vk.vkCreateDebugUtilsMessengerEXT(instance, &messenger_info, nullptr, &messenger),
            "vkCreateDebugUtilsMessengerEXT");
    }

    std::uint32_t count = 0;
    check(vk.vkEnumeratePhysicalDevices(instance, &count, nullptr), "vkEnumeratePhysicalDevices");
    std::vector<VkPhysicalDevice> devices(count);
    if (count) check(vk.vkEnumeratePhysicalDevices(instance, &count, devices.data()), "vkEnumeratePhysicalDevices");
    if (count == 0) throw Unavailable("no Vulkan device");
    int best_rank = -1;
    std::string rejected;
    for (VkPhysicalDevice pd : devices) {
      VkPhysicalDeviceProperties p;
      vk.vkGetPhysicalDeviceProperties(pd, &p);
      const std::string name = p.deviceName;
      auto reject = [&](const std::string& why) {
        rejected += (rejected.empty() ? "" : "; ") + name + ": " + why;
      };
      if (!options.device_filter.empty() && name.find(options.device_filter) == std::string::npos) {
        reject("not $MR_VULKAN_DEVICE");
        continue;
      }
      if (p.apiVersion < VK_API_VERSION_1_3) {
        reject("Vulkan < 1.3");
        continue;
      }
      std::uint32_t nq = 0;
      vk.vkGetPhysicalDeviceQueueFamilyProperties(pd, &nq, nullptr);
      std::vector<VkQueueFamilyProperties> families(nq);
      vk.vkGetPhysicalDeviceQueueFamilyProperties(pd, &nq, families.data());
      int family = -1;
      for (std::uint32_t i = 0; i < nq; ++i)
        if ((families[i].queueFlags & (VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT)) ==
            (VK_QUEUE_GRAPHICS_BIT | VK_QUEUE_COMPUTE_BIT)) {
          family = int(i);
          break;
        }
      if (family < 0) {
        reject("no graphics + compute queue");
        continue;
      }
      VkFormatProperties fp;
      vk.vkGetPhysicalDeviceFormatProperties(pd, VK_FORMAT_R32_SFLOAT, &fp);
      const VkFormatFeatureFlags need = VK_FORMAT_FEATURE_COLOR_ATTACHMENT_BIT | VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT;
      VkFormatProperties dp;
      vk.vkGetPhysicalDeviceFormatProperties(pd, VK_FORMAT_D32_SFLOAT, &dp);
      if ((fp.optimalTilingFeatures & need) != need ||
          !(dp.optimalTilingFeatures & VK_FORMAT_FEATURE_DEPTH_STENCIL_ATTACHMENT_BIT)) {
        reject("no R32_SFLOAT / D32_SFLOAT attachments");
        continue;
      }
      const int rank = device_rank(p.deviceType);
      if (rank > best_rank) {
        best_rank = rank;
        physical = pd;
        properties = p;
        queue_family = std::uint32_t(family);
        timestamp_valid_bits = families[std::size_t(family)].timestampValidBits;
      }
    }
    if (!physical) throw Unavailable("no usable Vulkan device (" + rejected + ")");
    info.name = properties.deviceName;
    info.type = type_name(properties.deviceType);
    info.cpu_implementation = properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
    if (options.reject_cpu_implementation && info.cpu_implementation)
      throw Unavailable("only a software device (" + info.name + ")");
    vk.vkGetPhysicalDeviceMemoryProperties(physical, &memory);

    const float priority = 1.0f;
    VkDeviceQueueCreateInfo qci = make<VkDeviceQueueCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO);
    qci.queueFamilyIndex = queue_family;
    qci.queueCount = 1;
    qci.pQueuePriorities = &priority;
    VkPhysicalDeviceVulkan13Features f13 = make<VkPhysicalDeviceVulkan13Features>(VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_3_FEATURES);
    f13.dynamicRendering = VK_TRUE;
    f13.maintenance4 = VK_TRUE;  // core in 1.3: shaders size workgroups with a constant (LocalSizeId)
    VkPhysicalDeviceFeatures supported{};
    vk.vkGetPhysicalDeviceFeatures(physical, &supported);
    VkPhysicalDeviceFeatures enabled{};
    enabled.fullDrawIndexUint32 = supported.fullDrawIndexUint32;  // meshes of > 2^24 vertices
    VkDeviceCreateInfo dci = make<VkDeviceCreateInfo>(VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO);
    dci.pNext = &f13;
    dci.pEnabledFeatures = &enabled;
    dci.queueCreateInfoCount = 1;
    dci.pQueueCreateInfos = &qci;
    check(vk.vkCreateDevice(physical, &dci, nullptr, &device), "vkCreateDevice");
    vk.load_device(device);
    vk.vkGetDeviceQueue(device, queue_family, 0, &queue);
  } catch (...) {
    if (device) vk.vkDestroyDevice(device, nullptr);
    if (messenger) vk.vkDestroyDebugUtilsMessengerEXT(instance, messenger, nullptr);
    if (vk.vkDestroyInstance) vk.vkDestroyInstance(instance, nullptr);
    throw;
  }
}

Context::~Context() {
  if (device) {
    vk.vkDeviceWaitIdle(device);
    vk.vkDestroyDevice(device, nullptr);
  }
  if (messenger) vk.vkDestroyDebugUtilsMessengerEXT(instance, messenger, nullptr);
  if (instance) vk.vkDestroyInstance(instance, nullptr);
}

std::uint32_t Context::memory_type(std::uint32_t type_bits, VkMemoryPropertyFlags want,
                                   VkMemoryPropertyFlags fallback) const {
  for (VkMemoryPropertyFlags flags : {want, fallback})
    for (std::uint32_t i = 0; i < memory.memoryTypeCount; ++i)
      if ((type_bits & (1u << i)) && (memory.memoryTypes[i].propertyFlags & flags) == flags) return i;
  throw Unavailable("no suitable memory type");
}

Buffer::Buffer(const Context& ctx, VkDeviceSize size_, VkBufferUsageFlags usage, bool host_visible)
    : size(size_), ctx_(&ctx) {
  VkBufferCreateInfo bci = make<VkBufferCreateInfo>(VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO);
  bci.size = size;
  bci.usage = usage;
  bci.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  check(ctx.vk.vkCreateBuffer(ctx.device, &bci, nullptr, &handle), "vkCreateBuffer");
  try {
    VkMemoryRequirements req;
    ctx.vk.vkGetBufferMemoryRequirements(ctx.device, handle, &req);
    VkMemoryAllocateInfo mai = make<VkMemoryAllocateInfo>(VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO);
    mai.allocationSize = req.size;
    mai.memoryTypeIndex =
        host_visible
            ? ctx.memory_type(req.memoryTypeBits,
                              VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT |
                                  VK_MEMORY_PROPERTY_HOST_CACHED_BIT,
                              VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT)
            : ctx.memory_type(req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, 0);
    check(ctx.vk.vkAllocateMemory(ctx.device, &mai, nullptr, &memory), "vkAllocateMemory (buffer)");
    check(ctx.vk.vkBindBufferMemory(ctx.device, handle, memory, 0), "vkBindBufferMemory");
    if (host_visible) check(ctx.vk.vkMapMemory(ctx.device, memory, 0, VK_WHOLE_SIZE, 0, &mapped), "vkMapMemory");
  } catch (...) {
    reset();
    throw;
  }
}

Buffer& Buffer::operator=(Buffer&& o) noexcept {
  if (this != &o) {
    reset();
    ctx_ = o.ctx_;
    handle = std::exchange(o.handle, VK_NULL_HANDLE);
    memory = std::exchange(o.memory, VK_NULL_HANDLE);
    size = std::exchange(o.size, 0);
    mapped = std::exchange(o.mapped, nullptr);
  }
  return *this;
}

void Buffer::reset() {
  if (!ctx_) return;
  if (handle) ctx_->vk.vkDestroyBuffer(ctx_->device, handle, nullptr);
  if (memory) ctx_->vk.vkFreeMemory(ctx_->device, memory, nullptr);  // unmaps implicitly
  handle = VK_NULL_HANDLE;
  memory = VK_NULL_HANDLE;
  mapped = nullptr;
  size = 0;
}

Image2D::Image2D(const Context& ctx, VkFormat format, std::uint32_t w, std::uint32_t h,
                 std::uint32_t n_layers, VkImageUsageFlags usage, VkImageAspectFlags aspect)
    : width(w), height(h), layers(n_layers), ctx_(&ctx) {
  VkImageCreateInfo ici = make<VkImageCreateInfo>(VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO);
  ici.imageType = VK_IMAGE_TYPE_2D;
  ici.format = format;
  ici.extent = {w, h, 1};
  ici.mipLevels = 1;
  ici.arrayLayers = n_layers;
  ici.samples = VK_SAMPLE_COUNT_1_BIT;
  ici.tiling = VK_IMAGE_TILING_OPTIMAL;
  ici.usage = usage;
  ici.sharingMode = VK_SHARING_MODE_EXCLUSIVE;
  ici.initialLayout = VK_IMAGE_LAYOUT_UNDEFINED;
  check(ctx.vk.vkCreateImage(ctx.device, &ici, nullptr, &handle), "vkCreateImage");
  try {
    VkMemoryRequirements req;
    ctx.vk.vkGetImageMemoryRequirements(ctx.device, handle, &req);
    VkMemoryAllocateInfo mai = make<VkMemoryAllocateInfo>(VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO);
    mai.allocationSize = req.size;
    mai.memoryTypeIndex = ctx.memory_type(req.memoryTypeBits, VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT, 0);
    check(ctx.vk.vkAllocateMemory(ctx.device, &mai, nullptr, &memory), "vkAllocateMemory (image)");
    check(ctx.vk.vkBindImageMemory(ctx.device, handle, memory, 0), "vkBindImageMemory");
    VkImageViewCreateInfo vci = make<VkImageViewCreateInfo>(VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO);
    vci.image = handle;
    vci.viewType = VK_IMAGE_VIEW_TYPE_2D_ARRAY;
    vci.format = format;
    vci.subresourceRange = {aspect, 0, 1, 0, n_layers};
    check(ctx.vk.vkCreateImageView(ctx.device, &vci, nullptr, &all_layers), "vkCreateImageView");
    if (usage & (VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT))
      for (std::uint32_t l = 0; l < n_layers; ++l) {
        vci.viewType = VK_IMAGE_VIEW_TYPE_2D;
        vci.subresourceRange = {aspect, 0, 1, l, 1};
        VkImageView v = VK_NULL_HANDLE;
        check(ctx.vk.vkCreateImageView(ctx.device, &vci, nullptr, &v), "vkCreateImageView");
        layer_views.push_back(v);
      }
  } catch (...) {
    reset();
    throw;
  }
}

Image2D& Image2D::operator=(Image2D&& o) noexcept {
  if (this != &o) {
    reset();
    ctx_ = o.ctx_;
    handle = std::exchange(o.handle, VK_NULL_HANDLE);
    memory = std::exchange(o.memory, VK_NULL_HANDLE);
    all_layers = std::exchange(o.all_layers, VK_NULL_HANDLE);
    layer_views = std::move(o.layer_views);
    o.layer_views.clear();
    width = o.width;
    height = o.height;
    layers = o.layers;
  }
  return *this;
}

void Image2D::reset() {
  if (!ctx_) return;
  for (VkImageView v : layer_views) ctx_->vk.vkDestroyImageView(ctx_->device, v, nullptr);
  layer_views.clear();
  if (all_layers) ctx_->vk.vkDestroyImageView(ctx_->device, all_layers, nullptr);
  if (handle) ctx_->vk.vkDestroyImage(ctx_->device, handle, nullptr);
  if (memory) ctx_->vk.vkFreeMemory(ctx_->device, memory, nullptr);
  all_layers = VK_NULL_HANDLE;
  handle = VK_NULL_HANDLE;
  memory = VK_NULL_HANDLE;
}

}  // namespace mr::render::vulkan
