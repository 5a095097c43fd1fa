// Private to libmr: a Vulkan instance + device + compute/graphics queue, and RAII owners for the
// objects the backend creates (each destroys its handle with the context's entry points).
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "render/vulkan/vk_loader.h"
#include "render/vulkan/vulkan_backend.h"

namespace mr::render::vulkan {

/// A zero-initialised Vulkan struct with its sType set.
template <class T>
T make(VkStructureType type) {
  T v{};
  v.sType = type;
  return v;
}

struct ContextOptions {
  bool validation = false;
  std::string device_filter;  ///< substring of the device name; empty: the best device
  /// Throw Unavailable when the best device is a CPU implementation (lavapipe), before a
  /// device is created or a pipeline compiled: Backend::automatic's cheap probe.
  bool reject_cpu_implementation = false;
};

class Context {
 public:
  /// Throws Unavailable.
  explicit Context(const ContextOptions& options);
  ~Context();
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;

  Functions vk;
  VkInstance instance = VK_NULL_HANDLE;
  VkDebugUtilsMessengerEXT messenger = VK_NULL_HANDLE;
  VkPhysicalDevice physical = VK_NULL_HANDLE;
  VkDevice device = VK_NULL_HANDLE;
  VkQueue queue = VK_NULL_HANDLE;
  std::uint32_t queue_family = 0;
  std::uint32_t timestamp_valid_bits = 0;
  VkPhysicalDeviceProperties properties{};
  VkPhysicalDeviceMemoryProperties memory{};
  DeviceInfo info;
  bool validation = false;

  /// A memory type among `type_bits` with all of `want` (else all of `fallback`). Throws.
  std::uint32_t memory_type(std::uint32_t type_bits, VkMemoryPropertyFlags want,
                            VkMemoryPropertyFlags fallback) const;

  // Validation messages (warnings and errors), counted by the debug messenger.
  std::atomic<std::size_t> validation_count{0};
  mutable std::mutex log_mutex;
  std::string validation_log;
};

/// Owner of one Vulkan handle, destroyed with the context's entry points.
template <class T>
class Unique {
 public:
  using Deleter = void (*)(const Context&, T);
  Unique() = default;
  Unique(const Context& ctx, T handle, Deleter deleter) : ctx_(&ctx), handle_(handle), deleter_(deleter) {}
  ~Unique() { reset(); }
  Unique(Unique&& o) noexcept
      : ctx_(o.ctx_), handle_(std::exchange(o.handle_, T(VK_NULL_HANDLE))), deleter_(o.deleter_) {}
  Unique& operator=(Unique&& o) noexcept {
    if (this != &o) {
      reset();
      ctx_ = o.ctx_;
      handle_ = std::exchange(o.handle_, T(VK_NULL_HANDLE));
      deleter_ = o.deleter_;
    }
    return *this;
  }
  Unique(const Unique&) = delete;
  Unique& operator=(const Unique&) = delete;
  T get() const { return handle_; }
  void reset() {
    if (handle_ != T(VK_NULL_HANDLE) && ctx_ && deleter_) deleter_(*ctx_, handle_);
    handle_ = T(VK_NULL_HANDLE);
  }

 private:
  const Context* ctx_ = nullptr;
  T handle_ = T(VK_NULL_HANDLE);
  Deleter deleter_ = nullptr;
};

/// A buffer with its own memory. Host-visible buffers stay mapped (`mapped`).
class Buffer {
 public:
  Buffer() = default;
  Buffer(const Context& ctx, VkDeviceSize size, VkBufferUsageFlags usage, bool host_visible);
  ~Buffer() { reset(); }
  Buffer(Buffer&& o) noexcept { *this = std::move(o); }
  Buffer& operator=(Buffer&& o) noexcept;
  Buffer(const Buffer&) = delete;
  Buffer& operator=(const Buffer&) = delete;
  void reset();

  VkBuffer handle = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkDeviceSize size = 0;
  void* mapped = nullptr;

 private:
  const Context* ctx_ = nullptr;
};

/// A 2D (array) image with its own memory and one view per layer plus a view of all layers.
class Image2D {
 public:
  Image2D() = default;
  Image2D(const Context& ctx, VkFormat format, std::uint32_t width, std::uint32_t height,
          std::uint32_t layers, VkImageUsageFlags usage, VkImageAspectFlags aspect);
  ~Image2D() { reset(); }
  Image2D(Image2D&& o) noexcept { *this = std::move(o); }
  Image2D& operator=(Image2D&& o) noexcept;
  Image2D(const Image2D&) = delete;
  Image2D& operator=(const Image2D&) = delete;
  void reset();

  VkImage handle = VK_NULL_HANDLE;
  VkDeviceMemory memory = VK_NULL_HANDLE;
  VkImageView all_layers = VK_NULL_HANDLE;  ///< 2D array view
  std::vector<VkImageView> layer_views;     ///< 2D view of each layer
  std::uint32_t width = 0, height = 0, layers = 0;

 private:
  const Context* ctx_ = nullptr;
};

}  // namespace mr::render::vulkan
