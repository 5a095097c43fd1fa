// mr-studio's main window: the photo view with a before/after split, the layer switcher, the
// fog panel, the live preview (rendered on a worker thread: a draft pass on <= 0.25 MP, then a
// normal pass at the view's resolution; stale results are discarded by a generation counter),
// project files and export. Errors are shown in non-modal message boxes (and errorShown).
#pragma once
#include <QElapsedTimer>
#include <QFutureWatcher>
#include <QMainWindow>
#include <QThreadPool>
#include <QTimer>
#include <memory>

#include "mr/color.h"
#include "preview.h"

class QComboBox;
class QLabel;
class QSlider;

namespace mrstudio {

class FogPanel;
class ImageView;

/// Measures how long the event loop goes without running a 10 ms timer (the longest gap).
class EventLoopMonitor : public QObject {
  Q_OBJECT
 public:
  explicit EventLoopMonitor(QObject* parent = nullptr);
  void reset();
  double maxGapMs() const { return max_gap_ms_; }

 private:
  QTimer timer_;
  QElapsedTimer clock_;
  double max_gap_ms_ = 0;
};

class MainWindow : public QMainWindow {
  Q_OBJECT
 public:
  explicit MainWindow(QWidget* parent = nullptr);
  ~MainWindow() override;

  /// Starts loading a photo (asynchronously); photoLoaded or errorShown follows.
  void openPhoto(const QString& path);
  /// Writes the project (photo path relative to the project file, and the scene). true on success.
  bool saveProject(const QString& path);
  /// Reads a project and opens its photo with its scene.
  void openProject(const QString& path);
  /// Renders at full resolution (normal quality) and writes the composite; blocks the caller
  /// while waiting but keeps the event loop running. true on success.
  bool exportImage(const QString& path);

  FogPanel* fogPanel() const { return fog_panel_; }
  ImageView* imageView() const { return view_; }
  QComboBox* layerBox() const { return layer_box_; }
  QSlider* splitSlider() const { return split_slider_; }
  const Document* document() const { return document_.get(); }
  /// The newest preview shown (nullptr before the first).
  std::shared_ptr<const PreviewResult> preview() const { return preview_; }
  bool rendering() const { return rendering_; }
  int generation() const { return generation_; }
  EventLoopMonitor* eventLoopMonitor() const { return monitor_; }
  void setLayer(Layer layer);

 signals:
  void photoLoaded();
  void previewUpdated(int generation, int quality);  ///< quality: int(mr::Quality)
  void errorShown(const QString& message);

 protected:
  void dragEnterEvent(QDragEnterEvent*) override;
  void dropEvent(QDropEvent*) override;

 private:
  void buildMenus();
  void showError(const QString& title, const QString& message);
  void requestPreview();
  void startRender(mr::Quality quality);
  void onRenderDone(std::shared_ptr<PreviewResult> result, QString error, int generation);
  void showLayer();
  void updateTitle();
  void onOpen();
  void onSaveProject();
  void onOpenProject();
  void onExport();

  mr::ColorConfig color_;
  ImageView* view_;
  FogPanel* fog_panel_;
  QComboBox* layer_box_;
  QSlider* split_slider_;
  QLabel* backend_label_;
  QLabel* timing_label_;
  QLabel* zoom_label_;
  EventLoopMonitor* monitor_;

  std::shared_ptr<const Document> document_;
  std::shared_ptr<const PreviewResult> preview_;
  QString project_path_;
  std::unique_ptr<mr::FogScene> pending_scene_;  ///< scene to apply when the photo loads (project)
  int load_generation_ = 0;
  int generation_ = 0;         ///< bumped by every edit; results of older ones are discarded
  bool rendering_ = false;     ///< a render job is on the worker
  bool render_pending_ = false;  ///< an edit arrived while rendering: render again when done
  bool exporting_ = false;
  /// Runs loads, renders and exports; the destructor waits for it (jobs post back to `this`).
  QThreadPool pool_;
};

}  // namespace mrstudio
