#include "preview.h"

#include <QFileInfo>
#include <chrono>
#include <filesystem>

#include "image_convert.h"

namespace fs = std::filesystem;

namespace mrstudio {

namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

const char* to_string(mr::Quality quality) {
  switch (quality) {
    case mr::Quality::draft:
      return "draft";
    case mr::Quality::normal:
      return "normal";
    case mr::Quality::final:
      return "final";
  }
  return "?";
}

std::shared_ptr<const Document> load_document(const QString& path, const mr::ColorConfig& color,
                                              const mr::Annotations* given_annotations,
                                              const mr::CancelToken* progress) {
  auto doc = std::make_shared<Document>();
  doc->photo_path = QFileInfo(path).absoluteFilePath();
  const fs::path photo_path = path.toStdString();
  mr::ReadOptions read;
  read.color = &color;
  mr::Image photo = mr::read_image(photo_path, read);
  if (photo.channels() >= 3) {
    doc->photo =
        photo.channels() == 3 ? std::move(photo) : photo.select_channels(std::array{0, 1, 2});
  } else {
    doc->photo = photo.select_channels(std::array{0, 0, 0});
  }
  doc->camera =
      mr::Camera::from_metadata(doc->photo.width(), doc->photo.height(), doc->photo.metadata());
  const float sigma = float(mr::extinction_from_visibility(150.0));
  doc->scene.medium.sigma_t_per_m = {sigma, sigma, sigma};

  std::error_code ec;
  const fs::path annotations_path =
      photo_path.parent_path() / (photo_path.stem().string() + "_annotations.json");
  const bool annotated = !given_annotations && fs::exists(annotations_path, ec);
  if (given_annotations)
    doc->annotations = *given_annotations;
  else if (annotated)
    doc->annotations = mr::load_annotations(annotations_path);
  // Blockers the annotations state (what the photo does not show) are the scene's, as in mr fog.
  if (doc->annotations.blockers) doc->scene.blockers = *doc->annotations.blockers;
  fs::path depth_path;
  for (const char* ext : {".exr", ".tif", ".tiff", ".pfm", ".png"}) {
    fs::path candidate = photo_path.parent_path() / (photo_path.stem().string() + "_depth" + ext);
    if (fs::exists(candidate, ec)) {
      depth_path = candidate;
      break;
    }
  }
  if (!depth_path.empty()) {
    mr::DepthMap depth = mr::read_depth(depth_path, doc->camera);
    doc->depth_source = QString::fromStdString(depth_path.string());
    if (depth.invalid_pixels > 0)
      doc->notes << QString("%1: %2 pixels are NaN or negative: treated as sky")
                        .arg(doc->depth_source)
                        .arg(depth.invalid_pixels);
    if (depth.no_surface_pixels == depth.distance_m.pixel_count())
      doc->notes << QString("%1: no pixel has a surface: all sky").arg(doc->depth_source);
    doc->distance_m = std::move(depth.distance_m);
  } else {
    try {
      mr::EstimateOptions options;
      options.cancel = progress;
      mr::SceneEstimate est =
          mr::estimate_scene(doc->photo, doc->camera, doc->annotations, options);
      doc->scene.pose = est.scene.pose;
      doc->scene.lighting.sun = est.scene.lighting.sun;
      doc->scene.lighting.sky_radiance = est.scene.lighting.sky_radiance;
      doc->distance_m = std::move(est.geometry.distance_m);
      doc->sky_alpha = std::move(est.geometry.sky_alpha);
      for (const std::string& note : est.notes) doc->notes << QString::fromStdString(note);
    } catch (const mr::Error& e) {
      throw mr::Error(e.code(), photo_path.string() + ": estimating the geometry: " + e.what());
    }
    doc->depth_estimated = true;
    doc->depth_source =
        annotated
            ? QString("estimated with %1").arg(QString::fromStdString(annotations_path.string()))
        : given_annotations ? QString("estimated with the project's annotations")
                            : QString("estimated automatically");
  }
  doc->photo_display = to_display(doc->photo, color);
  return doc;
}

std::shared_ptr<const Document> with_distance(const Document& document, mr::Image distance_m,
                                              mr::Image sky_alpha, const QString& depth_source) {
  auto doc = std::make_shared<Document>();
  doc->photo_path = document.photo_path;
  doc->photo = document.photo;
  doc->camera = document.camera;
  doc->distance_m = std::move(distance_m);
  doc->sky_alpha = std::move(sky_alpha);
  doc->depth_estimated = true;
  doc->depth_source = depth_source;
  doc->scene = document.scene;
  doc->notes = document.notes;
  doc->photo_display = document.photo_display;
  doc->annotations = document.annotations;
  return doc;
}

mr::Annotations scale_annotations(const mr::Annotations& annotations, double sx, double sy) {
  mr::Annotations a = annotations;
  // Pixel-centre coordinates: the continuous position (p + 0.5) scales.
  auto scale = [&](mr::PixelPoint& p) { p = {(p[0] + 0.5) * sx - 0.5, (p[1] + 0.5) * sy - 0.5}; };
  auto scale_all = [&](std::vector<mr::PixelPoint>& points) {
    for (auto& p : points) scale(p);
  };
  if (a.horizon) scale((*a.horizon)[0]), scale((*a.horizon)[1]);
  if (a.known_length) scale(a.known_length->a), scale(a.known_length->b);
  for (auto& plane : a.planes) {
    scale_all(plane.polygon);
    if (plane.base) scale((*plane.base)[0]), scale((*plane.base)[1]);
  }
  for (auto& hint : a.distance_hints) scale_all(hint.polygon);
  for (auto& pair : a.shadow_pairs)
    scale(pair.caster_top), scale(pair.caster_foot), scale(pair.shadow_tip);
  scale_all(a.sunlit_patch);
  scale_all(a.shadowed_patch);
  for (auto& lamp : a.lamps) scale(lamp.pixel);
  for (auto& patch : a.lamp_patches) scale_all(patch.polygon);
  if (a.interior_box) {
    scale_all(a.interior_box->floor);
    if (a.interior_box->ceiling_point) scale(*a.interior_box->ceiling_point);
  }
  return a;
}

std::shared_ptr<EstimateResult> run_estimate(const std::shared_ptr<const Document>& document,
                                             const mr::Annotations& annotations,
                                             const mr::ColorConfig& color,
                                             const mr::CancelToken* cancel) {
  const auto start = std::chrono::steady_clock::now();
  auto result = std::make_shared<EstimateResult>();
  mr::EstimateOptions options;
  options.cancel = cancel;
  if (document->depth_estimated ||
      double(document->photo.width()) * document->photo.height() <= kEstimatePixels) {
    result->estimate = mr::estimate_scene(document->photo, document->camera, annotations, options);
    result->overlay = to_display(
        mr::render_estimate_overlay(document->photo, result->estimate, annotations), color);
  } else {
    // The depth is measured (a depth file): only the pose, the light and the overlay are wanted,
    // and they do not need every pixel. The horizon's pose is exact at any scale (the camera
    // scales with it); the sun fit sees the same marks.
    const std::shared_ptr<const PreviewInputs> inputs =
        preview_inputs(*document, kEstimatePixels, color);
    const mr::Annotations scaled =
        scale_annotations(annotations, double(inputs->photo.width()) / document->photo.width(),
                          double(inputs->photo.height()) / document->photo.height());
    result->estimate = mr::estimate_scene(inputs->photo, inputs->camera, scaled, options);
    result->overlay =
        to_display(mr::render_estimate_overlay(inputs->photo, result->estimate, scaled), color);
  }
  if (document->depth_estimated)
    result->document = with_distance(*document, result->estimate.geometry.distance_m,
                                     result->estimate.geometry.sky_alpha,
                                     QStringLiteral("estimated from the annotations"));
  result->seconds = seconds_since(start);
  return result;
}

std::shared_ptr<const PreviewInputs> preview_inputs(const Document& document, double max_pixels,
                                                    const mr::ColorConfig& color) {
  const QSize size = fit_pixels(document.photo.width(), document.photo.height(), max_pixels);
  {
    const std::lock_guard<std::mutex> lock(document.inputs_mutex);
    for (const auto& cached : document.inputs_cache)
      if (cached->photo.width() == size.width() && cached->photo.height() == size.height())
        return cached;
  }
  auto inputs = std::make_shared<PreviewInputs>();
  inputs->photo = downscale_area(document.photo, size.width(), size.height());
  inputs->distance_m = mr::resize_nearest(document.distance_m, size.width(), size.height());
  if (!document.sky_alpha.empty())
    inputs->sky_alpha = downscale_area(document.sky_alpha, size.width(), size.height());
  inputs->camera = mr::scale_camera(document.camera, size.width(), size.height());
  inputs->photo_image = to_display(inputs->photo, color);
  inputs->depth = depth_colormap(inputs->distance_m);
  const std::lock_guard<std::mutex> lock(document.inputs_mutex);
  constexpr std::size_t kCachedSizes = 3;  // the draft's, the view's and one more (a resize, 100 %)
  if (document.inputs_cache.size() >= kCachedSizes)
    document.inputs_cache.erase(document.inputs_cache.begin());
  document.inputs_cache.push_back(inputs);
  return inputs;
}

const QImage& PreviewResult::displayLayer(Layer layer, const mr::ColorConfig& color) const {
  switch (layer) {
    case Layer::transmittance:
      if (transmittance.isNull()) transmittance = to_display(layers.transmittance, color);
      return transmittance;
    case Layer::inscatter:
      if (inscatter.isNull()) inscatter = to_display(layers.inscatter, color);
      return inscatter;
    case Layer::depth:
      return depth;
    case Layer::photo:
      return photo_image;
    default:
      return composite;
  }
}

std::shared_ptr<const mr::ObjectMesh> object_mesh(const Document& document,
                                                  const mr::SceneObject& object,
                                                  const QString& document_dir) {
  mr::SceneObject plain = object;
  plain.material.reset();  // the override goes with the InsertObject, not into the cached mesh
  const fs::path dir = document_dir.toStdString();
  const fs::path path = mr::object_mesh_path(plain, dir);
  const std::string key = path.empty() ? plain.mesh : path.lexically_normal().string();
  {
    const std::lock_guard<std::mutex> lock(document.insert_mutex);
    const auto it = document.meshes.find(key);
    if (it != document.meshes.end()) return it->second;
  }
  auto mesh = std::make_shared<const mr::ObjectMesh>(mr::resolve_object_mesh(plain, dir));
  const std::lock_guard<std::mutex> lock(document.insert_mutex);
  document.meshes.emplace(key, mesh);
  return mesh;
}

namespace {

// The parts of a scene the photo's insertion geometry depends on, and its light, as keys.
std::string geometry_key(const mr::FogScene& scene) {
  mr::FogScene s;
  s.pose = scene.pose;
  s.blockers = scene.blockers;
  s.render.volumetric_shadows = scene.render.volumetric_shadows;
  return mr::scene_to_json(s);
}
std::string lighting_key(const mr::FogScene& scene) {
  mr::FogScene s;
  s.lighting = scene.lighting;
  return mr::scene_to_json(s);
}

// The document's insertion preview at the inputs' size for `scene` (made, and kept, when there
// is none yet: the photo's normals, occluder mesh and BVH at that size).
std::shared_ptr<InsertSession> insert_session(const Document& document, const PreviewInputs& inputs,
                                              const mr::FogScene& scene,
                                              const mr::CancelToken* cancel, double& prepare_s) {
  const std::string key = geometry_key(scene);
  const int w = inputs.photo.width(), h = inputs.photo.height();
  {
    const std::lock_guard<std::mutex> lock(document.insert_mutex);
    for (const auto& s : document.insert_sessions)
      if (s->width == w && s->height == h && s->geometry_key == key) return s;
  }
  auto session = std::make_shared<InsertSession>();
  session->width = w;
  session->height = h;
  session->geometry_key = key;
  session->lighting_key = lighting_key(scene);
  session->preview = std::make_unique<mr::InsertPreview>(
      inputs.photo, inputs.distance_m, inputs.camera, scene, mr::InsertOptions::preview(), cancel);
  prepare_s = session->preview->prepare_seconds();
  const std::lock_guard<std::mutex> lock(document.insert_mutex);
  constexpr std::size_t kSessions = 3;  // the draft's size, the view's, one more
  if (document.insert_sessions.size() >= kSessions)
    document.insert_sessions.erase(document.insert_sessions.begin());
  document.insert_sessions.push_back(session);
  return session;
}

}  // namespace

std::shared_ptr<PreviewResult> render_preview(const PreviewRequest& request,
                                              const mr::ColorConfig& color) {
  const auto start = std::chrono::steady_clock::now();
  auto result = std::make_shared<PreviewResult>();
  result->generation = request.generation;
  result->quality = request.quality;
  const std::shared_ptr<const PreviewInputs> inputs =
      preview_inputs(*request.document, request.max_pixels, color);
  result->photo = inputs->photo;
  result->distance_m = inputs->distance_m;
  result->sky_alpha = inputs->sky_alpha;
  result->camera = inputs->camera;
  result->scene = request.scene;
  result->scene.render.quality = request.quality;
  mr::FogScene fog_scene = result->scene;
  if (!request.scene.objects.empty()) {
    // Issue 16: the objects go into the photo first (differential rendering), then the fog
    // takes the composite and the objects' depth like a photo of its own.
    const auto insert_start = std::chrono::steady_clock::now();
    std::vector<mr::InsertObject> objects;
    for (const mr::SceneObject& so : request.scene.objects) {
      mr::InsertObject o;
      o.mesh = *object_mesh(*request.document, so, request.document_dir);
      o.placement = so.placement;
      o.material = so.material;
      objects.push_back(std::move(o));
    }
    const std::shared_ptr<InsertSession> session = insert_session(
        *request.document, *inputs, request.scene, request.cancel.get(), result->insert_prepare_s);
    const std::lock_guard<std::mutex> lock(session->mutex);
    const std::string light = lighting_key(request.scene);
    if (light != session->lighting_key) {
      session->preview->set_lighting(request.scene.lighting);
      session->lighting_key = light;
    }
    const bool draft = request.quality == mr::Quality::draft;
    const mr::InsertResult& inserted = session->preview->render(
        objects, draft ? mr::InsertOptions::preview() : mr::InsertOptions::preview_refined(),
        request.cancel.get());
    result->photo = inserted.composite;
    result->distance_m = inserted.distance_m;
    result->matte = inserted.matte;
    // The objects cover the sky where they stand in front of it: they are not fogged as sky.
    if (!result->sky_alpha.empty())
      for (std::size_t i = 0; i < result->sky_alpha.pixels().size(); ++i)
        result->sky_alpha.pixels()[i] *= 1.0f - result->matte.pixels()[i];
    // The objects' shafts in the fog: in the idle (normal) pass only; a drag's drafts skip the
    // fog core's occluder rebuild that their triangles would cost.
    if (!draft)
      for (mr::Blockers::Polygon& p : mr::object_shadow_polygons(objects))
        fog_scene.blockers.polygons.push_back(std::move(p));
    result->insert_tiles = session->preview->last_frame().tiles_rendered;
    result->insert_tiles_total = session->preview->last_frame().tiles_total;
    result->insert_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - insert_start).count();
  }
  const auto render_start = std::chrono::steady_clock::now();
  mr::ScatteringLayers aovs;
  result->layers = mr::fog(result->photo, result->distance_m, result->sky_alpha, result->camera,
                           fog_scene, &aovs, request.cancel.get());
  // Issue 11 item 3: as `mr fog --depth auto`, a guessed depth's seams softened (not under a
  // sun or lamps, whose shafts' edges are the scene's).
  if (request.document->depth_estimated && !fog_scene.lighting.sun &&
      fog_scene.lighting.lamps.empty())
    mr::soften_fog_seams(result->photo, result->layers);
  result->render_s = seconds_since(render_start);
  result->backend = aovs.backend;
  result->backend_notice = aovs.backend_notice;
  result->composite = to_display(result->layers.composite, color);
  result->photo_image = inputs->photo_image;  // QImage: shared, not copied
  if (request.display_aovs) {
    result->transmittance = to_display(result->layers.transmittance, color);
    result->inscatter = to_display(result->layers.inscatter, color);
  }
  result->depth = inputs->depth;
  result->total_s = seconds_since(start);
  if (request.prepare_insert_pixels > 0) {
    // Idle work for the insertion tool; a failure here is the first drop's to report.
    try {
      const std::shared_ptr<const PreviewInputs> draft =
          preview_inputs(*request.document, request.prepare_insert_pixels, color);
      double prepare_s = 0;
      insert_session(*request.document, *draft, request.scene, request.cancel.get(), prepare_s);
    } catch (const mr::Error& e) {
      if (e.code() == mr::ErrorCode::cancelled) throw;
    }
  }
  return result;
}

}  // namespace mrstudio
