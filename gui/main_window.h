// mr-studio's main window: the photo view with a before/after split, the layer switcher, the
// fog panel, the live preview (rendered on a worker thread: a draft pass on <= 0.25 MP, then a
// normal pass at the view's resolution; a new edit cancels the running pass through its
// mr::CancelToken, and stale results are discarded by a generation counter),
// project files and export. Errors are shown in non-modal message boxes (and errorShown).
// The annotation tools (annotation_editor.h) edit the photo's annotations over the view; every
// edit is undoable and re-estimates the scene (mr::estimate_scene) on the worker, which updates
// the pose, the sun, the sky, the lamps (and the distance map when it was estimated) and the
// "Estimation overlay" layer. Unsaved changes are asked about on close and open, autosaved to
// a recovery file and offered back at start; recent files are kept in QSettings.
// Long work (loading with an estimate, re-estimates, preview passes, exports) shows its progress
// (mr::Progress, through the job's mr::CancelToken) in a bar in the status bar; the worker's
// reports reach the UI thread through a queued signal.
#pragma once
#include <QElapsedTimer>
#include <QFutureWatcher>
#include <QMainWindow>
#include <QMessageBox>
#include <QThreadPool>
#include <QTimer>
#include <array>
#include <atomic>
#include <memory>

#include "annotation_editor.h"
#include "mr/color.h"
#include "preview.h"

class QActionGroup;
class QCheckBox;
class QComboBox;
class QDockWidget;
class QDoubleSpinBox;
class QLabel;
class QListWidget;
class QMenu;
class QProgressBar;
class QSlider;

namespace mrstudio {

class BlockersPanel;
class FogPanel;
class ObjectsPanel;
class ObjectTool;
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
  /// Export settings (the export dialog edits them).
  struct ExportSettings {
    mr::PixelType pixel_type = mr::PixelType::automatic;
    std::string colorspace;  ///< empty: the format's default (sRGB / scene_linear)
    bool aovs = false;       ///< EXR: + transmittance, inscatter, depth layers (scene-linear)
  };
  /// Renders at full resolution (normal quality) and writes the composite (with `settings`);
  /// blocks the caller while waiting but keeps the event loop running (a progress dialog with
  /// Cancel is shown when `show_progress`). true on success; false on error or cancel.
  bool exportImage(const QString& path, const ExportSettings& settings, bool show_progress = false);
  bool exportImage(const QString& path) { return exportImage(path, ExportSettings{}); }
  /// Cancels a running export (nothing is written).
  void cancelExport();

  AnnotationEditor* annotationEditor() const { return editor_; }
  void setTool(Tool tool);
  /// Re-estimates the scene from the annotations on the worker; estimateFinished follows.
  /// `apply_scene`: false only updates the overlay (a project's saved scene stays as saved).
  void reestimate(bool apply_scene = true);
  /// An estimate is running or about to start (an edit's debounce).
  /// Snaps the selected plane / lamp-patch polygon to the object it outlines (OpenCV GrabCut,
  /// on the worker); one undoable edit. snapFinished follows.
  void snapSelectedPolygon();
  bool estimating() const { return estimating_ || estimate_timer_.isActive(); }
  QImage estimateOverlay() const { return estimate_overlay_; }
  QString projectPath() const { return project_path_; }

  /// Unsaved edits (fog panel or annotations) since the last save or open.
  bool isModified() const;
  /// Tests: answer every following question (unsaved changes: Save / Discard / Cancel; recovery:
  /// Yes / No) with `answer` instead of showing a box. NoButton: ask with a message box.
  void setPromptAnswer(QMessageBox::StandardButton answer) { prompt_answer_ = answer; }
  /// Asks what to do with unsaved changes; true when the caller may go on (saved or discarded).
  bool maybeSave();
  /// The recovery file and how often it is written while there are unsaved changes.
  void setAutosave(const QString& recovery_path, int interval_ms);
  QString recoveryPath() const { return recovery_path_; }
  /// Writes the recovery file now (when there is a photo). true on success.
  bool autosaveNow();
  /// At start: when a recovery file exists, offers to reopen it. true when it was reopened.
  bool offerRecovery();
  QStringList recentFiles() const;

  FogPanel* fogPanel() const { return fog_panel_; }
  /// Blockers the photo does not show (the scene's mr::Blockers; its own dock).
  BlockersPanel* blockersPanel() const { return blockers_panel_; }
  QDockWidget* blockersDock() const { return blockers_dock_; }
  ObjectsPanel* objectsPanel() const { return objects_panel_; }
  /// The insertion tool over the view (drop a model, drag / turn / scale objects).
  ObjectTool* objectTool() const { return object_tool_; }
  QDockWidget* objectsDock() const { return objects_dock_; }
  ImageView* imageView() const { return view_; }
  QComboBox* layerBox() const { return layer_box_; }
  QSlider* splitSlider() const { return split_slider_; }
  const Document* document() const { return document_.get(); }
  /// The newest preview shown (nullptr before the first).
  std::shared_ptr<const PreviewResult> preview() const { return preview_; }
  bool rendering() const { return rendering_; }
  int generation() const { return generation_; }
  /// Preview renders stopped by a newer edit so far (mr::CancelToken).
  int cancelledRenders() const { return cancelled_renders_; }
  /// Whether a new edit cancels the running preview render (default) or lets it finish and
  /// drops its result; off only to measure what cancelling gains (bench/bench_studio.cpp).
  void setCancelStaleRenders(bool on) { cancel_stale_renders_ = on; }
  EventLoopMonitor* eventLoopMonitor() const { return monitor_; }
  void setLayer(Layer layer);
  /// The status bar's progress of the running work (hidden when idle).
  QProgressBar* progressBar() const { return progress_bar_; }
  /// The long work whose progress the status bar shows; when several run, the first listed.
  enum class Job { export_image, load, estimate, preview };

 signals:
  void photoLoaded();
  void previewUpdated(int generation, int quality);  ///< quality: int(mr::Quality)
  void errorShown(const QString& message);
  void estimateFinished(bool ok, const QString& message);
  void snapFinished(bool ok, const QString& message);
  /// Emitted on the worker thread from a job's progress callback; it reaches onProgress queued.
  /// `job`: int(Job); `id`: the job's run (reports of a run that has ended are dropped).
  void progressReported(int job, quint64 id, const QString& stage, double fraction);
  /// On the UI thread, after the status bar's progress changed: its text and fraction in
  /// [0, 1]; an empty text: the bar is hidden (nothing runs).
  void progressShown(const QString& text, double fraction);

 protected:
  void dragEnterEvent(QDragEnterEvent*) override;
  void dropEvent(QDropEvent*) override;
  void closeEvent(QCloseEvent*) override;

 private:
  void buildMenus();
  void showError(const QString& title, const QString& message);
  void requestPreview();
  void startRender(mr::Quality quality);
  /// `cancelled`: the render was stopped by a newer edit (no result, no error).
  void onRenderDone(std::shared_ptr<PreviewResult> result, QString error, int generation,
                    bool cancelled = false);
  void showLayer();
  /// The camera and the sun of the scene into the blockers panel (drawn for orientation).
  void syncBlockersContext();
  void updateTitle();
  void onOpen();
  void onSaveProject();
  void onOpenProject();
  void onExport();
  void buildAnnotationDock();
  void refreshAnnotationList();
  void onEstimateDone(std::shared_ptr<EstimateResult> result, QString error, int generation,
                      bool apply);
  QMessageBox::StandardButton ask(QMessageBox::Icon icon, const QString& title, const QString& text,
                                  QMessageBox::StandardButtons buttons);
  QByteArray projectJson(const QString& path) const;  ///< throws mr::Error
  void writeFileAtomically(const QString& path, const QByteArray& data) const;
  void addRecentFile(const QString& path);
  void rebuildRecentMenu();
  void openAny(const QString& path);  ///< photo or project, after maybeSave
  /// Starts a run of `job` (a newer run replaces an older one's progress): the progress that
  /// calls using `token` report reaches the status bar. Returns the run's id for endProgress.
  /// Only before the job's call starts using the token.
  quint64 startProgress(Job job, mr::CancelToken& token);
  /// The run `id` of `job` has ended (a no-op when a newer run has replaced it).
  void endProgress(Job job, quint64 id);
  void onProgress(int job, quint64 id, const QString& stage, double fraction);
  void showProgress();

  mr::ColorConfig color_;
  ImageView* view_;
  FogPanel* fog_panel_;
  BlockersPanel* blockers_panel_;
  QDockWidget* blockers_dock_;
  ObjectsPanel* objects_panel_;  // issue 16: inserted 3D objects (the scene's objects list)
  QDockWidget* objects_dock_;
  ObjectTool* object_tool_;
  QComboBox* layer_box_;
  QSlider* split_slider_;
  QLabel* backend_label_;
  QLabel* timing_label_;
  QLabel* warning_label_;  ///< the preview scene's warnings (mr::scene_warnings)
  QLabel* zoom_label_;
  QProgressBar* progress_bar_;
  EventLoopMonitor* monitor_;
  struct JobProgress {
    quint64 id = 0;  ///< the running run's, 0: none runs
    QString stage;   ///< the stage last reported (empty before the first report)
    double fraction = 0;
  };
  std::array<JobProgress, 4> progress_;  ///< by Job
  quint64 last_progress_id_ = 0;

  std::shared_ptr<const Document> document_;
  std::shared_ptr<const PreviewResult> preview_;
  QString project_path_;
  std::unique_ptr<mr::FogScene> pending_scene_;  ///< scene to apply when the photo loads (project)
  std::unique_ptr<mr::Annotations> pending_annotations_;  ///< the project's annotations

  AnnotationEditor* editor_;
  QActionGroup* tool_group_;
  QDockWidget* fog_dock_;
  QDockWidget* annotation_dock_;
  QListWidget* annotation_list_;
  QCheckBox* height_check_;
  QDoubleSpinBox* height_spin_;
  QDoubleSpinBox* length_spin_;
  QCheckBox* ceiling_check_;
  QDoubleSpinBox* ceiling_spin_;
  QCheckBox* auto_estimate_;
  QLabel* estimate_label_;
  QTimer estimate_timer_;  ///< debounces re-estimates after edits
  QImage estimate_overlay_;
  int estimate_generation_ = 0;
  bool estimating_ = false;
  bool estimate_pending_ = false;
  bool estimate_pending_apply_ = false;
  QString unpaired_note_;
  /// The annotations as of the undo stack's last index change (JSON): an index change that
  /// leaves them alone (an object edit) does not re-estimate.
  std::string
      stacked_annotations_;  ///< what the running estimate leaves out (lamps without a patch)

  bool scene_modified_ = false;
  QMessageBox::StandardButton prompt_answer_ = QMessageBox::NoButton;
  QString recovery_path_;
  QTimer autosave_timer_;
  QMenu* recent_menu_ = nullptr;
  std::shared_ptr<mr::CancelToken> export_cancel_;  ///< the running export's (stops mr::fog)
  std::shared_ptr<mr::CancelToken> render_cancel_;  ///< the running preview render's
  int load_generation_ = 0;
  int generation_ = 0;           ///< bumped by every edit; results of older ones are discarded
  bool rendering_ = false;       ///< a render job is on the worker
  bool render_pending_ = false;  ///< an edit arrived while rendering: render again when done
  int cancelled_renders_ = 0;
  bool cancel_stale_renders_ = true;
  bool has_warning_ = false;  ///< the preview's scene has a warning (warning_label_)
  bool exporting_ = false;
  /// Runs loads, renders and exports; the destructor waits for it (jobs post back to `this`).
  QThreadPool pool_;
};

}  // namespace mrstudio
