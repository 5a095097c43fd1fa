// The streaming sky-only pipeline (mr/fog_stream.h). Every per-pixel step is the full-frame
// path's own code, applied to strips: OCIO conversions through ColorConfig::convert_pixels (the
// processors are per pixel, so strips give the same values), depth through
// detail::stored_depth_to_distance (depth_to_distance's), the fog through
// render::sky_only_inscatter (the scattering core's), the composite through photo::composite.
// What is repeated here from io.cpp is file plumbing only (which attributes are dropped, which
// formats hold which pixel types), kept in step by tests/fog_stream_test.cpp, which compares
// the outputs file for file.
#include "mr/fog_stream.h"

#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <vector>

#include "atomic_file.h"
#include "depth_convert.h"
#include "mr/error.h"
#include "mr/scattering.h"
#include "core/metadata_impl.h"
#include "image_files.h"
#include "oiio_formats.h"
#include "photo/composite.h"
#include "render/medium.h"

namespace mr {

namespace {

using detail::automatic_pixel_type;
using detail::drop_encoding_attributes;
using detail::format_supports;
using detail::ImageHeader;
using detail::ImageReader;
using detail::ImageWriter;
using detail::stored_type;

constexpr double kInf = std::numeric_limits<double>::infinity();

bool is_integer(PixelType t) {
  return t == PixelType::uint8 || t == PixelType::uint16;
}

int depth_channel(const ImageHeader& spec) {
  for (const char* name : {"Z", "depth.Z", "Y", "depth.Y", "R"})
    for (int c = 0; c < spec.nchannels; ++c)
      if (c < int(spec.channelnames.size()) && spec.channelnames[c] == name) return c;
  return 0;
}

// One strip of rows in flight. Its buffers keep their capacity from photo to photo.
struct Strip {
  int y0 = 0, rows = 0;
  std::vector<unsigned char> photo_codes;   // decoded photo, 8/16-bit codes, n channels
  std::vector<unsigned char> depth_values;  // decoded depth channel: float or 8/16-bit codes
  std::vector<float> pixels;                // linear photo, then the composite, n channels
  std::vector<float> distance_m, transmittance, inscatter;  // one row
  std::vector<unsigned char> out_codes;                     // encoded composite (integer outputs)
  detail::DepthCounts counts;
};

template <class T>
void ensure(std::vector<T>& v, std::size_t n) {
  if (v.size() < n) v.resize(n);
}

std::unique_ptr<ImageReader> open_quietly(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return nullptr;
  try {
    return detail::open_image_reader(path);
  } catch (const Error&) {
    return nullptr;  // the full-frame path reports the problem
  }
}

}  // namespace

bool is_sky_only(const FogScene& scene) {
  // As the scattering core's constant-source test (render/scattering_cpu.cpp).
  return !scene.lighting.sun && scene.lighting.lamps.empty() && scene.medium.noise.amplitude <= 0;
}

struct FogStreamer::Impl {
  std::vector<Strip> strips;
};

FogStreamer::FogStreamer() : impl_(std::make_unique<Impl>()) {}
FogStreamer::~FogStreamer() = default;

StreamFogResult FogStreamer::fog_file(const StreamFogRequest& req, const CancelToken* cancel) {
  StreamFogResult result;
  auto decline = [&](std::string reason) {
    result.streamed = false;
    result.reason = std::move(reason);
    return result;
  };
  if (!req.scene) throw Error(ErrorCode::invalid_argument, "fog_file: no scene");
  const FogScene& scene = *req.scene;
  if (!is_sky_only(scene)) return decline("the scene has a sun, lamps or noise");
  if (!scene.lighting.sky_radiance) return decline("the sky radiance is estimated from the photo");
  const bool by_direction = scene.lighting.sky_by_direction.value_or(false);
  if (by_direction && !req.sky_light)
    return decline("the sky light by direction needs its map (mr::sky_light_from_photo)");
  validate_scene(scene);
  ColorConfig storage = ColorConfig::builtin();
  const ColorConfig& config = req.color ? *req.color : (storage = ColorConfig::from_environment());

  // --- The photo's header: what read_image would do with it.
  const Image* image = req.photo_image;
  std::unique_ptr<ImageReader> in;
  int w = 0, h = 0, n = 0, photo_bits = 0;
  std::string from;
  std::vector<std::string> channel_names;
  Metadata metadata;
  if (image) {
    w = image->width(), h = image->height(), n = image->channels();
    if (n < 3 || n > 4) return decline("not RGB or RGBA");
    channel_names = image->channel_names();
    metadata = image->metadata();
  } else {
    in = open_quietly(req.photo);
    if (!in) return decline("the photo cannot be opened here");
    const ImageHeader& spec = in->spec();
    w = spec.width, h = spec.height, n = spec.nchannels;
    if (w <= 0 || h <= 0 || spec.depth > 1) return decline("unusual image shape");
    if (std::uint64_t(w) * std::uint64_t(h) > max_decoded_pixels())
      return decline("larger than the decoded-size limit");
    if (n != 3 && n != 4) return decline("not RGB or RGBA");
    if (spec.tile_width > 0) return decline("tiled photo");
    if (!spec.channelformats.empty()) return decline("per-channel pixel types");
    const int orientation = spec.get_int_attribute("Orientation", 1);
    if (orientation >= 2 && orientation <= 8) return decline("EXIF orientation turns the photo");
    if (spec.format.is(detail::DataType::kUInt8))
      photo_bits = 8;
    else if (spec.format.is(detail::DataType::kUInt16))
      photo_bits = 16;
    else
      return decline("not an 8/16-bit photo");
    from = req.input_colorspace;
    if (from.empty()) {
      const std::string tag = spec.get_string_attribute("oiio:ColorSpace");
      from = config.has_colorspace(tag) && !config.is_data(tag) ? tag : colorspace::srgb;
    } else if (!config.has_colorspace(from)) {
      return decline("unknown input colour space");
    }
    channel_names = spec.channelnames;
    metadata.impl().attributes = spec.extra_attribs;
    drop_encoding_attributes(metadata.impl().attributes);
  }

  // --- The depth file's header: what read_depth would do with it.
  auto depth_in = open_quietly(req.depth);
  if (!depth_in) return decline("the depth map cannot be opened here");
  const ImageHeader dspec = depth_in->spec();
  if (dspec.width != w || dspec.height != h || dspec.depth > 1 || dspec.nchannels <= 0)
    return decline("depth map of another size");
  if (dspec.tile_width > 0) return decline("tiled depth map");
  if (!dspec.channelformats.empty()) return decline("depth map with per-channel pixel types");
  const int d_orientation = dspec.get_int_attribute("Orientation", 1);
  if (d_orientation >= 2 && d_orientation <= 8) return decline("depth map has an orientation");
  detail::DataType depth_type;
  std::size_t depth_bytes = 0;
  if (dspec.format.is(detail::DataType::kUInt8))
    depth_type = detail::kTypeUInt8, depth_bytes = 1;
  else if (dspec.format.is(detail::DataType::kUInt16))
    depth_type = detail::kTypeUInt16, depth_bytes = 2;
  else if (dspec.format.is(detail::DataType::kFloat) || dspec.format.is(detail::DataType::kHalf))
    depth_type = detail::kTypeFloat, depth_bytes = 4;
  else
    return decline("depth map of an unusual pixel type");
  const int depth_c = depth_channel(dspec);
  const DepthOptions& depth_options = req.depth_options;
  if (!(depth_options.scale > 0) || !std::isfinite(depth_options.scale) ||
      !std::isfinite(depth_options.doffs_px) ||
      (depth_options.kind == DepthKind::disparity &&
       (!(depth_options.baseline_m > 0) || !std::isfinite(depth_options.baseline_m))))
    return decline("bad depth options");

  // --- The output: what write_image would do.
  const std::filesystem::path& out_path = req.output;
  std::unique_ptr<ImageWriter> out = detail::create_image_writer(out_path);
  if (!out) return decline("no writer for the output's extension");
  const std::string format = out->format_name();
  const WriteOptions& wo = req.write;
  const PixelType out_type =
      wo.pixel_type == PixelType::automatic ? automatic_pixel_type(format) : wo.pixel_type;
  if (!format_supports(format, out_type)) return decline("the format cannot store the bit depth");
  if (wo.jpeg_quality < 1 || wo.jpeg_quality > 100) return decline("bad JPEG quality");
  const std::string to = !wo.colorspace.empty()
                             ? wo.colorspace
                             : (is_integer(out_type) ? colorspace::srgb : colorspace::scene_linear);
  if (!config.has_colorspace(to)) return decline("unknown output colour space");
  {
    std::error_code ec;
    const auto folder =
        out_path.parent_path().empty() ? std::filesystem::path(".") : out_path.parent_path();
    if (!std::filesystem::is_directory(folder, ec)) return decline("no output folder");
    if (!wo.overwrite && std::filesystem::exists(out_path, ec)) return decline("output exists");
  }

  const Camera camera =
      req.camera ? req.camera(w, h, metadata) : Camera::from_metadata(w, h, metadata);
  if (camera.width != w || camera.height != h)
    throw Error(ErrorCode::size_mismatch, req.photo.string() + ": camera is " +
                                              std::to_string(camera.width) + "x" +
                                              std::to_string(camera.height) + ", photo is " +
                                              std::to_string(w) + "x" + std::to_string(h));
  if (by_direction && !req.sky_light->scale.empty() &&
      (req.sky_light->scale.width() != w || req.sky_light->scale.height() != h))
    return decline("the sky light's scale is not the photo's size");
  if (by_direction && !req.sky_light->tint.empty() &&
      (req.sky_light->tint.width() != w || req.sky_light->tint.height() != h ||
       req.sky_light->tint.channels() != 3))
    return decline("the sky light's tint is not the photo's size with 3 channels");
  result.camera = camera;
  result.width = w;
  result.height = h;

  // --- The fog: the scattering core's closed form with its own constants.
  const Medium& medium = scene.medium;
  const std::array<float, 3> sky = *scene.lighting.sky_radiance;
  const double sigma[3] = {medium.sigma_t_per_m[0], medium.sigma_t_per_m[1],
                           medium.sigma_t_per_m[2]};
  // Homogeneous fog without a layer: the unit optical depth along any ray is its length, which
  // is what RayDensity::optical_depth(0, d) returns for it, bit for bit (k = 1, a = 0).
  const bool unbounded_homogeneous =
      !medium.height_fog && medium.layer_bottom_m == -kInf && medium.layer_top_m == kInf;
  const auto [forward, right, up] = scene.pose.axes();
  const render::Vec3d origin{scene.pose.position_m.x, scene.pose.position_m.y,
                             scene.pose.position_m.z};
  // The core's view ray (render/scattering_cpu.cpp, Core::ray), same operations in order.
  auto ray = [&](int x, int y) {
    const double a = (x + 0.5 - camera.cx) / camera.focal_px,
                 b = (y + 0.5 - camera.cy) / camera.focal_px;
    const render::Vec3d d{forward.x + a * right.x + -b * up.x, forward.y + a * right.y + -b * up.y,
                          forward.z + a * right.z + -b * up.z};
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    return render::Vec3d{d[0] / len, d[1] / len, d[2] / len};
  };
  const double focal_baseline = camera.focal_px * depth_options.baseline_m;

  // --- Strips.
  int strip_rows = req.strip_rows;
  if (strip_rows <= 0) {
    // About 128 K pixels a strip (a few MB of floats: cache-friendly, many in flight), in
    // multiples of 16 rows (JPEG MCU rows, OpenEXR zip chunks).
    strip_rows = std::clamp(int((131072 + w - 1) / w + 15) / 16 * 16, 16, 256);
  }
  const int threads = tbb::this_task_arena::max_concurrency();
  const std::size_t strip_count = std::size_t((h + strip_rows - 1) / strip_rows);
  const std::size_t tokens = std::min<std::size_t>(strip_count, std::size_t(2 * threads + 2));
  result.strips = strip_count;
  std::vector<Strip>& strips = impl_->strips;
  if (strips.size() < tokens) strips.resize(tokens);
  const std::size_t photo_bytes = std::size_t(photo_bits / 8);  // 0: photo in memory
  const std::size_t strip_px = std::size_t(w) * std::size_t(strip_rows);
  const int out_bits = out_type == PixelType::uint8 ? 8 : 16;
  for (std::size_t i = 0; i < tokens; ++i) {
    Strip& s = strips[i];
    ensure(s.photo_codes, strip_px * n * photo_bytes);
    ensure(s.depth_values, strip_px * depth_bytes);
    ensure(s.pixels, strip_px * n);
    ensure(s.distance_m, std::size_t(w));
    ensure(s.transmittance, std::size_t(w) * 3);
    ensure(s.inscatter, std::size_t(w) * 3);
    if (is_integer(out_type)) ensure(s.out_codes, strip_px * n * std::size_t(out_bits / 8));
  }

  // --- The output file, opened before the first strip is decoded.
  ImageHeader out_spec;
  out_spec.width = w, out_spec.height = h, out_spec.nchannels = n;
  out_spec.format = stored_type(out_type);
  out_spec.channelnames = channel_names;
  if (n == 4) out_spec.alpha_channel = 3;
  out_spec.extra_attribs = metadata.impl().attributes;
  drop_encoding_attributes(out_spec.extra_attribs);
  out_spec.attribute("oiio:ColorSpace", to);
  if (!req.software.empty()) out_spec.attribute("Software", req.software);
  if (format == "jpeg") {
    out_spec.attribute("Compression", "jpeg:" + std::to_string(wo.jpeg_quality));
    // As write_image: full-resolution chroma.
    out_spec.attribute("jpeg:subsampling", "4:4:4");
  }
  if (format == "openexr") out_spec.attribute("Compression", "zip");
  if (format == "tiff") out_spec.attribute("Compression", "zip");
  detail::AtomicFile file(out_path);
  // `out` was made before `file`: closed (reset) explicitly below before the commit, or, on
  // an exception, before the temporary file is removed.
  struct CloseFirst {
    std::unique_ptr<ImageWriter>& out;
    ~CloseFirst() { out.reset(); }
  } close_first{out};
  out->open(file.temp_path().string(), out_path.string(), out_spec);

  int next_row = 0;
  std::size_t next_token = 0;
  bool stopped = false;
  const detail::DataType photo_type = photo_bits == 16 ? detail::kTypeUInt16 : detail::kTypeUInt8;
  const double alpha_scale = 1.0 / (photo_bits == 16 ? 65535.0 : 255.0);
  const double out_max_code = out_bits == 8 ? 255.0 : 65535.0;
  report_progress(cancel, "render", 0, std::size_t(h));  // mr/cancel.h: rows written
  tbb::parallel_pipeline(
      tokens,
      // Decode the photo's next rows (libjpeg & co. decode in order: one strip at a time).
      tbb::make_filter<void, Strip*>(
          tbb::filter_mode::serial_in_order,
          [&](tbb::flow_control& fc) -> Strip* {
            if (next_row >= h || (cancel && cancel->requested())) {
              stopped = next_row < h;
              fc.stop();
              return nullptr;
            }
            Strip& s = strips[next_token++ % tokens];
            s.y0 = next_row;
            s.rows = std::min(strip_rows, h - next_row);
            next_row += s.rows;
            // The photo's own type (photo_bits is its format): a native read.
            if (in)
              in->read_scanlines(s.y0, s.y0 + s.rows, 0, n, photo_type, s.photo_codes.data());
            return &s;
          }) &
          // Decode the depth map's rows (its own decoder: overlaps the photo's).
          tbb::make_filter<Strip*, Strip*>(
              tbb::filter_mode::serial_in_order,
              [&](Strip* s) {
                // Native (no conversion) when stored as read (float, 8 or 16-bit).
                depth_in->read_scanlines(s->y0, s->y0 + s->rows, depth_c, depth_c + 1, depth_type,
                                         s->depth_values.data());
                return s;
              }) &
          // Linearise, fog, composite, encode: strips in parallel.
          tbb::make_filter<Strip*, Strip*>(
              tbb::filter_mode::parallel,
              [&](Strip* s) {
                const std::ptrdiff_t in_px = std::ptrdiff_t(n * photo_bytes),
                                     lin_px = std::ptrdiff_t(n * sizeof(float));
                if (in)
                  config.convert_pixels(s->photo_codes.data(), photo_bits, in_px, in_px * w,
                                        s->pixels.data(), 32, lin_px, lin_px * w, w, s->rows, from,
                                        colorspace::scene_linear);
                const std::size_t count = std::size_t(w) * std::size_t(s->rows);
                if (in && n > 3) {  // alpha: normalised codes, as read_image
                  const auto* c8 = s->photo_codes.data();
                  const auto* c16 = reinterpret_cast<const std::uint16_t*>(s->photo_codes.data());
                  for (std::size_t i = 0; i < count; ++i)
                    for (int c = 3; c < n; ++c) {
                      const std::size_t k = i * n + c;
                      s->pixels[k] = float((photo_bits == 8 ? c8[k] : c16[k]) * alpha_scale);
                    }
                }
                s->counts = {};
                const auto* depth_f = reinterpret_cast<const float*>(s->depth_values.data());
                const auto* depth_8 = s->depth_values.data();
                const auto* depth_16 =
                    reinterpret_cast<const std::uint16_t*>(s->depth_values.data());
                float* dist = s->distance_m.data();
                float* t_row = s->transmittance.data();
                float* r_row = s->inscatter.data();
                for (int r = 0; r < s->rows; ++r) {
                  const int y = s->y0 + r;
                  const std::size_t base = std::size_t(r) * w;
                  for (int x = 0; x < w; ++x) {
                    // read_depth: integer files as their stored codes, floats as they are.
                    const double stored = depth_bytes == 4   ? double(depth_f[base + x])
                                          : depth_bytes == 2 ? double(depth_16[base + x])
                                                             : double(depth_8[base + x]);
                    dist[x] = detail::stored_depth_to_distance(stored * depth_options.scale,
                                                               depth_options, camera,
                                                               focal_baseline, x, y, s->counts);
                  }
                  for (int x = 0; x < w; ++x) {
                    // The core's sky-only pixel: od = sigma * RayDensity(0, d), T = exp(-od),
                    // R = sky_only_inscatter (render/scattering_cpu.cpp, march and pass 3).
                    const double d = dist[x];
                    const double unit =
                        unbounded_homogeneous
                            ? d
                            : render::RayDensity(medium, origin, ray(x, y)).optical_depth(0, d);
                    double od[3], inscatter[3];
                    for (int c = 0; c < 3; ++c)
                      od[c] = render::scaled_optical_depth(sigma[c], unit);
                    render::sky_only_inscatter(od, medium.albedo, sky, inscatter);
                    if (by_direction && !req.sky_light->deviation.empty()) {
                      // As mr::add_sky_light on the full-frame path's float layers: the
                      // deviation from L_sky along this pixel's ray.
                      const Rgb deviation =
                          req.sky_light->deviation_at(scene.pose.ray_direction(camera, x, y), x, y);
                      const double od_stored[3] = {float(od[0]), float(od[1]), float(od[2])};
                      double extra[3];
                      render::sky_only_inscatter(od_stored, medium.albedo, deviation, extra);
                      for (int c = 0; c < 3; ++c)
                        inscatter[c] = float(std::max(0.0, double(float(inscatter[c])) + extra[c]));
                    }
                    double tau = 0;
                    for (int c = 0; c < 3; ++c) {
                      if (c == 0 || !(od[c] == od[c - 1])) tau = std::exp(-od[c]);
                      t_row[3 * x + c] = float(tau);
                      r_row[3 * x + c] = float(inscatter[c]);
                    }
                  }
                  // In place over the decoded row, or from the photo in memory.
                  const ImageView composite{s->pixels.data() + base * n, w, 1, n,
                                            std::ptrdiff_t(w) * n};
                  const ConstImageView photo_row =
                      image ? ConstImageView{image->pixel(0, y), w, 1, n, std::ptrdiff_t(w) * n}
                            : ConstImageView(composite);
                  photo::composite(photo_row, ConstImageView{t_row, w, 1, 3, std::ptrdiff_t(w) * 3},
                                   ConstImageView{r_row, w, 1, 3, std::ptrdiff_t(w) * 3},
                                   composite);
                }
                if (is_integer(out_type)) {
                  const std::size_t out_bytes = std::size_t(out_bits / 8);
                  const std::ptrdiff_t out_px = std::ptrdiff_t(n * out_bytes);
                  config.convert_pixels(s->pixels.data(), 32, lin_px, lin_px * w,
                                        s->out_codes.data(), out_bits, out_px, out_px * w, w,
                                        s->rows, colorspace::scene_linear, to);
                  auto* c16 = reinterpret_cast<std::uint16_t*>(s->out_codes.data());
                  for (std::size_t i = 0; i < count; ++i)  // alpha, as write_image
                    for (int c = 3; c < n; ++c) {
                      const std::size_t k = i * n + c;
                      const double v =
                          std::lround(std::clamp(double(s->pixels[k]), 0.0, 1.0) * out_max_code);
                      if (out_bits == 8)
                        s->out_codes[k] = static_cast<unsigned char>(v);
                      else
                        c16[k] = static_cast<std::uint16_t>(v);
                    }
                } else {
                  config.convert_pixels(s->pixels.data(), 32, lin_px, lin_px * w, s->pixels.data(),
                                        32, lin_px, lin_px * w, w, s->rows,
                                        colorspace::scene_linear, to);
                }
                return s;
              }) &
          // Encode in order.
          tbb::make_filter<Strip*, void>(tbb::filter_mode::serial_in_order, [&](Strip* s) {
            if (is_integer(out_type))
              out->write_scanlines(s->y0, s->y0 + s->rows,
                                   out_bits == 8 ? detail::kTypeUInt8 : detail::kTypeUInt16,
                                   s->out_codes.data());
            else
              out->write_scanlines(s->y0, s->y0 + s->rows, detail::kTypeFloat,
                                   s->pixels.data());
            result.no_surface_pixels += s->counts.no_surface;
            result.invalid_pixels += s->counts.invalid;
            result.sky_threshold_pixels += s->counts.sky_threshold;
            result.clamped_pixels += s->counts.clamped;
            report_progress(cancel, "render", std::size_t(s->y0 + s->rows), std::size_t(h));
          }));
  if (stopped) throw_if_cancelled(cancel, "fog_file");
  in.reset();
  depth_in.reset();
  out->close();
  out.reset();
  file.commit(wo.overwrite);
  result.streamed = true;
  return result;
}

}  // namespace mr
