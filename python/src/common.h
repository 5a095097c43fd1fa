// Shared pieces of the `libmr` Python module (issue 15): numpy <-> mr::Image, argument parsing,
// and the binding functions of each file. Only libmr's public API (libmr/include/mr/) is used.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl_bind.h>

#include <optional>
#include <string>
#include <vector>

#include "mr/error.h"
#include "mr/image.h"
#include "mr/io.h"
#include "mr/scene.h"

// Lamps are edited in place from Python (scene.lighting.lamps.append(...), lamps[0].position_m =
// ...), so their list is a bound type, not a copy converted to a Python list.
PYBIND11_MAKE_OPAQUE(std::vector<mr::Lamp>)

namespace mrpy {

namespace py = pybind11;

/// Name of the capsules that own the mr::Image behind an array libmr returned.
inline constexpr const char* kImageCapsule = "libmr.Image";

/// An mr::Image handed to Python as a numpy float32 array (H, W, C) without a copy: the array
/// points at the image's pixels and its base, a capsule, owns the image (and its metadata).
/// An empty image becomes None.
py::object to_array(mr::Image&& image);

/// The mr::Image that `array` shows exactly (the same pixels, shape and strides), when it is an
/// array libmr returned (or a view equal to it); else nullptr.
const mr::Image* backing_image(py::handle array);

/// An image argument from Python. Arrays libmr returned are used in place (no copy); any other
/// float32 array of shape (H, W, C) or (H, W) is copied once into an mr::Image, whatever its
/// strides. `metadata` (not null) replaces the image's metadata, which needs a copy too.
class ImageArg {
 public:
  ImageArg() = default;
  ImageArg(py::handle object, const std::string& what, const mr::Metadata* metadata = nullptr);
  const mr::Image& image() const { return borrowed_ ? *borrowed_ : owned_; }
  bool copied() const { return borrowed_ == nullptr; }
  /// The image to keep: the copy itself, or a copy of a borrowed one.
  mr::Image take() && { return borrowed_ ? mr::Image(*borrowed_) : std::move(owned_); }

 private:
  py::object keep_alive_;  // the array, so that a borrowed image outlives the call
  const mr::Image* borrowed_ = nullptr;
  mr::Image owned_;
};

/// A writable view of a float32 array's pixels, for in-place operations (colour conversion).
/// Throws mr::Error(invalid_argument) unless the array is writable, (H, W, C) or (H, W), and its
/// channels and pixels are packed (rows may be padded or strided).
mr::ImageView writable_view(py::handle array, const std::string& what);

/// Throws mr::Error(ErrorCode::invalid_argument) with `message`.
[[noreturn]] void invalid(const std::string& message);

/// A filesystem path from str / bytes / os.PathLike.
std::string path_arg(py::handle path, const char* what);

/// "automatic", "8", "16", "half", "float" or a PixelType.
mr::PixelType pixel_type_arg(py::handle value);

void bind_errors(py::module_& m);
void bind_images(py::module_& m);
void bind_scene(py::module_& m);
void bind_operations(py::module_& m);

}  // namespace mrpy
