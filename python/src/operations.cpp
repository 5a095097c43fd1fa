// The long calls: fog, depth, estimation, material transfer. Each converts its arguments with
// the GIL held (numpy arrays, a copy of the scene), then releases the GIL for the C++ work, so
// Python threads and Dask workers render in parallel.
#include <cctype>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>

#include "common.h"
#include "mr/annotations.h"
#include "mr/camera.h"
#include "mr/cancel.h"
#include "mr/depth.h"
#include "mr/estimate.h"
#include "mr/fog.h"
#include "mr/fog_stream.h"
#include "mr/io.h"
#include "mr/material.h"
#include "mr/scattering.h"
#include "mr/scene_json.h"
#include "mr/working_size.h"

namespace mrpy {
namespace {

struct FogResult {
  py::object composite, transmittance, inscatter, sun_visibility, optical_depth;
  mr::Rgb sky_radiance{};
  mr::Camera camera;
  std::string backend, backend_notice;
  bool backend_notice_is_warning = false;
  py::dict timings;
  std::vector<std::string> warnings;
  double call_s = 0;  // inside the C++ call (the binding's own overhead is the rest)
};

struct FileFogResult {
  bool streamed = false;
  std::string reason;  // why it did not stream (empty when it did)
  mr::Camera camera;
  int width = 0, height = 0;
  std::size_t no_surface_pixels = 0, invalid_pixels = 0, sky_threshold_pixels = 0,
              clamped_pixels = 0;
};

struct DepthResult {
  py::object distance_m;
  std::size_t no_surface_pixels = 0, invalid_pixels = 0, sky_threshold_pixels = 0,
              clamped_pixels = 0;
};

struct EstimateResult {
  mr::FogScene scene;
  mr::Camera camera;
  std::string camera_source;
  py::object distance_m, sky_alpha, depth_confidence;
  std::array<mr::PixelPoint, 2> horizon{};
  std::string horizon_source, height_source;
  double confidence = 0;
  bool sky_from_mask = false;
  std::optional<mr::SunEstimate> sun;
  std::vector<std::string> notes;
  py::dict pixels;
};

struct MaterialResult {
  py::object image, segment_labels;
  std::vector<mr::MaterialCandidate> candidates;
  std::vector<int> assignment;
  std::vector<double> exposures;
  double objective = 0;
  std::vector<double> best_objective_history;
  std::vector<std::string> notes, warnings;
  std::string json;
};

mr::Camera default_camera(int width, int height, const mr::FogScene* scene,
                          const mr::Metadata& metadata) {
  if (scene && scene->camera) return mr::camera_for_image(*scene->camera, width, height);
  return mr::Camera::from_metadata(width, height, metadata);
}

mr::DepthKind depth_kind_arg(py::handle value) {
  if (py::isinstance<mr::DepthKind>(value)) return value.cast<mr::DepthKind>();
  const std::string k = py::str(value);
  if (k == "distance") return mr::DepthKind::distance;
  if (k == "z" || k == "planar_z") return mr::DepthKind::planar_z;
  if (k == "disparity") return mr::DepthKind::disparity;
  invalid("kind: expected 'distance', 'z' or 'disparity', got '" + k + "'");
}

mr::Annotations annotations_arg(py::handle value) {
  if (value.is_none()) return {};
  if (py::isinstance<py::dict>(value)) {
    const std::string text = py::module_::import("json").attr("dumps")(value).cast<std::string>();
    return mr::annotations_from_json(text, "<annotations>");
  }
  if (py::isinstance<py::str>(value)) {
    const std::string text = value.cast<std::string>();
    const auto first = text.find_first_not_of(" \t\r\n");
    if (first != std::string::npos && text[first] == '{')
      return mr::annotations_from_json(text, "<annotations>");
  }
  return mr::load_annotations(path_arg(value, "annotations"));
}

py::dict timings_dict(const mr::ScatteringLayers::Timings& t) {
  py::dict d;
  d["mesh_s"] = t.mesh_s;
  d["bvh_s"] = t.bvh_s;
  d["scatter_s"] = t.scatter_s;
  d["total_s"] = t.total_s;
  d["exact_pixels"] = t.exact_pixels;
  d["interpolated_pixels"] = t.interpolated_pixels;
  d["shadow_rays"] = t.shadow_rays;
  d["upload_s"] = t.upload_s;
  d["shadow_maps_s"] = t.shadow_maps_s;
  d["gpu_scatter_s"] = t.gpu_scatter_s;
  d["download_s"] = t.download_s;
  d["tiles"] = t.tiles;
  return d;
}

mr::Rgb rgb_arg(py::handle value, const char* what) {
  if (py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value)) {
    const float v = value.cast<float>();
    return {v, v, v};
  }
  try {
    return value.cast<mr::Rgb>();
  } catch (const py::cast_error&) {
    invalid(std::string(what) + ": expected a number or 3 numbers (R, G, B)");
  }
}

// The write options `mr fog` uses (cli/fog_command.cpp, output_write_options): with an automatic
// pixel type, EXR keeps float inputs float (else half) and PNG/TIFF keep 16-bit inputs 16-bit;
// display-referred (integer) outputs are encoded through the config's highlight roll-off.
mr::WriteOptions mr_fog_write_options(const std::string& output, const mr::ImageFileInfo& input,
                                      mr::PixelType type, const std::string& colorspace,
                                      const mr::ColorConfig& config, int jpeg_quality,
                                      bool overwrite) {
  mr::WriteOptions w;
  w.color = &config;
  w.colorspace = colorspace;
  w.pixel_type = type;
  w.jpeg_quality = jpeg_quality;
  w.overwrite = overwrite;
  std::string ext = std::filesystem::path(output).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (w.pixel_type == mr::PixelType::automatic) {
    if (ext == ".exr")
      w.pixel_type =
          input.pixel_type == mr::PixelType::float32 ? mr::PixelType::float32 : mr::PixelType::half;
    else if (input.pixel_type == mr::PixelType::uint16 &&
             (ext == ".png" || ext == ".tif" || ext == ".tiff"))
      w.pixel_type = mr::PixelType::uint16;
  }
  const bool float_out =
      w.pixel_type == mr::PixelType::half || w.pixel_type == mr::PixelType::float32 ||
      (w.pixel_type == mr::PixelType::automatic && (ext == ".exr" || ext == ".hdr"));
  if (w.colorspace.empty() && !float_out) w.colorspace = config.display_colorspace();
  return w;
}

// One photo file -> one fogged file, as `mr fog` does it: scenes lit by the sky alone stream
// through decode -> fog -> encode in strips (mr::FogStreamer, one per thread, buffers reused);
// the rest, and what the streamer declines, take the full-frame path. Runs without the GIL.
FileFogResult fog_file(const std::string& photo_path, const std::string& depth_path,
                       const std::string& output, const mr::FogScene& scene,
                       const std::optional<mr::Camera>& given_camera,
                       const mr::DepthOptions& depth_options, mr::PixelType pixel_type,
                       const std::string& colorspace, const std::string& input_colorspace,
                       const std::string& software, int jpeg_quality, bool overwrite,
                       const mr::ColorConfig& config, const mr::CancelToken* cancel) {
  if (!overwrite && std::filesystem::exists(output))
    throw mr::Error(mr::ErrorCode::io, output + ": exists (overwrite=False)");
  const mr::ImageFileInfo info = mr::probe_image(photo_path);
  const mr::WriteOptions write =
      mr_fog_write_options(output, info, pixel_type, colorspace, config, jpeg_quality, overwrite);
  mr::ReadOptions read;
  read.colorspace = input_colorspace;
  read.color = &config;
  auto camera_for = [&](int width, int height, const mr::Metadata& metadata) {
    return given_camera ? *given_camera : default_camera(width, height, &scene, metadata);
  };
  FileFogResult result;
  mr::Image photo;
  if (mr::is_sky_only(scene) && scene.render.backend != mr::Backend::vulkan) {
    mr::FogScene render_scene = scene;
    mr::StreamFogRequest request;
    bool stream = true;
    if (!scene.lighting.sky_radiance) {  // 'auto': the dark channel prior needs the whole photo
      photo = mr::read_image(photo_path, read);
      stream = photo.channels() >= 3;
      if (stream) render_scene.lighting.sky_radiance = mr::estimate_airlight(photo);
      request.photo_image = &photo;
    }
    if (stream) {
      request.photo = photo_path;
      request.depth = depth_path;
      request.output = output;
      request.depth_options = depth_options;
      request.scene = &render_scene;
      request.camera = camera_for;
      request.color = &config;
      request.input_colorspace = input_colorspace;
      request.software = software;
      request.write = write;
      thread_local mr::FogStreamer streamer;
      const mr::StreamFogResult r = streamer.fog_file(request, cancel);
      result.reason = r.reason;
      if (r.streamed) {
        result.streamed = true;
        result.camera = r.camera;
        result.width = r.width;
        result.height = r.height;
        result.no_surface_pixels = r.no_surface_pixels;
        result.invalid_pixels = r.invalid_pixels;
        result.sky_threshold_pixels = r.sky_threshold_pixels;
        result.clamped_pixels = r.clamped_pixels;
        return result;
      }
    }
  } else {
    result.reason =
        "the scene has a sun, lamps or noise (the scattering core needs the whole frame)";
  }
  if (photo.empty()) photo = mr::read_image(photo_path, read);
  if (!software.empty()) photo.metadata().set("Software", software);
  const mr::Camera camera = camera_for(photo.width(), photo.height(), photo.metadata());
  const mr::DepthMap depth = mr::read_depth(depth_path, camera, depth_options);
  const mr::FogLayers layers = mr::fog(photo, depth.distance_m, camera, scene, nullptr, cancel);
  mr::write_image(output, layers.composite, write);
  result.camera = camera;
  result.width = photo.width();
  result.height = photo.height();
  result.no_surface_pixels = depth.no_surface_pixels;
  result.invalid_pixels = depth.invalid_pixels;
  result.sky_threshold_pixels = depth.sky_threshold_pixels;
  result.clamped_pixels = depth.clamped_pixels;
  return result;
}

}  // namespace

void bind_operations(py::module_& m) {
  // --- Koschmieder ---
  m.def("extinction_from_visibility", &mr::extinction_from_visibility, py::arg("visibility_m"),
        "Extinction coefficient (1/m) for a meteorological visibility (m): 3.912 / V.");
  m.def("visibility_from_extinction", &mr::visibility_from_extinction, py::arg("sigma_t_per_m"),
        "Meteorological visibility (m) of an extinction coefficient (1/m): 3.912 / sigma_t.");
  m.def(
      "estimate_airlight",
      [](py::handle image) {
        const ImageArg photo(image, "image");
        py::gil_scoped_release release;
        return mr::estimate_airlight(photo.image());
      },
      py::arg("image"),
      "Airlight (scene-linear RGB) from a scene-linear photo by the dark channel prior, "
      "bounded to daylight colours.");

  // --- depth ---
  py::enum_<mr::DepthKind>(m, "DepthKind", "What the values of a depth map mean.")
      .value("distance", mr::DepthKind::distance, "metres along the pixel's ray")
      .value("planar_z", mr::DepthKind::planar_z, "metres along the optical axis (z-depth)")
      .value("disparity", mr::DepthKind::disparity,
             "pixels: z = focal_px * baseline / (d + doffs)");
  py::class_<DepthResult>(m, "DepthMap",
                          "A metric distance map: distance_m float32 (H, W, 1), metres along "
                          "each ray, +inf = sky; and counts of what was read.")
      .def_readonly("distance_m", &DepthResult::distance_m)
      .def_readonly("no_surface_pixels", &DepthResult::no_surface_pixels,
                    "pixels stored as NaN, inf, 0 or < 0 (sky)")
      .def_readonly("invalid_pixels", &DepthResult::invalid_pixels,
                    "of those, NaN or negative (a broken or mis-scaled map)")
      .def_readonly("sky_threshold_pixels", &DepthResult::sky_threshold_pixels,
                    "finite values >= sky_depth_m, read as sky")
      .def_readonly("clamped_pixels", &DepthResult::clamped_pixels,
                    "surfaces beyond 10,000 km, clamped");
  auto depth_call = [](mr::Image stored_or_empty, const std::string& file,
                       const std::optional<mr::Camera>& camera, py::handle kind, double scale,
                       double baseline_m, double doffs_px, double sky_depth_m) {
    mr::DepthOptions o;
    o.kind = depth_kind_arg(kind);
    o.scale = scale;
    o.baseline_m = baseline_m;
    o.doffs_px = doffs_px;
    o.sky_depth_m = sky_depth_m;
    mr::DepthMap map;
    {
      py::gil_scoped_release release;
      mr::Camera cam;
      if (camera) {
        cam = *camera;
      } else {
        if (o.kind != mr::DepthKind::distance)
          invalid("camera: needed to convert planar z-depth or disparity");
        int w = stored_or_empty.width(), h = stored_or_empty.height();
        if (!file.empty()) {
          const mr::ImageFileInfo info = mr::probe_image(file);
          w = info.orientation >= 5 ? info.height : info.width;
          h = info.orientation >= 5 ? info.width : info.height;
        }
        cam = mr::Camera::from_horizontal_fov(w, h, 60.0);  // only its size is used
      }
      map = file.empty() ? mr::depth_to_distance(std::move(stored_or_empty), cam, o)
                         : mr::read_depth(file, cam, o);
    }
    DepthResult r;
    r.no_surface_pixels = map.no_surface_pixels;
    r.invalid_pixels = map.invalid_pixels;
    r.sky_threshold_pixels = map.sky_threshold_pixels;
    r.clamped_pixels = map.clamped_pixels;
    r.distance_m = to_array(std::move(map.distance_m));
    return r;
  };
  m.def(
      "read_depth",
      [depth_call](py::handle path, std::optional<mr::Camera> camera, py::handle kind, double scale,
                   double baseline_m, double doffs_px, double sky_depth_m) {
        return depth_call({}, path_arg(path, "path"), camera, kind, scale, baseline_m, doffs_px,
                          sky_depth_m);
      },
      py::arg("path"), py::arg("camera") = py::none(), py::kw_only(), py::arg("kind") = "distance",
      py::arg("scale") = 1.0, py::arg("baseline_m") = 0.0, py::arg("doffs_px") = 0.0,
      py::arg("sky_depth_m") = mr::kDefaultSkyDepthM,
      "Reads a depth file (float EXR/TIFF/PFM; 8/16-bit files as raw codes times `scale`) as a "
      "DepthMap of metres along each ray. kind: 'distance' (along the ray), 'z' (planar; "
      "needs the camera) or 'disparity' (pixels; needs the camera and baseline_m, metres). "
      "Stored values * scale >= sky_depth_m (default 65504 m; Blender's 1e10 background) are "
      "sky (+inf). The camera's size must match (SizeMismatchError).");
  m.def(
      "depth_to_distance",
      [depth_call](py::handle stored, std::optional<mr::Camera> camera, py::handle kind,
                   double scale, double baseline_m, double doffs_px, double sky_depth_m) {
        mr::Image values = ImageArg(stored, "stored").take();  // converted in place
        if (values.channels() != 1) invalid("stored: expected one channel (H, W) or (H, W, 1)");
        for (float& v : values.pixels()) v = float(double(v) * scale);
        return depth_call(std::move(values), {}, camera, kind, 1.0, baseline_m, doffs_px,
                          sky_depth_m);
      },
      py::arg("stored"), py::arg("camera") = py::none(), py::kw_only(),
      py::arg("kind") = "distance", py::arg("scale") = 1.0, py::arg("baseline_m") = 0.0,
      py::arg("doffs_px") = 0.0, py::arg("sky_depth_m") = mr::kDefaultSkyDepthM,
      "As read_depth, for values already in memory, e.g. a renderer's Z pass: "
      "depth_to_distance(z, camera, kind='z') (Blender's Z is planar z-depth). The input is "
      "copied once (the conversion needs its own buffer).");

  // --- fog ---
  py::class_<FogResult>(m, "FogLayers",
                        "The layers of a fogged photo, float32 (H, W, C), scene-linear, no "
                        "copies (each array owns libmr's image).")
      .def_readonly("composite", &FogResult::composite,
                    "C = I * T + R (R, G, B[, alpha carried]); carries the photo's metadata")
      .def_readonly("transmittance", &FogResult::transmittance,
                    "T (R, G, B) in [0, 1]: tau(camera, surface) * S(surface)")
      .def_readonly("inscatter", &FogResult::inscatter,
                    "R (R, G, B): light scattered into the view ray, scene-linear radiance")
      .def_readonly("sun_visibility", &FogResult::sun_visibility,
                    "(H, W, 1): fraction of the sun's disk seen from the surface; None for "
                    "fog_homogeneous")
      .def_readonly("optical_depth", &FogResult::optical_depth,
                    "(H, W, 3): optical depth camera -> surface (inf for sky in unbounded fog); "
                    "None for fog_homogeneous")
      .def_readonly("sky_radiance", &FogResult::sky_radiance,
                    "the sky radiance / airlight used (given or estimated), scene-linear RGB")
      .def_readonly("camera", &FogResult::camera, "the camera rendered with")
      .def_readonly("backend", &FogResult::backend, "'cpu' or 'vulkan: <device>'")
      .def_readonly("backend_notice", &FogResult::backend_notice)
      .def_readonly("backend_notice_is_warning", &FogResult::backend_notice_is_warning)
      .def_readonly("timings", &FogResult::timings,
                    "seconds (mesh_s, bvh_s, scatter_s, total_s, ...) and pixel / ray counts")
      .def_readonly("warnings", &FogResult::warnings, "scene_warnings(scene)")
      .def_readonly("call_s", &FogResult::call_s,
                    "seconds spent in the C++ call (mr::fog); the rest of the Python call's "
                    "time is the binding's overhead (argument conversion, copies, arrays)")
      .def("__repr__",
           [](const FogResult& r) { return "libmr.FogLayers(backend='" + r.backend + "')"; });

  m.def(
      "default_camera",
      [](int width, int height, const mr::FogScene* scene, std::optional<mr::Metadata> md) {
        return default_camera(width, height, scene, md ? *md : mr::Metadata());
      },
      py::arg("width"), py::arg("height"), py::arg("scene") = py::none(),
      py::arg("metadata") = py::none(),
      "The camera `mr fog` uses without --fov / --focal-px: the scene's recorded camera "
      "(scaled to the size), else EXIF FocalLengthIn35mmFormat from `metadata`, else 60 "
      "degrees across.");

  m.def(
      "fog",
      [](py::handle image, py::handle depth, const mr::FogScene* scene,
         std::optional<mr::Camera> camera, py::handle sky_alpha,
         std::optional<mr::Metadata> metadata, mr::CancelToken* cancel, bool soften_seams) {
        const ImageArg photo(image, "image", metadata ? &*metadata : nullptr);
        const ImageArg distance(depth, "depth");
        const ImageArg alpha = sky_alpha.is_none() ? ImageArg() : ImageArg(sky_alpha, "sky_alpha");
        const mr::FogScene s = scene ? *scene : mr::FogScene();  // Python may edit it meanwhile
        const mr::Camera cam = camera
                                   ? *camera
                                   : default_camera(photo.image().width(), photo.image().height(),
                                                    &s, photo.image().metadata());
        FogResult r;
        mr::ScatteringLayers aovs;
        mr::FogLayers layers;
        {
          py::gil_scoped_release release;
          const auto start = std::chrono::steady_clock::now();
          layers = mr::fog(photo.image(), distance.image(), alpha.image(), cam, s, &aovs, cancel);
          if (soften_seams) mr::soften_fog_seams(photo.image(), layers);
          r.call_s =
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
          r.warnings = mr::scene_warnings(s);
        }
        r.composite = to_array(std::move(layers.composite));
        r.transmittance = to_array(std::move(layers.transmittance));
        r.inscatter = to_array(std::move(layers.inscatter));
        r.sun_visibility = to_array(std::move(aovs.sun_visibility));
        r.optical_depth = to_array(std::move(aovs.optical_depth));
        r.sky_radiance = layers.airlight;
        r.camera = cam;
        r.backend = aovs.backend;
        r.backend_notice = aovs.backend_notice;
        r.backend_notice_is_warning = aovs.backend_notice_is_warning;
        r.timings = timings_dict(aovs.timings);
        return r;
      },
      py::arg("image"), py::arg("depth"), py::arg("scene") = py::none(), py::kw_only(),
      py::arg("camera") = py::none(), py::arg("sky_alpha") = py::none(),
      py::arg("metadata") = py::none(), py::arg("cancel") = py::none(),
      py::arg("soften_seams") = false,
      "Physically based fog (single scattering of sun, sky and lamps with volumetric "
      "shadows; DESIGN.md section 3) in a photo with its depth. image: scene-linear float32 "
      "(H, W, C >= 3); depth: float32 (H, W) or (H, W, 1), metres along each pixel's ray, "
      "+inf = sky (read_depth / depth_to_distance convert other kinds); scene: a Scene "
      "(None: the defaults, 150 m visibility, sky light estimated from the photo). camera: "
      "None = default_camera(W, H, scene, metadata) as `mr fog`. sky_alpha: optional soft "
      "sky matte (H, W, 1) in [0, 1] (estimate().sky_alpha). metadata: replaces the photo's "
      "(arrays from read_image carry their file's; a given one copies the photo). cancel: a "
      "CancelToken. soften_seams: for a guessed depth (estimate()), soften the fog where the "
      "depth makes edges the photo lacks, as `mr fog --depth auto` does without sun or lamps "
      "(mr::soften_fog_seams; never for a measured depth). Returns FogLayers. Arrays libmr returned are used in place; other arrays "
      "are copied once. Raises InvalidArgumentError (bad scene field, NaN depth, wrong "
      "dtype/shape), SizeMismatchError, CancelledError. Releases the GIL while rendering.");

  // Camera-size photos at a working size (mr/working_size.h): what `mr fog --depth auto` does.
  m.def(
      "working_size",
      [](int width, int height, int long_side_px) -> py::object {
        const std::optional<mr::WorkingSize> s = mr::working_size(width, height, long_side_px);
        if (!s) return py::none();
        return py::make_tuple(s->width, s->height);
      },
      py::arg("width"), py::arg("height"), py::arg("long_side_px") = mr::kDefaultWorkingLongSidePx,
      "The (width, height) a photo is estimated and fogged at when its longer side may be at "
      "most long_side_px (default 1280, the size the estimate was tuned at), or None when it is "
      "not larger (or long_side_px <= 0).");
  m.def(
      "working_copy",
      [](py::handle image, int width, int height) {
        const ImageArg photo(image, "image");
        mr::Image out;
        {
          py::gil_scoped_release release;
          out = mr::working_copy(photo.image(), width, height);
        }
        return to_array(std::move(out));
      },
      py::arg("image"), py::arg("width"), py::arg("height"),
      "The photo (scene-linear float32) reduced to width x height as the estimate's tuning "
      "photos were: sRGB-encoded values averaged over each pixel's area, decoded again.");
  m.def("scale_camera", &mr::scale_camera, py::arg("camera"), py::arg("width"), py::arg("height"),
        "The camera of the same photo stored at width x height (focal length and principal "
        "point scaled).");
  m.def(
      "upsample_fog",
      [](py::handle image, py::handle working_image, const FogResult& working) {
        const ImageArg photo(image, "image"), work(working_image, "working_image");
        mr::FogLayers layers;
        layers.transmittance = ImageArg(working.transmittance, "working.transmittance").take();
        layers.inscatter = ImageArg(working.inscatter, "working.inscatter").take();
        layers.airlight = working.sky_radiance;
        const int w = photo.image().width(), h = photo.image().height();
        mr::Image sun, od;
        if (!working.sun_visibility.is_none())
          sun = ImageArg(working.sun_visibility, "working.sun_visibility").take();
        if (!working.optical_depth.is_none())
          od = ImageArg(working.optical_depth, "working.optical_depth").take();
        FogResult r;
        mr::FogLayers up;
        {
          py::gil_scoped_release release;
          const auto start = std::chrono::steady_clock::now();
          up = mr::upsample_fog_layers(photo.image(), work.image(), layers);
          if (!sun.empty()) sun = mr::resize_nearest(sun, w, h);
          if (!od.empty()) od = mr::resize_nearest(od, w, h);
          r.call_s =
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        }
        r.composite = to_array(std::move(up.composite));
        r.transmittance = to_array(std::move(up.transmittance));
        r.inscatter = to_array(std::move(up.inscatter));
        r.sun_visibility = sun.empty() ? py::none() : to_array(std::move(sun));
        r.optical_depth = od.empty() ? py::none() : to_array(std::move(od));
        r.sky_radiance = up.airlight;
        r.camera = mr::scale_camera(working.camera, w, h);
        r.backend = working.backend;
        r.timings = working.timings;
        r.warnings = working.warnings;
        return r;
      },
      py::arg("image"), py::arg("working_image"), py::arg("working"),
      "A fog made on working_copy(image, ...) (working: its FogLayers, seams already softened) "
      "brought to the image's size by guided upsampling (mr::upsample_fog_layers): T and R "
      "follow the full-size photo's outlines; sun_visibility and optical_depth are their working "
      "pixels' (nearest), the camera scaled. Raises SizeMismatchError, InvalidArgumentError. "
      "Releases the GIL.");

  m.def(
      "fog_homogeneous",
      [](py::handle image, py::handle depth, py::handle sigma_t_per_m, py::handle airlight) {
        const ImageArg photo(image, "image");
        const ImageArg distance(depth, "depth");
        mr::FogParams p;
        p.sigma_t_per_m = rgb_arg(sigma_t_per_m, "sigma_t_per_m");
        if (!airlight.is_none()) p.airlight = rgb_arg(airlight, "airlight");
        mr::FogLayers layers;
        FogResult r;
        {
          py::gil_scoped_release release;
          const auto start = std::chrono::steady_clock::now();
          layers = mr::fog(photo.image(), distance.image(), p);
          r.call_s =
              std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        }
        r.composite = to_array(std::move(layers.composite));
        r.transmittance = to_array(std::move(layers.transmittance));
        r.inscatter = to_array(std::move(layers.inscatter));
        r.sun_visibility = py::none();
        r.optical_depth = py::none();
        r.sky_radiance = layers.airlight;
        r.backend = "closed form";
        return r;
      },
      py::arg("image"), py::arg("depth"), py::arg("sigma_t_per_m"),
      py::arg("airlight") = py::none(),
      "Koschmieder fog (homogeneous, sky light only): T = exp(-sigma_t d), R = A (1 - T), "
      "C = I T + R. sigma_t_per_m: 1/m, one number or (R, G, B); airlight A: scene-linear, "
      "None = estimate_airlight(image).");

  py::class_<FileFogResult>(m, "FileFogResult", "What fog_file did.")
      .def_readonly("streamed", &FileFogResult::streamed,
                    "True: decoded, fogged and encoded in strips (sky-light-only scenes)")
      .def_readonly("reason", &FileFogResult::reason, "why it did not stream")
      .def_readonly("camera", &FileFogResult::camera)
      .def_readonly("width", &FileFogResult::width)
      .def_readonly("height", &FileFogResult::height)
      .def_readonly("no_surface_pixels", &FileFogResult::no_surface_pixels)
      .def_readonly("invalid_pixels", &FileFogResult::invalid_pixels)
      .def_readonly("sky_threshold_pixels", &FileFogResult::sky_threshold_pixels)
      .def_readonly("clamped_pixels", &FileFogResult::clamped_pixels);
  m.def(
      "fog_file",
      [](py::handle photo, py::handle depth, py::handle output, const mr::FogScene* scene,
         std::optional<mr::Camera> camera, py::handle depth_kind, double depth_scale,
         double baseline_m, double doffs_px, double sky_depth_m, py::handle pixel_type,
         const std::string& colorspace, const std::string& input_colorspace,
         const std::string& software, int jpeg_quality, bool overwrite, py::object color,
         mr::CancelToken* cancel) {
        const std::string photo_path = path_arg(photo, "photo");
        const std::string depth_path = path_arg(depth, "depth");
        const std::string output_path = path_arg(output, "output");
        const mr::FogScene s = scene ? *scene : mr::FogScene();
        mr::DepthOptions d;
        d.kind = depth_kind_arg(depth_kind);
        d.scale = depth_scale;
        d.baseline_m = baseline_m;
        d.doffs_px = doffs_px;
        d.sky_depth_m = sky_depth_m;
        const mr::PixelType type = pixel_type_arg(pixel_type);
        const mr::ColorConfig config = color.is_none() ? mr::ColorConfig::from_environment()
                                       : py::isinstance<mr::ColorConfig>(color)
                                           ? color.cast<mr::ColorConfig>()
                                           : mr::ColorConfig::from_file(path_arg(color, "color"));
        py::gil_scoped_release release;
        return fog_file(photo_path, depth_path, output_path, s, camera, d, type, colorspace,
                        input_colorspace, software, jpeg_quality, overwrite, config, cancel);
      },
      py::arg("photo"), py::arg("depth"), py::arg("output"), py::arg("scene") = py::none(),
      py::kw_only(), py::arg("camera") = py::none(), py::arg("depth_kind") = "distance",
      py::arg("depth_scale") = 1.0, py::arg("baseline_m") = 0.0, py::arg("doffs_px") = 0.0,
      py::arg("sky_depth_m") = mr::kDefaultSkyDepthM, py::arg("pixel_type") = "automatic",
      py::arg("colorspace") = "", py::arg("input_colorspace") = "", py::arg("software") = "",
      py::arg("jpeg_quality") = 95, py::arg("overwrite") = true, py::arg("color") = py::none(),
      py::arg("cancel") = py::none(),
      "One photo file -> one fogged file, exactly as `mr fog` writes it: the camera as "
      "default_camera (or `camera`), the depth file read as read_depth (kind, scale in "
      "metres per stored unit, ...), the output written atomically with mr fog's options "
      "(pixel_type 'automatic': EXR keeps float inputs float, else half; PNG/TIFF keep 16-bit "
      "inputs; 8/16-bit outputs through the highlight roll-off 'srgb_rolloff'). Scenes lit by "
      "the sky alone stream in strips (a few MiB of memory whatever the size); others render "
      "the whole frame. software: the output's Software tag (empty: the photo's). "
      "overwrite=False: FileError if the output exists. Releases the GIL.");

  // --- estimation ---
  py::class_<mr::SunEstimate>(m, "SunEstimate", "The sun fitted to the shadow pairs.")
      .def_readonly("direction_to_sun", &mr::SunEstimate::direction_to_sun)
      .def_readonly("azimuth_deg", &mr::SunEstimate::azimuth_deg)
      .def_readonly("elevation_deg", &mr::SunEstimate::elevation_deg)
      .def_readonly("rms_residual_deg", &mr::SunEstimate::rms_residual_deg)
      .def_readonly("median_residual_px", &mr::SunEstimate::median_residual_px);
  py::class_<EstimateResult>(m, "SceneEstimate",
                             "What estimate() found: a Scene for fog(), the distance map and "
                             "how far to trust them.")
      .def_readonly("scene", &EstimateResult::scene)
      .def_readonly("camera", &EstimateResult::camera)
      .def_readonly("camera_source", &EstimateResult::camera_source,
                    "'exif', 'vanishing points', 'default' or 'given'")
      .def_readonly("distance_m", &EstimateResult::distance_m,
                    "(H, W, 1) metres along each ray, +inf = sky")
      .def_readonly("sky_alpha", &EstimateResult::sky_alpha,
                    "(H, W, 1) soft sky matte in [0, 1] (None without the automatic sky mask); "
                    "pass to fog(sky_alpha=...)")
      .def_readonly("depth_confidence", &EstimateResult::depth_confidence,
                    "(H, W, 1) in [0, 1] or None")
      .def_readonly("horizon", &EstimateResult::horizon,
                    "the horizon at the first and last pixel column ((x, y), (x, y)), pixels")
      .def_readonly("horizon_source", &EstimateResult::horizon_source)
      .def_readonly("height_source", &EstimateResult::height_source)
      .def_readonly("confidence", &EstimateResult::confidence, "in [0, 1]")
      .def_readonly("sky_from_mask", &EstimateResult::sky_from_mask)
      .def_readonly("sun", &EstimateResult::sun, "SunEstimate or None (no shadow pairs)")
      .def_readonly("notes", &EstimateResult::notes)
      .def_readonly("pixels", &EstimateResult::pixels,
                    "pixel counts: sky, ground, plane, hint, billboard, contact, room, ...");

  m.def(
      "camera_for_photo",
      [](py::handle image, double fallback_fov_deg, std::optional<mr::Metadata> metadata) {
        const ImageArg photo(image, "image", metadata ? &*metadata : nullptr);
        mr::PhotoCamera pc;
        {
          py::gil_scoped_release release;
          pc = mr::camera_for_photo(photo.image(), fallback_fov_deg);
        }
        return py::make_tuple(pc.camera, pc.source, pc.confidence);
      },
      py::arg("image"), py::arg("fallback_fov_deg") = 60.0, py::kw_only(),
      py::arg("metadata") = py::none(),
      "(Camera, source, confidence): EXIF's focal length, else the photo's orthogonal "
      "vanishing points when confident, else fallback_fov_deg across.");

  m.def(
      "estimate",
      [](py::handle image, py::handle annotations, std::optional<mr::Camera> camera,
         std::optional<mr::Metadata> metadata, bool automatic, double default_camera_height_m,
         double billboard_depression_deg, bool ground_contact, double min_rise_ratio,
         bool refine_depth, bool sky_fold, bool vegetation, bool people, bool frame_border,
         bool backlit_land, bool water_mirror, bool lamps_not_sky, bool wall_not_sky,
         bool little_sky_evidence, bool level_sky_line, bool standing_people,
         mr::CancelToken* cancel) {
        const ImageArg photo(image, "image", metadata ? &*metadata : nullptr);
        const mr::Annotations notes_in = annotations_arg(annotations);
        mr::EstimateOptions o;
        o.automatic = automatic;
        o.default_camera_height_m = default_camera_height_m;
        o.billboard_depression_deg = billboard_depression_deg;
        o.ground_contact = ground_contact;
        o.min_rise_ratio = min_rise_ratio;
        o.refine_depth = refine_depth;
        o.sky_fold = sky_fold;
        o.vegetation = vegetation;
        o.people = people;
        o.frame_border = frame_border;
        o.backlit_land = backlit_land;
        o.water_mirror = water_mirror;
        o.lamps_not_sky = lamps_not_sky;
        o.wall_not_sky = wall_not_sky;
        o.little_sky_evidence = little_sky_evidence;
        o.level_sky_line = level_sky_line;
        o.standing_people = standing_people;
        o.cancel = cancel;
        EstimateResult r;
        mr::SceneEstimate est;
        {
          py::gil_scoped_release release;
          if (camera) {
            r.camera = *camera;
            r.camera_source = "given";
          } else {
            const mr::PhotoCamera pc = mr::camera_for_photo(photo.image());
            r.camera = pc.camera;
            r.camera_source = pc.source;
          }
          est = mr::estimate_scene(photo.image(), r.camera, notes_in, o);
        }
        mr::GeometryEstimate& g = est.geometry;
        r.scene = est.scene;
        r.distance_m = to_array(std::move(g.distance_m));
        r.sky_alpha = to_array(std::move(g.sky_alpha));
        r.depth_confidence = to_array(std::move(g.depth_confidence));
        r.horizon = g.horizon;
        r.horizon_source = mr::to_string(g.horizon_source);
        r.height_source = mr::to_string(g.height_source);
        r.confidence = g.confidence;
        r.sky_from_mask = g.sky_from_mask;
        r.sun = est.sun;
        r.notes = est.notes;
        r.pixels["sky"] = g.sky_pixels;
        r.pixels["ground"] = g.ground_pixels;
        r.pixels["plane"] = g.plane_pixels;
        r.pixels["hint"] = g.hint_pixels;
        r.pixels["billboard"] = g.billboard_pixels;
        r.pixels["contact"] = g.contact_pixels;
        r.pixels["sky_gap"] = g.sky_gap_pixels;
        r.pixels["vegetation"] = g.vegetation_pixels;
        r.pixels["vegetation_gap"] = g.vegetation_gap_pixels;
        r.pixels["tree"] = g.tree_pixels;
        r.pixels["room"] = g.room_pixels;
        r.pixels["people"] = g.people_pixels;
        r.pixels["frame_border"] = g.frame_border_pixels;
        return r;
      },
      py::arg("image"), py::arg("annotations") = py::none(), py::kw_only(),
      py::arg("camera") = py::none(), py::arg("metadata") = py::none(),
      py::arg("automatic") = mr::EstimateOptions{}.automatic,
      py::arg("default_camera_height_m") = mr::EstimateOptions{}.default_camera_height_m,
      py::arg("billboard_depression_deg") = mr::EstimateOptions{}.billboard_depression_deg,
      py::arg("ground_contact") = mr::EstimateOptions{}.ground_contact,
      py::arg("min_rise_ratio") = mr::EstimateOptions{}.min_rise_ratio,
      py::arg("refine_depth") = mr::EstimateOptions{}.refine_depth,
      py::arg("sky_fold") = mr::EstimateOptions{}.sky_fold,
      py::arg("vegetation") = mr::EstimateOptions{}.vegetation,
      py::arg("people") = mr::EstimateOptions{}.people,
      py::arg("frame_border") = mr::EstimateOptions{}.frame_border,
      py::arg("backlit_land") = mr::EstimateOptions{}.backlit_land,
      py::arg("water_mirror") = mr::EstimateOptions{}.water_mirror,
      py::arg("lamps_not_sky") = mr::EstimateOptions{}.lamps_not_sky,
      py::arg("wall_not_sky") = mr::EstimateOptions{}.wall_not_sky,
      py::arg("little_sky_evidence") = mr::EstimateOptions{}.little_sky_evidence,
      py::arg("level_sky_line") = mr::EstimateOptions{}.level_sky_line,
      py::arg("standing_people") = mr::EstimateOptions{}.standing_people,
      py::arg("cancel") = py::none(),
      "Single-photo estimation (as `mr estimate`): camera pose, a metric distance map and the "
      "light from a scene-linear photo (H, W, 3) and optional annotations (a dict, a JSON "
      "string, or a path to a libmr-annotations document; docs/annotations.md). camera: None "
      "= camera_for_photo(image). Lengths in metres, angles in degrees. Releases the GIL.");

  // --- material transfer ---
  py::class_<mr::Material> material(
      m, "Material",
      "Lambert diffuse + GGX specular: diffuse_albedo (RGB in [0, 1]), specular_albedo (F0 in "
      "[0, 1]), roughness (perceptual, [0.02, 1]).");
  material.def(py::init<>())
      .def_readwrite("diffuse_albedo", &mr::Material::diffuse_albedo)
      .def_readwrite("specular_albedo", &mr::Material::specular_albedo)
      .def_readwrite("roughness", &mr::Material::roughness)
      .def("__repr__", [](const mr::Material& x) {
        return "libmr.Material(diffuse_albedo=" +
               std::string(py::repr(py::cast(x.diffuse_albedo))) +
               ", specular_albedo=" + std::to_string(x.specular_albedo) +
               ", roughness=" + std::to_string(x.roughness) + ")";
      });
  py::class_<mr::MaterialCandidate>(m, "MaterialCandidate")
      .def_readonly("material", &mr::MaterialCandidate::material)
      .def_readonly("segment", &mr::MaterialCandidate::segment)
      .def_readonly("pixel_count", &mr::MaterialCandidate::pixel_count)
      .def_readonly("relative_rms", &mr::MaterialCandidate::relative_rms);
  py::class_<MaterialResult>(m, "MaterialTransferResult")
      .def_readonly("image", &MaterialResult::image,
                    "the target with its regions re-materialed, scene-linear (H, W, 3)")
      .def_readonly("segment_labels", &MaterialResult::segment_labels,
                    "(h, w, 1) the sample's segment id per pixel, -1 = unused")
      .def_readonly("candidates", &MaterialResult::candidates)
      .def_readonly("assignment", &MaterialResult::assignment,
                    "candidate index per region (region r = label r + 1)")
      .def_readonly("exposures", &MaterialResult::exposures,
                    "per region: the factor its rendering was scaled by to stay within the "
                    "photo's white (1: the photo's own exposure)")
      .def_readonly("objective", &MaterialResult::objective)
      .def_readonly("best_objective_history", &MaterialResult::best_objective_history)
      .def_readonly("notes", &MaterialResult::notes)
      .def_readonly("warnings", &MaterialResult::warnings)
      .def(
          "to_json", [](const MaterialResult& r) { return r.json; },
          "The 'mr-materials' JSON document (candidates, assignment, objective).");
  m.def(
      "load_region_labels",
      [](py::handle path, int width, int height) {
        mr::Image labels;
        const std::string file = path_arg(path, "path");
        {
          py::gil_scoped_release release;
          labels = mr::load_region_labels(file, width, height);
        }
        return to_array(std::move(labels));
      },
      py::arg("path"), py::arg("width"), py::arg("height"),
      "Region labels (H, W, 1), 0 = none, 1..n, from a mask image or an annotations JSON's "
      "plane polygons.");
  m.def(
      "transfer_material",
      [](py::handle sample, py::handle sample_depth, py::handle target, py::handle target_depth,
         py::handle region_labels, const mr::FogScene* sample_scene,
         const mr::FogScene* target_scene, std::optional<mr::Camera> sample_camera,
         std::optional<mr::Camera> target_camera, int max_candidates, double superpixel_size_px,
         double max_relative_rms, double smoothness_weight, int tabu_max_iterations,
         int tabu_patience, std::uint32_t seed, bool keep_detail, bool fit_photo_range, int threads,
         mr::CancelToken* cancel) {
        const ImageArg s_photo(sample, "sample");
        const ImageArg s_depth(sample_depth, "sample_depth");
        const ImageArg t_depth(target_depth, "target_depth");
        std::optional<ImageArg> t_photo;
        if (!target.is_none()) t_photo.emplace(target, "target");
        const int tw = t_depth.image().width(), th = t_depth.image().height();
        std::optional<ImageArg> labels_arg;
        mr::Image labels_file;
        if (py::isinstance<py::array>(region_labels))
          labels_arg.emplace(region_labels, "region_labels");
        else
          labels_file = mr::load_region_labels(path_arg(region_labels, "region_labels"), tw, th);
        const mr::Image& labels = labels_arg ? labels_arg->image() : labels_file;
        mr::ShadedPhoto s{
            &s_photo.image(), &s_depth.image(), {}, sample_scene ? *sample_scene : mr::FogScene()};
        s.camera = sample_camera ? *sample_camera
                                 : mr::Camera::from_metadata(s_photo.image().width(),
                                                             s_photo.image().height(),
                                                             s_photo.image().metadata());
        mr::ShadedPhoto t{t_photo ? &t_photo->image() : nullptr,
                          &t_depth.image(),
                          {},
                          target_scene ? *target_scene : mr::FogScene()};
        t.camera = target_camera
                       ? *target_camera
                       : mr::Camera::from_metadata(
                             tw, th, t_photo ? t_photo->image().metadata() : mr::Metadata());
        mr::MaterialTransferOptions o;
        o.max_candidates = max_candidates;
        o.superpixel_size_px = superpixel_size_px;
        o.max_relative_rms = max_relative_rms;
        o.smoothness_weight = smoothness_weight;
        o.tabu_max_iterations = tabu_max_iterations;
        o.tabu_patience = tabu_patience;
        o.seed = seed;
        o.keep_detail = keep_detail;
        o.fit_photo_range = fit_photo_range;
        o.threads = threads;
        o.cancel = cancel;
        mr::MaterialTransferResult res;
        MaterialResult r;
        {
          py::gil_scoped_release release;
          res = mr::transfer_material(s, t, labels, o);
          r.json = mr::material_result_to_json(res);
        }
        r.image = to_array(std::move(res.image));
        r.segment_labels = to_array(std::move(res.candidates.segment_labels));
        r.candidates = res.candidates.candidates;
        r.assignment = res.assignment;
        r.objective = res.objective;
        r.best_objective_history = res.best_objective_history;
        r.exposures = res.exposures;
        r.notes = res.notes;
        r.warnings = res.warnings;
        return r;
      },
      py::arg("sample"), py::arg("sample_depth"), py::arg("target"), py::arg("target_depth"),
      py::arg("region_labels"), py::kw_only(), py::arg("sample_scene") = py::none(),
      py::arg("target_scene") = py::none(), py::arg("sample_camera") = py::none(),
      py::arg("target_camera") = py::none(),
      py::arg("max_candidates") = mr::MaterialTransferOptions{}.max_candidates,
      py::arg("superpixel_size_px") = mr::MaterialTransferOptions{}.superpixel_size_px,
      py::arg("max_relative_rms") = mr::MaterialTransferOptions{}.max_relative_rms,
      py::arg("smoothness_weight") = mr::MaterialTransferOptions{}.smoothness_weight,
      py::arg("tabu_max_iterations") = mr::MaterialTransferOptions{}.tabu_max_iterations,
      py::arg("tabu_patience") = mr::MaterialTransferOptions{}.tabu_patience,
      py::arg("seed") = mr::MaterialTransferOptions{}.seed,
      py::arg("keep_detail") = mr::MaterialTransferOptions{}.keep_detail,
      py::arg("fit_photo_range") = mr::MaterialTransferOptions{}.fit_photo_range,
      py::arg("threads") = 0, py::arg("cancel") = py::none(),
      "Material style transfer (DESIGN.md section 5, as `mr material`): candidate materials "
      "fitted to the sample (scene-linear (h, w, 3) with its distance map, metres) are "
      "assigned to the target's regions (every assignment tried, or Tabu search for many regions) "
      "and re-rendered under the target's "
      "lighting (its scene's pose and lights). target None: a 3D scene given by its distance "
      "map alone. region_labels: (H, W) ids 0 = untouched, 1..n, or a mask / annotations path. "
      "Cameras: None = from the photo's metadata (60 degrees without EXIF). Deterministic for "
      "a seed. fit_photo_range: a region that would render beyond the photo's white is "
      "exposed down as a whole (False: the photo's own exposure). Releases the GIL.");
}

}  // namespace mrpy
