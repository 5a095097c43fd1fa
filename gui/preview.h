// The photo being edited (photo, camera, distance map, estimated scene) and the preview render
// job: mr::fog on a downscaled copy, turned into displayable layers. Both run on worker threads;
// they only read what they are given.
#pragma once
#include <QImage>
#include <QSize>
#include <QString>
#include <QStringList>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "mr/mr.h"

namespace mrstudio {

/// The downscaled inputs of a preview at one size (photo area-averaged, depth nearest, camera
/// scaled) and their display images.
struct PreviewInputs {
  mr::Image photo, distance_m;
  mr::Camera camera;
  QImage photo_image, depth;  ///< 8-bit sRGB photo; depth colour map
};

struct Document {
  QString photo_path;
  mr::Image photo;  ///< scene-linear RGB (3 channels)
  mr::Camera camera;
  mr::Image distance_m;  ///< 1 channel, metres along the ray, +inf = sky
  bool depth_estimated = false;
  QString depth_source;  ///< the depth file, or "estimated (...)"
  mr::FogScene scene;    ///< starting scene: estimated pose / sun / sky, default medium
  QStringList notes;     ///< estimation notes, depth warnings
  QImage photo_display;  ///< the photo as 8-bit sRGB, full resolution

  /// Downscaled inputs already made, newest last (a few sizes: the draft's, the view's): an edit
  /// re-renders without resizing the full-resolution photo again. Filled by preview_inputs.
  mutable std::mutex inputs_mutex;
  mutable std::vector<std::shared_ptr<const PreviewInputs>> inputs_cache;
};

/// Reads the photo, its depth ({stem}_depth.{exr,tif,tiff,pfm,png} next to it, as `mr fog`
/// finds it) or, without one, the geometry from mr::estimate_scene (automatic; with
/// {stem}_annotations.json when it exists). Throws mr::Error naming the file.
std::shared_ptr<const Document> load_document(const QString& path, const mr::ColorConfig& color);

/// The layers the view can show.
enum class Layer { composite, photo, transmittance, inscatter, depth };

struct PreviewRequest {
  std::shared_ptr<const Document> document;
  mr::FogScene scene;  ///< render.quality is set from `quality`
  mr::Quality quality = mr::Quality::draft;
  double max_pixels = 0.25e6;  ///< the render's size: the photo's aspect, at most this many pixels
  int generation = 0;
};

struct PreviewResult {
  int generation = 0;
  mr::Quality quality = mr::Quality::draft;
  // What was rendered, exactly: mr::fog(photo, distance_m, camera, scene) gives `layers`.
  mr::Image photo, distance_m;
  mr::Camera camera;
  mr::FogScene scene;
  mr::FogLayers layers;
  QImage composite, photo_image, transmittance, inscatter, depth;  ///< 8-bit sRGB for display
  std::string backend, backend_notice;
  double render_s = 0, total_s = 0;  ///< mr::fog alone; everything (downscale, display)
};

/// The downscaled inputs of a request at fit_pixels(photo, max_pixels): from the document's
/// cache, or made (and cached) now. Thread-safe.
std::shared_ptr<const PreviewInputs> preview_inputs(const Document& document, double max_pixels,
                                                    const mr::ColorConfig& color);

/// Renders a request. Throws mr::Error.
std::shared_ptr<PreviewResult> render_preview(const PreviewRequest& request,
                                              const mr::ColorConfig& color);

const char* to_string(mr::Quality quality);

}  // namespace mrstudio
