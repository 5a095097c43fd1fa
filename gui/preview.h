// The photo being edited (photo, camera, distance map, estimated scene) and the preview render
// job: mr::fog on a downscaled copy, turned into displayable layers. Both run on worker threads;
// they only read what they are given.
#pragma once
#include <QImage>
#include <QSize>
#include <QString>
#include <QStringList>
#include <map>
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
  mr::Image sky_alpha;  ///< the document's sky matte at this size (area average); may be empty
  mr::Camera camera;
  QImage photo_image, depth;  ///< 8-bit sRGB photo; depth colour map
};

/// A photo's interactive insertion preview at one size (mr::InsertPreview: the photo's geometry
/// prepared once, then frames that re-render only the tiles the objects touch), with what it was
/// made for. One render at a time (mutex).
struct InsertSession {
  int width = 0, height = 0;
  std::string geometry_key;  ///< the pose, blockers and shadow settings it was prepared with
  std::string lighting_key;  ///< the light it renders with now
  std::mutex mutex;
  std::unique_ptr<mr::InsertPreview> preview;
};

struct Document {
  QString photo_path;
  mr::Image photo;  ///< scene-linear RGB (3 channels)
  mr::Camera camera;
  mr::Image distance_m;  ///< 1 channel, metres along the ray, +inf = sky
  /// The estimate's soft sky matte (1 channel, 1 = sky; GeometryEstimate::sky_alpha), given to
  /// mr::fog so that the fogged sky edge is as soft as the photo's. Empty with a depth file.
  mr::Image sky_alpha;
  bool depth_estimated = false;
  QString depth_source;  ///< the depth file, or "estimated (...)"
  mr::FogScene scene;    ///< starting scene: estimated pose / sun / sky, default medium
  QStringList notes;     ///< estimation notes, depth warnings
  QImage photo_display;  ///< the photo as 8-bit sRGB, full resolution
  /// The annotations the document opened with (the project's, else {stem}_annotations.json,
  /// else none); the editor edits a copy.
  mr::Annotations annotations;

  /// Downscaled inputs already made, newest last (a few sizes: the draft's, the view's): an edit
  /// re-renders without resizing the full-resolution photo again. Filled by preview_inputs.
  mutable std::mutex inputs_mutex;
  mutable std::vector<std::shared_ptr<const PreviewInputs>> inputs_cache;
  /// Insertion previews made so far (the draft's size, the view's), newest last; and the object
  /// meshes loaded so far (by model path or primitive name), so that a drag neither reloads a
  /// model nor rebuilds the photo's geometry.
  mutable std::mutex insert_mutex;
  mutable std::vector<std::shared_ptr<InsertSession>> insert_sessions;
  mutable std::map<std::string, std::shared_ptr<const mr::ObjectMesh>> meshes;
};

/// The mesh of a scene object (without its material override), loaded once per document and
/// model path. Thread-safe. Throws mr::Error naming the file.
std::shared_ptr<const mr::ObjectMesh> object_mesh(const Document& document,
                                                  const mr::SceneObject& object,
                                                  const QString& document_dir);

/// Reads the photo, its depth ({stem}_depth.{exr,tif,tiff,pfm,png} next to it, as `mr fog`
/// finds it) or, without one, the geometry from mr::estimate_scene (automatic; with
/// `annotations` when given, else {stem}_annotations.json when it exists). Throws mr::Error
/// naming the file. `progress` (may be null): the estimation's steps are reported to it.
std::shared_ptr<const Document> load_document(const QString& path, const mr::ColorConfig& color,
                                              const mr::Annotations* annotations = nullptr,
                                              const mr::CancelToken* progress = nullptr);

/// A copy of `document` with another distance map and sky matte (an estimate from edited
/// annotations).
std::shared_ptr<const Document> with_distance(const Document& document, mr::Image distance_m,
                                              mr::Image sky_alpha, const QString& depth_source);

/// A re-estimate of the scene from edited annotations (run on a worker thread).
struct EstimateResult {
  int generation = 0;
  mr::SceneEstimate estimate;
  QImage overlay;  ///< mr::render_estimate_overlay as 8-bit sRGB
  /// The document with the estimated distance map when its depth was estimated (a depth file,
  /// being measured, is kept); else nullptr.
  std::shared_ptr<const Document> document;
  double seconds = 0;
};
/// Photos above this size with a measured depth are estimated on a downscaled copy.
inline constexpr double kEstimatePixels = 2.0e6;
/// Annotations of a photo resized by sx, sy (pixel-centre convention kept).
mr::Annotations scale_annotations(const mr::Annotations& annotations, double sx, double sy);
/// Throws mr::Error (annotations that do not fit the photo, contradictory shadow pairs, ...).
/// `cancel` (may be null): the estimation's steps are reported to it, and it stops the estimate.
std::shared_ptr<EstimateResult> run_estimate(const std::shared_ptr<const Document>& document,
                                             const mr::Annotations& annotations,
                                             const mr::ColorConfig& color,
                                             const mr::CancelToken* cancel = nullptr);

/// The layers the view can show.
enum class Layer { composite, photo, transmittance, inscatter, depth, estimate };

struct PreviewRequest {
  std::shared_ptr<const Document> document;
  mr::FogScene scene;  ///< render.quality is set from `quality`
  mr::Quality quality = mr::Quality::draft;
  double max_pixels = 0.25e6;  ///< the render's size: the photo's aspect, at most this many pixels
  bool display_aovs = false;   ///< convert the transmittance and in-scatter for display too
  int generation = 0;
  /// Requested by the UI thread when a newer edit makes this render stale: mr::fog stops within
  /// a row and render_preview throws mr::Error(cancelled). Its progress callback (when set)
  /// hears mr::fog's stages. May be null.
  std::shared_ptr<mr::CancelToken> cancel;
  /// Where the scene's relative model paths start (the project's folder; empty: absolute).
  QString document_dir;
  /// > 0: after rendering, also prepare the document's insertion preview at this size (the
  /// photo's geometry for mr::InsertPreview) if it is not yet, so that the first model dropped
  /// on the photo pays only its frame. mr-studio asks for the draft's size in normal passes.
  double prepare_insert_pixels = 0;
};

struct PreviewResult {
  int generation = 0;
  mr::Quality quality = mr::Quality::draft;
  // What was rendered, exactly: mr::fog(photo, distance_m, sky_alpha, camera, scene) gives
  // `layers`.
  mr::Image photo, distance_m, sky_alpha;
  mr::Camera camera;
  mr::FogScene scene;
  mr::FogLayers layers;
  QImage composite, photo_image, depth;  ///< 8-bit sRGB for display
  /// The transmittance and in-scatter layers for display: made by the render job only when
  /// PreviewRequest::display_aovs (they are shown rarely; each costs a colour conversion), else
  /// on first use by displayLayer on the UI thread.
  mutable QImage transmittance, inscatter;
  const QImage& displayLayer(Layer layer, const mr::ColorConfig& color) const;
  std::string backend, backend_notice;
  double render_s = 0, total_s = 0;  ///< mr::fog alone; everything (downscale, display)
  /// The scene's objects (issue 16), inserted before the fog by the document's mr::InsertPreview
  /// at this size: `photo` and `distance_m` above are then the insertion's composite and depth,
  /// `matte` the objects' coverage (empty without objects). Draft passes use
  /// InsertOptions::preview() and leave the objects out of the fog's shadow casters; normal
  /// passes use InsertOptions::preview_refined() and let the objects cast shafts.
  mr::Image matte;
  double insert_s = 0;          ///< the insertion frame (objects' scene, tiles), 0 without objects
  double insert_prepare_s = 0;  ///< the photo's geometry, when this pass had to prepare it
  std::size_t insert_tiles = 0, insert_tiles_total = 0;
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
