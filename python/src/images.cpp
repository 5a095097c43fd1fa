// numpy <-> mr::Image, metadata, colour (OpenColorIO), image files (OpenImageIO), cancellation.
#include <Python.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>

#include "common.h"
#include "mr/cancel.h"
#include "mr/color.h"
#include "mr/io.h"
#include "mr/metadata.h"

namespace mrpy {

void invalid(const std::string& message) {
  throw mr::Error(mr::ErrorCode::invalid_argument, message);
}

namespace {

void destroy_image_capsule(PyObject* capsule) {
  delete static_cast<mr::Image*>(PyCapsule_GetPointer(capsule, kImageCapsule));
}

std::string shape_text(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t i = 0; i < a.ndim(); ++i) s += (i ? ", " : "") + std::to_string(a.shape(i));
  return s + (a.ndim() == 1 ? ",)" : ")");
}

// The float32 array behind `object`, with its shape checked: (H, W, C) or (H, W).
py::array float_array(py::handle object, const std::string& what) {
  if (!py::isinstance<py::array>(object))
    invalid(what + ": expected a numpy float32 array of shape (H, W, C) or (H, W), got " +
            std::string(py::str(py::type::handle_of(object).attr("__name__"))));
  py::array a = py::reinterpret_borrow<py::array>(object);
  if (!py::isinstance<py::array_t<float>>(a))
    invalid(what + ": expected dtype float32, got " + std::string(py::str(a.dtype())) +
            " (convert with .astype(numpy.float32))");
  if (a.ndim() != 2 && a.ndim() != 3)
    invalid(what + ": expected shape (H, W, C) or (H, W), got " + shape_text(a));
  if (a.shape(0) <= 0 || a.shape(1) <= 0 || (a.ndim() == 3 && a.shape(2) <= 0))
    invalid(what + ": empty image, shape " + shape_text(a));
  if (a.shape(0) > (1 << 30) || a.shape(1) > (1 << 30) || (a.ndim() == 3 && a.shape(2) > 1024))
    invalid(what + ": absurd shape " + shape_text(a));
  return a;
}

mr::Metadata metadata_from_dict(py::handle mapping) {
  mr::Metadata md;
  for (auto item : py::reinterpret_borrow<py::dict>(mapping)) {
    const std::string name = py::str(item.first);
    if (py::isinstance<py::str>(item.second))
      md.set(name, item.second.cast<std::string>());
    else
      md.set(name, item.second.cast<double>());
  }
  return md;
}

py::object metadata_value(const mr::Metadata& md, const std::string& name) {
  if (const auto number = md.get_number(name)) {
    // A number whose text is not the number itself (an array, a rational) reads as text.
    const auto text = md.get_string(name);
    if (text && text->find_first_of(" ,/") == std::string::npos) return py::float_(*number);
  }
  if (const auto text = md.get_string(name)) return py::str(*text);
  throw py::key_error(name);
}

// A ColorConfig argument: a ColorConfig, a path to a config file, or None ($OCIO, else builtin).
mr::ColorConfig color_arg(py::handle value) {
  if (value.is_none()) return mr::ColorConfig::from_environment();
  if (py::isinstance<mr::ColorConfig>(value)) return value.cast<mr::ColorConfig>();
  return mr::ColorConfig::from_file(path_arg(value, "color"));
}

}  // namespace

py::object to_array(mr::Image&& image) {
  if (image.empty()) return py::none();
  auto owned = std::make_unique<mr::Image>(std::move(image));
  PyObject* capsule = PyCapsule_New(owned.get(), kImageCapsule, &destroy_image_capsule);
  if (!capsule) throw py::error_already_set();
  mr::Image* img = owned.release();  // the capsule owns it now
  py::object base = py::reinterpret_steal<py::object>(capsule);
  const py::ssize_t f = sizeof(float);
  const std::vector<py::ssize_t> shape{img->height(), img->width(), img->channels()};
  const std::vector<py::ssize_t> strides{img->row_stride() * f, img->channels() * f, f};
  return py::array(py::dtype::of<float>(), shape, strides, img->data(), base);
}

const mr::Image* backing_image(py::handle object) {
  if (!py::isinstance<py::array>(object)) return nullptr;
  py::array a = py::reinterpret_borrow<py::array>(object);
  py::object base = a.base();  // a view's base is the array it views: follow to the capsule
  while (base && py::isinstance<py::array>(base))
    base = py::reinterpret_borrow<py::array>(base).base();
  if (!base || !PyCapsule_IsValid(base.ptr(), kImageCapsule)) return nullptr;
  const auto* img = static_cast<const mr::Image*>(PyCapsule_GetPointer(base.ptr(), kImageCapsule));
  if (!img || !py::isinstance<py::array_t<float>>(a) || a.data() != img->data()) return nullptr;
  const py::ssize_t f = sizeof(float);
  const bool shape_ok = a.shape(0) == img->height() && a.shape(1) == img->width() &&
                        (a.ndim() == 3 ? a.shape(2) == img->channels() : img->channels() == 1);
  if ((a.ndim() != 2 && a.ndim() != 3) || !shape_ok) return nullptr;
  if (a.strides(0) != img->row_stride() * f || a.strides(1) != img->channels() * f ||
      (a.ndim() == 3 && a.strides(2) != f))
    return nullptr;
  return img;
}

ImageArg::ImageArg(py::handle object, const std::string& what, const mr::Metadata* metadata) {
  py::array a = float_array(object, what);
  keep_alive_ = a;
  if (!metadata) {
    if ((borrowed_ = backing_image(a))) return;
  }
  const int height = int(a.shape(0)), width = int(a.shape(1));
  const int channels = a.ndim() == 3 ? int(a.shape(2)) : 1;
  owned_ = mr::Image::uninitialized(width, height, channels);
  const py::ssize_t f = sizeof(float);
  const py::ssize_t sy = a.strides(0), sx = a.strides(1), sc = a.ndim() == 3 ? a.strides(2) : f;
  const auto* base = static_cast<const char*>(a.data());
  for (int y = 0; y < height; ++y) {
    float* out = owned_.pixel(0, y);
    const char* row = base + y * sy;
    if (sc == f && sx == channels * f) {
      std::memcpy(out, row, std::size_t(width) * channels * sizeof(float));
      continue;
    }
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < channels; ++c) std::memcpy(out++, row + x * sx + c * sc, sizeof(float));
  }
  if (metadata) owned_.metadata() = *metadata;
}

mr::ImageView writable_view(py::handle object, const std::string& what) {
  py::array a = float_array(object, what);
  if (!a.writeable()) invalid(what + ": the array is read-only");
  const py::ssize_t f = sizeof(float);
  const int channels = a.ndim() == 3 ? int(a.shape(2)) : 1;
  const bool packed = (a.ndim() == 2 || a.strides(2) == f) && a.strides(1) == channels * f &&
                      a.strides(0) > 0 && a.strides(0) % f == 0;
  if (!packed)
    invalid(what +
            ": in-place operations need packed pixels (channels and pixels adjacent); "
            "use numpy.ascontiguousarray first");
  return {static_cast<float*>(a.mutable_data()), int(a.shape(1)), int(a.shape(0)), channels,
          a.strides(0) / f};
}

std::string path_arg(py::handle path, const char* what) {
  if (py::isinstance<py::str>(path)) return path.cast<std::string>();
  py::object os = py::module_::import("os");
  try {
    py::object p = os.attr("fsdecode")(os.attr("fspath")(path));
    return p.cast<std::string>();
  } catch (py::error_already_set&) {
    invalid(std::string(what) + ": expected a path (str or os.PathLike), got " +
            std::string(py::str(py::type::handle_of(path).attr("__name__"))));
  }
}

mr::PixelType pixel_type_arg(py::handle value) {
  if (py::isinstance<mr::PixelType>(value)) return value.cast<mr::PixelType>();
  const std::string text = py::str(value);
  if (text == "automatic" || text == "auto") return mr::PixelType::automatic;
  return mr::parse_pixel_type(text);
}

void bind_images(py::module_& m) {
  // --- metadata ---
  py::class_<mr::Metadata>(m, "Metadata",
                           "Named attributes that travel with an image (EXIF, colour space, ...; "
                           "OpenImageIO's names such as 'Exif:FocalLengthIn35mmFilm', 'Make'). A "
                           "mapping: md['Make'], md['Software'] = 'x', del md['x'], 'x' in md; "
                           "values read as float when numeric, else str. Copies are independent.")
      .def(py::init<>())
      .def(py::init([](py::dict d) { return metadata_from_dict(d); }), py::arg("values"),
           "From a dict of str -> str | float.")
      .def("names", &mr::Metadata::names, "Attribute names, in insertion order.")
      .def("keys", &mr::Metadata::names)
      .def("get_string", &mr::Metadata::get_string, py::arg("name"),
           "The value as text (numbers formatted), or None if absent.")
      .def("get_number", &mr::Metadata::get_number, py::arg("name"),
           "The value as a number (first element of arrays / rationals), or None.")
      .def(
          "get",
          [](const mr::Metadata& md, const std::string& name, py::object fallback) {
            return md.contains(name) ? metadata_value(md, name) : fallback;
          },
          py::arg("name"), py::arg("default") = py::none())
      .def("__getitem__",
           [](const mr::Metadata& md, const std::string& name) {
             if (!md.contains(name)) throw py::key_error(name);
             return metadata_value(md, name);
           })
      .def("__setitem__",
           [](mr::Metadata& md, const std::string& name, py::object value) {
             if (py::isinstance<py::str>(value))
               md.set(name, value.cast<std::string>());
             else
               md.set(name, value.cast<double>());
           })
      .def("__delitem__",
           [](mr::Metadata& md, const std::string& name) {
             if (!md.contains(name)) throw py::key_error(name);
             md.erase(name);
           })
      .def("__contains__", &mr::Metadata::contains)
      .def("__len__", [](const mr::Metadata& md) { return md.names().size(); })
      .def("__iter__", [](const mr::Metadata& md) { return py::iter(py::cast(md.names())); })
      .def(
          "to_dict",
          [](const mr::Metadata& md) {
            py::dict d;
            for (const std::string& n : md.names()) d[py::str(n)] = metadata_value(md, n);
            return d;
          },
          "A dict copy: name -> float | str.")
      .def("copy", [](const mr::Metadata& md) { return mr::Metadata(md); })
      .def("__repr__", [](const mr::Metadata& md) {
        return "libmr.Metadata(" + std::to_string(md.names().size()) + " attributes)";
      });

  m.def(
      "image_metadata",
      [](py::handle array) -> std::optional<mr::Metadata> {
        if (const mr::Image* img = backing_image(array)) return img->metadata();
        return std::nullopt;
      },
      py::arg("image"),
      "A copy of the metadata an array returned by libmr carries (the file's, for read_image; "
      "the photo's, for fog().composite); None for any other array.");
  m.def(
      "is_libmr_image", [](py::handle array) { return backing_image(array) != nullptr; },
      py::arg("image"),
      "True when `image` is an array libmr returned, shown exactly: passing it back to libmr "
      "uses its pixels in place (no copy).");
  m.def(
      "new_image",
      [](int height, int width, int channels) {
        return to_array(mr::Image(width, height, channels));
      },
      py::arg("height"), py::arg("width"), py::arg("channels") = 3,
      "A zero-filled float32 array (H, W, C) owned by libmr: fill it in place (img[...] = ...) "
      "and libmr functions use it without copying.");

  // --- colour ---
  py::class_<mr::ColorConfig>(m, "ColorConfig",
                              "An OpenColorIO config (immutable, thread-safe, cheap to copy).")
      .def_static("builtin", &mr::ColorConfig::builtin,
                  "libmr's shipped config: sRGB texture, linear Rec.709 (scene_linear), ACEScg, "
                  "raw, srgb_rolloff.")
      .def_static(
          "from_file",
          [](py::handle path) { return mr::ColorConfig::from_file(path_arg(path, "path")); },
          py::arg("path"), "A config file; ColorError if OCIO cannot load it.")
      .def_static(
          "from_environment",
          [](py::object path) {
            return mr::ColorConfig::from_environment(path.is_none() ? std::string()
                                                                    : path_arg(path, "path"));
          },
          py::arg("path") = py::none(), "`path` if given, else $OCIO, else builtin().")
      .def_property_readonly("source", &mr::ColorConfig::source,
                             "Where the config came from: a file path or '<builtin>'.")
      .def("colorspace_names", &mr::ColorConfig::colorspace_names)
      .def("has_colorspace", &mr::ColorConfig::has_colorspace, py::arg("name"))
      .def("is_data", &mr::ColorConfig::is_data, py::arg("name"))
      .def("display_colorspace",
           [](const mr::ColorConfig& c) { return std::string(c.display_colorspace()); })
      .def(
          "convert",
          [](const mr::ColorConfig& c, py::handle image, const std::string& from,
             const std::string& to) {
            mr::ImageView view = writable_view(image, "image");
            py::gil_scoped_release release;
            c.convert(view, from, to);
          },
          py::arg("image"), py::arg("from_space"), py::arg("to_space"),
          "Converts the first three channels of a float32 array (H, W, C >= 3) IN PLACE (no "
          "copy; any row stride, packed pixels) between colour spaces (names, aliases, roles: "
          "'scene_linear', 'srgb_texture', 'ACEScg', ...). Releases the GIL.");
  m.def("highlight_rolloff", &mr::highlight_rolloff, py::arg("x"),
        py::arg("knee") = mr::kHighlightRolloffKnee,
        "The srgb_rolloff shoulder on a scene-linear value: identity up to `knee`, then "
        "knee + (1 - knee) u / (1 + u), u = (x - knee) / (1 - knee).");

  // --- image files ---
  py::enum_<mr::PixelType>(m, "PixelType", "How pixels are stored in a file.")
      .value("automatic", mr::PixelType::automatic)
      .value("uint8", mr::PixelType::uint8)
      .value("uint16", mr::PixelType::uint16)
      .value("half", mr::PixelType::half)
      .value("float32", mr::PixelType::float32);

  py::class_<mr::ImageFileInfo>(m, "ImageFileInfo", "What a file holds (from its header).")
      .def_readonly("width", &mr::ImageFileInfo::width)
      .def_readonly("height", &mr::ImageFileInfo::height)
      .def_readonly("channels", &mr::ImageFileInfo::channels)
      .def_readonly("pixel_type", &mr::ImageFileInfo::pixel_type)
      .def_readonly("format", &mr::ImageFileInfo::format, "OIIO format name: 'jpeg', 'openexr'")
      .def_readonly("orientation", &mr::ImageFileInfo::orientation, "EXIF Orientation 1..8")
      .def_readonly("software", &mr::ImageFileInfo::software)
      .def("__repr__", [](const mr::ImageFileInfo& i) {
        return "libmr.ImageFileInfo(" + std::to_string(i.width) + "x" + std::to_string(i.height) +
               "x" + std::to_string(i.channels) + ", " + mr::to_string(i.pixel_type) + ", " +
               i.format + ")";
      });
  m.def(
      "probe_image", [](py::handle path) { return mr::probe_image(path_arg(path, "path")); },
      py::arg("path"), "Reads an image file's header (no pixels). FileError if unreadable.");

  m.def(
      "read_image",
      [](py::handle path, const std::string& colorspace, bool to_scene_linear,
         bool reject_non_finite, bool apply_orientation, py::object color,
         bool with_metadata) -> py::object {
        const std::string file = path_arg(path, "path");
        const mr::ColorConfig config = color_arg(color);
        mr::ReadOptions o;
        o.colorspace = colorspace;
        o.to_scene_linear = to_scene_linear;
        o.reject_non_finite = reject_non_finite;
        o.apply_orientation = apply_orientation;
        o.color = &config;
        mr::Image image;
        {
          py::gil_scoped_release release;
          image = mr::read_image(file, o);
        }
        mr::Metadata md = image.metadata();
        py::object pixels = to_array(std::move(image));
        if (with_metadata) return py::make_tuple(pixels, md);
        return pixels;
      },
      py::arg("path"), py::kw_only(), py::arg("colorspace") = "", py::arg("to_scene_linear") = true,
      py::arg("reject_non_finite") = true, py::arg("apply_orientation") = true,
      py::arg("color") = py::none(), py::arg("with_metadata") = false,
      "Reads an image file through OpenImageIO as float32 (H, W, C), converted to scene-linear "
      "through OpenColorIO (8/16-bit files as sRGB, float files as linear, unless `colorspace` "
      "names the file's space), turned upright by its EXIF Orientation. No copy: the array "
      "owns libmr's image and carries the file's metadata (image_metadata()). "
      "with_metadata=True returns (pixels, Metadata). Raises FileError, CorruptInputError "
      "(truncated, NaN pixels), ColorError. Releases the GIL while decoding.");

  m.def(
      "write_image",
      [](py::handle path, py::handle image, py::handle pixel_type, const std::string& colorspace,
         int jpeg_quality, bool overwrite, std::optional<mr::Metadata> metadata, py::object color) {
        const std::string file = path_arg(path, "path");
        const ImageArg img(image, "image", metadata ? &*metadata : nullptr);
        const mr::ColorConfig config = color_arg(color);
        mr::WriteOptions o;
        o.pixel_type = pixel_type_arg(pixel_type);
        o.colorspace = colorspace;
        o.color = &config;
        o.jpeg_quality = jpeg_quality;
        o.overwrite = overwrite;
        py::gil_scoped_release release;
        mr::write_image(file, img.image(), o);
      },
      py::arg("path"), py::arg("image"), py::kw_only(), py::arg("pixel_type") = "automatic",
      py::arg("colorspace") = "", py::arg("jpeg_quality") = 95, py::arg("overwrite") = true,
      py::arg("metadata") = py::none(), py::arg("color") = py::none(),
      "Writes a scene-linear float32 image (H, W, C), 1..4 channels, format from the "
      "extension. Atomic (temporary file + rename; on failure `path` is untouched). "
      "pixel_type: 'automatic' (float for EXR/HDR/PFM, 16-bit TIFF, else 8-bit), '8', '16', "
      "'half', 'float'. colorspace: empty = sRGB for integer types, scene-linear for float. "
      "Metadata: `metadata` if given (this copies the pixels), else what a libmr array carries. "
      "Raises FileError, InvalidArgumentError. Releases the GIL while encoding.");

  m.def(
      "write_exr_layers",
      [](py::handle path, py::list layers, std::optional<mr::Metadata> metadata,
         py::handle pixel_type) {
        const std::string file = path_arg(path, "path");
        std::vector<std::unique_ptr<ImageArg>> images;
        std::vector<mr::Image> renamed;
        renamed.reserve(layers.size());
        std::vector<mr::ExrLayer> exr;
        for (py::handle item : layers) {
          py::tuple t = py::tuple(py::reinterpret_borrow<py::object>(item));
          if (t.size() < 2 || t.size() > 4)
            invalid("write_exr_layers: each layer is (name, image[, is_data[, channels]])");
          const std::string name = t[0].cast<std::string>();
          images.push_back(std::make_unique<ImageArg>(t[1], "layer '" + name + "'"));
          const mr::Image* img = &images.back()->image();
          if (t.size() == 4) {
            renamed.push_back(*img);  // a copy with the given channel names
            renamed.back().set_channel_names(t[3].cast<std::vector<std::string>>());
            img = &renamed.back();
          }
          exr.push_back({name, img, t.size() >= 3 && t[2].cast<bool>()});
        }
        const mr::Metadata md = metadata ? *metadata : mr::Metadata();
        const mr::PixelType type = pixel_type_arg(pixel_type);
        py::gil_scoped_release release;
        mr::write_exr_layers(file, exr, md, type);
      },
      py::arg("path"), py::arg("layers"), py::kw_only(), py::arg("metadata") = py::none(),
      py::arg("pixel_type") = "half",
      "Writes one multi-layer OpenEXR file (oiiotool, Nuke and Blender read the layers). "
      "layers: a list of (name, image[, is_data[, channel_names]]); name '' is the main "
      "R,G,B layer; channels are named '<layer>.<channel>' from the image's channel names "
      "(R,G,B[,A], 'Y' for one channel; libmr's depth maps 'Z'). Data layers are never "
      "colour-converted. Atomic. pixel_type 'half' or 'float'.");

  m.def(
      "check_output_path", [](py::handle path) { mr::check_output_path(path_arg(path, "path")); },
      py::arg("path"),
      "FileError when `path` exists and is not a regular file (a link, FIFO, device, folder).");
  m.def(
      "write_text_file",
      [](py::handle path, const std::string& text, bool overwrite) {
        mr::write_text_file(path_arg(path, "path"), text, overwrite);
      },
      py::arg("path"), py::arg("text"), py::arg("overwrite") = true,
      "Writes text atomically, as libmr writes its images (temporary + rename).");
  m.def(
      "is_readable_image_extension",
      [](py::handle p) { return mr::is_readable_image_extension(path_arg(p, "path")); },
      py::arg("path"));
  m.def(
      "is_writable_image_extension",
      [](py::handle p) { return mr::is_writable_image_extension(path_arg(p, "path")); },
      py::arg("path"));
  m.def("max_decoded_pixels", &mr::max_decoded_pixels,
        "The largest image read_image decodes, in pixels (default 250 megapixels).");
  m.def("set_max_decoded_pixels", &mr::set_max_decoded_pixels, py::arg("pixels"),
        "Process-wide decode limit in pixels; 0 restores the default.");

  // --- cancellation and progress ---
  py::class_<mr::CancelToken>(
      m, "CancelToken",
      "Cooperative cancellation of a long libmr call from another thread, and its progress. "
      "Pass it as `cancel=` to fog / estimate / transfer_material; request() from any thread "
      "makes the call raise CancelledError within about one image row (CPU) of the request, "
      "returning nothing. A token stays requested until reset().")
      .def(py::init<>())
      .def("request", &mr::CancelToken::request, "Asks every call using this token to stop.")
      .def("requested", &mr::CancelToken::requested)
      .def("reset", &mr::CancelToken::reset, "Only when no call is using the token.")
      .def(
          "set_progress",
          [](mr::CancelToken& token, py::object callback, double min_interval_s) {
            if (callback.is_none()) {
              token.set_progress({});
              return;
            }
            // Destroyed wherever the last copy goes, possibly on a TBB thread: take the GIL.
            std::shared_ptr<py::object> fn(new py::object(std::move(callback)), [](py::object* o) {
              py::gil_scoped_acquire gil;
              delete o;
            });
            token.set_progress(
                [fn](const mr::Progress& p) {
                  py::gil_scoped_acquire gil;
                  try {
                    (*fn)(std::string(p.stage), p.done, p.total);
                  } catch (py::error_already_set& e) {
                    // The token swallows exceptions and cancels the call; show the traceback.
                    e.discard_as_unraisable("libmr progress callback");
                    throw std::runtime_error("progress callback raised");
                  }
                },
                std::chrono::milliseconds(std::llround(min_interval_s * 1000.0)));
          },
          py::arg("callback"), py::arg("min_interval_s") = 0.1,
          "callback(stage: str, done: int, total: int), e.g. ('render', 120, 480): image rows "
          "of a render, estimation steps, fitted segments. Called from libmr's worker threads "
          "(with the GIL taken), never two at once, throttled to one call per min_interval_s "
          "except each stage's start and end; `done` only grows within a stage. An exception "
          "in it is printed and cancels the call. None removes it. Only while no call uses the "
          "token.");
}

}  // namespace mrpy
