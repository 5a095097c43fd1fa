#include "main_window.h"

#include <QAction>
#include <QActionGroup>
#include <QApplication>
#include <QCheckBox>
#include <QCloseEvent>
#include <QComboBox>
#include <QDir>
#include <QDockWidget>
#include <QDoubleSpinBox>
#include <QDragEnterEvent>
#include <QDropEvent>
#include <QEventLoop>
#include <QFile>
#include <QFileDialog>
#include <QFileInfo>
#include <QFormLayout>
#include <QGroupBox>
#include <QHBoxLayout>
#include <QJsonArray>
#include <QJsonDocument>
#include <QJsonObject>
#include <QLabel>
#include <QListWidget>
#include <QLocale>
#include <QMenuBar>
#include <QMessageBox>
#include <QMimeData>
#include <QProgressBar>
#include <QProgressDialog>
#include <QPushButton>
#include <QScrollArea>
#include <QSettings>
#include <QSlider>
#include <QStandardPaths>
#include <QStatusBar>
#include <QToolBar>
#include <QUndoStack>
#include <QVBoxLayout>
#include <QtConcurrent/QtConcurrentRun>
#include <algorithm>
#include <cmath>
#include <optional>

#include "blockers_panel.h"
#include "export_dialog.h"
#include "fog_panel.h"
#include "grabcut_assist.h"
#include "image_convert.h"
#include "image_view.h"
#include "object_tool.h"
#include "objects_panel.h"

namespace mrstudio {

namespace {

// The draft pass: on the 2-core machine mr::fog at draft quality takes ~25 ms on 0.25 MP and the
// whole pass shows ~42 ms after an edit (bench/bench_studio.cpp; 0.5 MP took ~99 ms).
constexpr double kDraftPixels = 0.25e6;
constexpr const char* kProjectFormat = "mr-studio-project";
constexpr int kRecentFiles = 8;
constexpr int kDefaultAutosaveMs = 60000;
// The progress bars' resolution (per mille: a 2000-row render moves it every other row).
constexpr int kProgressSteps = 1000;
// The stage an export reports while it writes the file (mr::fog's stages come first).
constexpr char kWritingStage[] = "writing";

QString ms(double seconds) {
  return QString::number(seconds * 1000.0, 'f', 0) + " ms";
}

}  // namespace

EventLoopMonitor::EventLoopMonitor(QObject* parent) : QObject(parent) {
  timer_.setInterval(10);
  timer_.setTimerType(Qt::PreciseTimer);
  connect(&timer_, &QTimer::timeout, this, [this] {
    max_gap_ms_ = std::max(max_gap_ms_, double(clock_.nsecsElapsed()) / 1e6);
    clock_.restart();
  });
  clock_.start();
  timer_.start();
}

void EventLoopMonitor::reset() {
  max_gap_ms_ = 0;
  clock_.restart();
}

MainWindow::MainWindow(QWidget* parent) : QMainWindow(parent), color_(mr::ColorConfig::builtin()) {
  setWindowTitle("mr-studio");
  setAcceptDrops(true);
  resize(1280, 800);

  view_ = new ImageView;
  setCentralWidget(view_);
  editor_ = new AnnotationEditor(this);
  view_->setEditor(editor_);

  fog_panel_ = new FogPanel;
  auto* scroll = new QScrollArea;
  scroll->setWidget(fog_panel_);
  scroll->setWidgetResizable(true);
  scroll->setHorizontalScrollBarPolicy(Qt::ScrollBarAlwaysOff);
  scroll->setMinimumWidth(fog_panel_->sizeHint().width() + 24);
  fog_dock_ = new QDockWidget(tr("Fog and light"), this);
  fog_dock_->setObjectName("fogDock");
  fog_dock_->setFeatures(QDockWidget::DockWidgetMovable | QDockWidget::DockWidgetFloatable);
  fog_dock_->setWidget(scroll);
  addDockWidget(Qt::RightDockWidgetArea, fog_dock_);
  buildAnnotationDock();
  tabifyDockWidget(fog_dock_, annotation_dock_);
  // Blockers the photo does not show (issue 13): they live in the scene (fog_panel_'s base
  // scene); the panel edits a copy and writes it back.
  blockers_panel_ = new BlockersPanel;
  blockers_panel_->setObjectName("blockersPanel");
  auto* blockers_scroll = new QScrollArea;
  blockers_scroll->setWidget(blockers_panel_);
  blockers_scroll->setWidgetResizable(true);
  blockers_scroll->setHorizontalScrollBarPolicy(Qt::ScrollBarAlwaysOff);
  blockers_dock_ = new QDockWidget(tr("Blockers"), this);
  blockers_dock_->setObjectName("blockersDock");
  blockers_dock_->setFeatures(QDockWidget::DockWidgetMovable | QDockWidget::DockWidgetFloatable);
  blockers_dock_->setWidget(blockers_scroll);
  addDockWidget(Qt::RightDockWidgetArea, blockers_dock_);
  tabifyDockWidget(annotation_dock_, blockers_dock_);
  // Inserted 3D objects (issue 16): like the blockers, they live in the scene; the panel edits
  // a copy and writes it back.
  objects_panel_ = new ObjectsPanel;
  objects_panel_->setObjectName("objectsPanel");
  auto* objects_scroll = new QScrollArea;
  objects_scroll->setWidget(objects_panel_);
  objects_scroll->setWidgetResizable(true);
  objects_scroll->setHorizontalScrollBarPolicy(Qt::ScrollBarAlwaysOff);
  objects_dock_ = new QDockWidget(tr("Objects"), this);
  objects_dock_->setObjectName("objectsDock");
  objects_dock_->setFeatures(QDockWidget::DockWidgetMovable | QDockWidget::DockWidgetFloatable);
  objects_dock_->setWidget(objects_scroll);
  addDockWidget(Qt::RightDockWidgetArea, objects_dock_);
  tabifyDockWidget(blockers_dock_, objects_dock_);
  // The insertion tool over the view: drop a model on the photo, drag / turn / scale objects.
  object_tool_ = new ObjectTool(objects_panel_, this);
  view_->setObjectTool(object_tool_);
  connect(object_tool_, &ObjectTool::message, this,
          [this](const QString& m) { statusBar()->showMessage(tr("Objects: %1").arg(m), 10000); });
  fog_dock_->raise();

  layer_box_ = new QComboBox;
  layer_box_->setObjectName("layerBox");
  layer_box_->addItem(tr("Composite"), int(Layer::composite));
  layer_box_->addItem(tr("Photo"), int(Layer::photo));
  layer_box_->addItem(tr("Transmittance"), int(Layer::transmittance));
  layer_box_->addItem(tr("In-scatter"), int(Layer::inscatter));
  layer_box_->addItem(tr("Depth"), int(Layer::depth));
  layer_box_->addItem(tr("Estimation overlay"), int(Layer::estimate));
  split_slider_ = new QSlider(Qt::Horizontal);
  split_slider_->setObjectName("splitSlider");
  split_slider_->setRange(0, 100);
  split_slider_->setValue(50);
  split_slider_->setFixedWidth(160);
  split_slider_->setToolTip(
      tr("Before / after: left of the line the photo, right of it the layer"));

  buildMenus();

  auto* bar = addToolBar(tr("View"));
  bar->setObjectName("viewToolBar");
  bar->setMovable(false);
  bar->addWidget(new QLabel(tr(" Layer ")));
  bar->addWidget(layer_box_);
  bar->addSeparator();
  bar->addWidget(new QLabel(tr(" Before | after ")));
  bar->addWidget(split_slider_);
  view_->setSplit(0.5);

  // The annotation tools, one checkable action each (exclusive).
  auto* tools = addToolBar(tr("Annotate"));
  tools->setObjectName("annotateToolBar");
  tools->setMovable(false);
  tools->setToolButtonStyle(Qt::ToolButtonTextOnly);
  tool_group_ = new QActionGroup(this);
  const std::pair<Tool, QString> tool_names[] = {
      {Tool::navigate, tr("Pan")},         {Tool::select, tr("Select")},
      {Tool::horizon, tr("Horizon")},      {Tool::known_length, tr("Length")},
      {Tool::shadow_pair, tr("Shadow")},   {Tool::lamp, tr("Lamp")},
      {Tool::plane, tr("Plane")},          {Tool::lamp_patch, tr("Lamp patch")},
      {Tool::interior_floor, tr("Floor")}, {Tool::ceiling_point, tr("Ceiling")}};
  const char* tool_tips[] = {
      "Drag to pan (the middle button pans with every tool)",
      "Click an annotation to select it, drag a point to move it, Delete removes it",
      "Click two points on the horizon (where the ground would meet the sky if it were flat)",
      "Click two points on the ground a known distance apart (the length is in the Annotations "
      "panel)",
      "Click the top of a vertical object, its foot on the ground, then the tip of its shadow",
      "Click a lamp (it also needs a lamp patch: a surface it lights)",
      "Click the corners of a vertical wall or object standing on the ground; double-click or "
      "Enter closes",
      "Click the corners of a surface lit by the lamps; double-click or Enter closes",
      "Interior box: click where the walls meet the floor, in order along the floor's edge (each "
      "two points span one wall); double-click or Enter finishes",
      "Interior box: click where the ceiling meets a wall (or give the ceiling height in the "
      "Annotations panel)"};
  int k = 0;
  for (const auto& [tool, name] : tool_names) {
    QAction* action = tools->addAction(name);
    action->setCheckable(true);
    action->setData(int(tool));
    action->setToolTip(tr(tool_tips[k++]));
    action->setObjectName(QString("tool_%1").arg(int(tool)));
    tool_group_->addAction(action);
    if (tool == Tool::navigate) action->setChecked(true);
  }
  connect(tool_group_, &QActionGroup::triggered, this,
          [this](QAction* a) { setTool(Tool(a->data().toInt())); });

  backend_label_ = new QLabel(tr("backend: -"));
  timing_label_ = new QLabel;
  zoom_label_ = new QLabel;
  // Shown once they have something to say (empty framed boxes look broken).
  timing_label_->setVisible(false);
  zoom_label_->setVisible(false);
  connect(view_, &ImageView::zoomChanged, zoom_label_, [this] { zoom_label_->setVisible(true); });
  connect(this, &MainWindow::previewUpdated, timing_label_,
          [this] { timing_label_->setVisible(true); });
  for (QLabel* label : {timing_label_, backend_label_, zoom_label_}) {
    label->setContentsMargins(10, 0, 10, 0);
    label->setFrameShape(QFrame::StyledPanel);
    label->setFrameShadow(QFrame::Sunken);
  }
  warning_label_ = new QLabel;
  warning_label_->setObjectName("warningLabel");
  warning_label_->setStyleSheet("color: #a05000;");
  warning_label_->setContentsMargins(10, 0, 10, 0);
  warning_label_->setVisible(false);
  // Not permanent: a tool's hint hides it for a while instead of being cut off by it (and it
  // comes back when the hint goes).
  statusBar()->addWidget(warning_label_);
  connect(statusBar(), &QStatusBar::messageChanged, warning_label_, [this](const QString& message) {
    warning_label_->setVisible(message.isEmpty() && has_warning_);
  });
  // Permanent: a status message (a hint, "Exporting ...") must not hide the progress.
  progress_bar_ = new QProgressBar;
  progress_bar_->setObjectName("progressBar");
  progress_bar_->setRange(0, kProgressSteps);
  progress_bar_->setTextVisible(true);
  progress_bar_->setFormat(QString());
  progress_bar_->setFixedWidth(
      progress_bar_->fontMetrics().horizontalAdvance(tr("estimating: sky mask 100 %")) + 24);
  progress_bar_->setVisible(false);
  statusBar()->addPermanentWidget(progress_bar_);
  // Queued: the reports come from TBB workers; widgets are touched on the UI thread only.
  connect(this, &MainWindow::progressReported, this, &MainWindow::onProgress, Qt::QueuedConnection);
  statusBar()->addPermanentWidget(timing_label_);
  statusBar()->addPermanentWidget(backend_label_);
  statusBar()->addPermanentWidget(zoom_label_);
  statusBar()->showMessage(tr("Open a photo to start"));

  monitor_ = new EventLoopMonitor(this);
  pool_.setMaxThreadCount(2);  // a load and a render (libmr parallelises each with TBB)

  connect(layer_box_, qOverload<int>(&QComboBox::currentIndexChanged), this,
          [this] { showLayer(); });
  connect(split_slider_, &QSlider::valueChanged, this,
          [this](int v) { view_->setSplit(v / 100.0); });
  connect(fog_panel_, &FogPanel::sceneChanged, this, [this] {
    scene_modified_ = true;
    syncBlockersContext();
    updateTitle();
    requestPreview();
  });
  connect(blockers_panel_, &BlockersPanel::changed, this, [this] {
    mr::FogScene scene = fog_panel_->scene();
    scene.blockers = blockers_panel_->blockers();
    fog_panel_->setScene(scene);
    scene_modified_ = true;
    updateTitle();
    requestPreview();
  });
  connect(blockers_panel_, &BlockersPanel::rejected, this,
          [this](const QString& m) { statusBar()->showMessage(tr("Blockers: %1").arg(m), 10000); });
  // Object edits are undoable with the annotations (one Edit > Undo).
  objects_panel_->setUndoStack(editor_->undoStack());
  connect(objects_panel_, &ObjectsPanel::changed, this, [this] {
    mr::FogScene scene = fog_panel_->scene();
    scene.objects = objects_panel_->objects();
    fog_panel_->setScene(scene);
    scene_modified_ = true;
    updateTitle();
    view_->update();  // the objects' marks
    requestPreview();
  });
  connect(objects_panel_, &ObjectsPanel::rejected, this,
          [this](const QString& m) { statusBar()->showMessage(tr("Objects: %1").arg(m), 10000); });
  estimate_timer_.setSingleShot(true);
  estimate_timer_.setInterval(250);
  connect(&estimate_timer_, &QTimer::timeout, this, [this] { reestimate(true); });
  connect(editor_->undoStack(), &QUndoStack::indexChanged, this, [this] {
    updateTitle();
    // The stack also holds the objects' edits (issue 16): those do not change what the
    // estimate sees, and a drag must not re-estimate (and re-pose) the scene under the object.
    std::string annotations;
    try {
      annotations = mr::annotations_to_json(editor_->annotations());
    } catch (const mr::Error&) {
      // Annotations between two clicks need not be a valid document (a lamp without its
      // patch yet): they count as changed.
    }
    if (!annotations.empty() && annotations == stacked_annotations_) return;
    stacked_annotations_ = annotations;
    if (document_ && auto_estimate_->isChecked()) estimate_timer_.start();
  });
  connect(editor_, &AnnotationEditor::changed, this, &MainWindow::refreshAnnotationList);
  connect(editor_, &AnnotationEditor::selectionChanged, this, &MainWindow::refreshAnnotationList);
  connect(editor_, &AnnotationEditor::rejected, this,
          [this](const QString& m) { statusBar()->showMessage(m, 10000); });
  connect(editor_, &AnnotationEditor::toolChanged, this, [this] {
    for (QAction* a : tool_group_->actions())
      a->setChecked(Tool(a->data().toInt()) == editor_->tool());
  });
  recovery_path_ =
      QStandardPaths::writableLocation(QStandardPaths::AppLocalDataLocation) + "/recovery.mrstudio";
  autosave_timer_.setInterval(kDefaultAutosaveMs);
  connect(&autosave_timer_, &QTimer::timeout, this, [this] {
    if (isModified()) autosaveNow();
  });
  autosave_timer_.start();
  connect(view_, &ImageView::zoomChanged, this, [this](double z) {
    zoom_label_->setText(
        QString("%1%2 %").arg(view_->fitting() ? tr("fit ") : QString()).arg(std::lround(z * 100)));
    // Zoomed in past the preview's resolution: refine (same generation: same scene).
    if (document_ && preview_ && !rendering_ && preview_->generation == generation_) {
      const QSize need = view_->displayPixels();
      const double have = double(preview_->photo.width()) * preview_->photo.height();
      if (double(need.width()) * need.height() > 1.5 * have) startRender(mr::Quality::normal);
    }
  });
}

MainWindow::~MainWindow() {
  // The jobs post back to this window; wait for them so none outlives it.
  pool_.waitForDone();
  // The editor (a child QObject) outlives the members; its undo stack signals while it is
  // destroyed, and the handlers read members that are gone by then.
  editor_->undoStack()->disconnect(this);
  editor_->disconnect(this);
}

void MainWindow::buildMenus() {
  QMenu* file = menuBar()->addMenu(tr("&File"));
  file->addAction(tr("&Open photo..."), this, &MainWindow::onOpen, QKeySequence::Open);
  file->addAction(tr("Open &project..."), this, &MainWindow::onOpenProject);
  recent_menu_ = file->addMenu(tr("Open &recent"));
  recent_menu_->setObjectName("recentMenu");
  connect(recent_menu_, &QMenu::aboutToShow, this, &MainWindow::rebuildRecentMenu);
  file->addAction(tr("&Save project..."), this, &MainWindow::onSaveProject, QKeySequence::Save);
  file->addAction(tr("&Export image..."), this, &MainWindow::onExport, QKeySequence(tr("Ctrl+E")));
  file->addSeparator();
  file->addAction(tr("&Quit"), this, &QWidget::close, QKeySequence::Quit);
  QMenu* edit = menuBar()->addMenu(tr("&Edit"));
  QAction* undo = editor_->undoStack()->createUndoAction(this, tr("&Undo"));
  undo->setShortcut(QKeySequence::Undo);
  undo->setObjectName("undoAction");
  QAction* redo = editor_->undoStack()->createRedoAction(this, tr("&Redo"));
  redo->setShortcuts({QKeySequence(tr("Ctrl+Shift+Z")), QKeySequence(tr("Ctrl+Y"))});
  redo->setObjectName("redoAction");
  edit->addAction(undo);
  edit->addAction(redo);
  edit->addSeparator();
  edit->addAction(tr("&Delete annotation"), editor_, &AnnotationEditor::deleteSelected);
  edit->addAction(tr("S&nap polygon to the object"), this, &MainWindow::snapSelectedPolygon,
                  QKeySequence(tr("Ctrl+G")));
  edit->addAction(
      tr("Re-&estimate the scene"), this, [this] { reestimate(true); }, QKeySequence(tr("Ctrl+R")));
  QMenu* view = menuBar()->addMenu(tr("&View"));
  QAction* show_annotations =
      view->addAction(tr("Show &annotations"), view_, &ImageView::setShowAnnotations);
  show_annotations->setCheckable(true);
  show_annotations->setChecked(true);
  show_annotations->setShortcut(QKeySequence(tr("Ctrl+H")));
  view->addSeparator();
  view->addAction(tr("&Fit to window"), view_, &ImageView::fitToWindow, QKeySequence(tr("Ctrl+0")));
  view->addAction(tr("&100 %"), view_, &ImageView::zoomActualSize, QKeySequence(tr("Ctrl+1")));
  view->addAction(
      tr("Zoom &in"), this,
      [this] { view_->setZoom(view_->zoom() * 1.25, view_->rect().center()); },
      QKeySequence::ZoomIn);
  view->addAction(
      tr("Zoom &out"), this,
      [this] { view_->setZoom(view_->zoom() / 1.25, view_->rect().center()); },
      QKeySequence::ZoomOut);
}

void MainWindow::showError(const QString& title, const QString& message) {
  auto* box = new QMessageBox(QMessageBox::Critical, title, message, QMessageBox::Ok, this);
  box->setObjectName("errorBox");
  box->setAttribute(Qt::WA_DeleteOnClose);
  box->setModal(false);
  box->show();
  statusBar()->showMessage(message, 10000);
  emit errorShown(message);
}

void MainWindow::updateTitle() {
  QString title = "mr-studio";
  if (document_)
    title = QFileInfo(project_path_.isEmpty() ? document_->photo_path : project_path_).fileName() +
            (isModified() ? "*" : "") + " - " + title;
  setWindowTitle(title);
}

bool MainWindow::isModified() const {
  return document_ && (scene_modified_ || !editor_->undoStack()->isClean());
}

void MainWindow::openPhoto(const QString& path) {
  const int load = ++load_generation_;
  statusBar()->showMessage(tr("Loading %1...").arg(path));
  const mr::ColorConfig color = color_;
  std::shared_ptr<const mr::Annotations> annotations;
  if (pending_annotations_) annotations = std::make_shared<mr::Annotations>(*pending_annotations_);
  auto progress = std::make_shared<mr::CancelToken>();
  const quint64 progress_id = startProgress(Job::load, *progress);
  QtConcurrent::run(&pool_, [this, path, color, load, annotations, progress, progress_id] {
    std::shared_ptr<const Document> doc;
    QString error;
    try {
      doc = load_document(path, color, annotations.get(), progress.get());
    } catch (const mr::Error& e) {
      error = QString::fromStdString(e.what());
    } catch (const std::exception& e) {
      error = path + ": " + QString::fromStdString(e.what());
    }
    QMetaObject::invokeMethod(
        this,
        [this, doc, error, load, progress_id] {
          endProgress(Job::load, progress_id);
          if (load != load_generation_) return;  // a newer open won
          if (!doc) {
            pending_scene_.reset();
            pending_annotations_.reset();
            showError(tr("Cannot open photo"), error);
            return;
          }
          const bool from_project = bool(pending_scene_);
          if (!from_project) project_path_.clear();
          document_ = doc;
          preview_.reset();
          estimate_overlay_ = QImage();
          ++estimate_generation_;  // an estimate of the previous photo is stale
          view_->setBefore(doc->photo_display);
          view_->setAfter(QImage());
          fog_panel_->setScene(pending_scene_ ? *pending_scene_ : doc->scene);
          blockers_panel_->setBlockers(fog_panel_->scene().blockers);
          objects_panel_->setObjects(fog_panel_->scene().objects);
          // Model paths are stored relative to the project's folder once it has one.
          objects_panel_->setDocumentDir(
              project_path_.isEmpty() ? QString() : QFileInfo(project_path_).absolutePath());
          syncBlockersContext();
          pending_scene_.reset();
          pending_annotations_.reset();
          editor_->reset(doc->annotations);
          try {
            stacked_annotations_ = mr::annotations_to_json(editor_->annotations());
          } catch (const mr::Error&) {
            stacked_annotations_.clear();
          }
          scene_modified_ = false;
          addRecentFile(from_project ? project_path_ : doc->photo_path);
          updateTitle();
          // The overlay of the annotations the photo came with; the scene stays as loaded.
          if (annotation_count(doc->annotations) > 0) reestimate(false);
          QString message =
              tr("%1: %2 x %3, depth %4")
                  .arg(QFileInfo(doc->photo_path).fileName())
                  .arg(doc->photo.width())
                  .arg(doc->photo.height())
                  .arg(doc->depth_estimated ? doc->depth_source
                                            : QFileInfo(doc->depth_source).fileName());
          if (!doc->notes.isEmpty()) message += " | " + doc->notes.join("; ");
          statusBar()->showMessage(message, 15000);
          emit photoLoaded();
          requestPreview();
        },
        Qt::QueuedConnection);
  });
}

void MainWindow::syncBlockersContext() {
  const mr::FogScene scene = fog_panel_->scene();
  std::optional<double> sun_azimuth;
  if (scene.lighting.sun) {
    const mr::Vec3 d = scene.lighting.sun->direction_to_sun;
    if (std::hypot(d.x, d.z) > 1e-9) sun_azimuth = std::atan2(d.x, d.z) * 180 / M_PI;
  }
  const double hfov = document_ ? document_->camera.horizontal_fov_deg() : 60.0;
  blockers_panel_->setContext(scene.pose, hfov, sun_azimuth);
  objects_panel_->setCameraPose(scene.pose);
  object_tool_->setContext(
      document_, scene.pose,
      project_path_.isEmpty() ? QString() : QFileInfo(project_path_).absolutePath());
}

void MainWindow::requestPreview() {
  if (!document_) return;
  ++generation_;
  if (rendering_) {
    // The job running now is stale: stop it (mr::fog returns within a row's work) and start the
    // newest when it ends.
    if (render_cancel_ && cancel_stale_renders_) render_cancel_->request();
    render_pending_ = true;
    return;
  }
  startRender(mr::Quality::draft);
}

void MainWindow::startRender(mr::Quality quality) {
  PreviewRequest request;
  request.document = document_;
  request.scene = fog_panel_->scene();
  request.quality = quality;
  request.document_dir =
      project_path_.isEmpty() ? QString() : QFileInfo(project_path_).absolutePath();
  request.generation = generation_;
  const Layer shown = Layer(layer_box_->currentData().toInt());
  request.display_aovs = shown == Layer::transmittance || shown == Layer::inscatter;
  if (quality == mr::Quality::draft) {
    request.max_pixels = kDraftPixels;
  } else {
    const QSize display = view_->displayPixels();
    request.max_pixels = std::max(kDraftPixels, double(display.width()) * display.height());
    request.prepare_insert_pixels = kDraftPixels;  // the insertion tool's first drop is then quick
  }
  request.cancel = std::make_shared<mr::CancelToken>();
  render_cancel_ = request.cancel;
  const quint64 progress_id = startProgress(Job::preview, *request.cancel);
  rendering_ = true;
  const mr::ColorConfig color = color_;
  QtConcurrent::run(&pool_, [this, request, color, progress_id] {
    std::shared_ptr<PreviewResult> result;
    QString error;
    bool cancelled = false;
    try {
      result = render_preview(request, color);
    } catch (const mr::Error& e) {
      cancelled = e.code() == mr::ErrorCode::cancelled;
      if (!cancelled) error = QString::fromStdString(e.what());
    } catch (const std::exception& e) {
      error = QString::fromStdString(e.what());
    }
    const int generation = request.generation;
    QMetaObject::invokeMethod(
        this,
        [this, result, error, generation, cancelled, progress_id] {
          endProgress(Job::preview, progress_id);
          onRenderDone(result, error, generation, cancelled);
        },
        Qt::QueuedConnection);
  });
}

void MainWindow::onRenderDone(std::shared_ptr<PreviewResult> result, QString error, int generation,
                              bool cancelled) {
  rendering_ = false;
  render_cancel_.reset();
  if (cancelled) ++cancelled_renders_;
  const bool current = generation == generation_;
  if (current && !error.isEmpty()) {
    // One box at a time: a slider drag over a bad value should not stack dialogs.
    if (!findChild<QMessageBox*>("errorBox"))
      showError(tr("Cannot render the preview"), error);
    else
      emit errorShown(error);
  }
  if (current && result) {
    preview_ = result;
    showLayer();
    // The fall-back notice is a long sentence: the label says it short, its tooltip in full.
    backend_label_->setText(
        tr("backend: %1%2")
            .arg(QString::fromStdString(result->backend))
            .arg(result->backend_notice.empty() ? QString() : tr(" (fall-back)")));
    backend_label_->setToolTip(QString::fromStdString(result->backend_notice));
    const QString insert = result->matte.empty() ? QString()
                                                 : tr("objects %1 (%2/%3 tiles), ")
                                                       .arg(ms(result->insert_s))
                                                       .arg(result->insert_tiles)
                                                       .arg(result->insert_tiles_total);
    timing_label_->setText(tr("%1 %2 x %3: %4fog %5, total %6")
                               .arg(to_string(result->quality))
                               .arg(result->photo.width())
                               .arg(result->photo.height())
                               .arg(insert)
                               .arg(ms(result->render_s))
                               .arg(ms(result->total_s)));
    // Warnings are long sentences: the label shows the first clause, its tooltip all of them.
    QStringList warnings;
    for (const std::string& w : mr::scene_warnings(result->scene))
      warnings << QString::fromStdString(w);
    has_warning_ = !warnings.isEmpty();
    warning_label_->setVisible(has_warning_ && statusBar()->currentMessage().isEmpty());
    if (!warnings.isEmpty()) {
      warning_label_->setText(tr("⚠ %1").arg(warnings.first().section(':', 0, 0)));
      warning_label_->setToolTip(warnings.join("\n\n"));
    }
    emit previewUpdated(generation, int(result->quality));
  }
  if (render_pending_) {
    render_pending_ = false;
    startRender(mr::Quality::draft);
  } else if (current && result && result->quality == mr::Quality::draft) {
    startRender(mr::Quality::normal);
  }
}

// ---- progress ----------------------------------------------------------------------------

quint64 MainWindow::startProgress(Job job, mr::CancelToken& token) {
  const quint64 id = ++last_progress_id_;
  progress_[int(job)] = JobProgress{id, QString(), 0.0};
  // Runs on whichever thread made the progress (a TBB worker): only a signal, which Qt queues
  // to the UI thread (the connection in the constructor).
  token.set_progress([this, job, id](const mr::Progress& p) {
    emit progressReported(int(job), id, QString::fromUtf8(p.stage.data(), int(p.stage.size())),
                          p.fraction());
  });
  showProgress();
  return id;
}

void MainWindow::endProgress(Job job, quint64 id) {
  JobProgress& p = progress_[int(job)];
  if (p.id != id) return;  // a newer run of the job owns the bar's line
  p = JobProgress{};
  showProgress();
}

void MainWindow::onProgress(int job, quint64 id, const QString& stage, double fraction) {
  if (job < 0 || job >= int(progress_.size())) return;
  JobProgress& p = progress_[job];
  if (p.id != id) return;  // a report of a run that ended or was replaced
  p.stage = stage;
  p.fraction = std::clamp(fraction, 0.0, 1.0);
  showProgress();
}

void MainWindow::showProgress() {
  // What each job does, and the stage its verb already says (not repeated in the text).
  static const char* const verbs[] = {QT_TR_NOOP("exporting"), QT_TR_NOOP("estimating"),
                                      QT_TR_NOOP("estimating"), QT_TR_NOOP("rendering")};
  static const char* const own_stage[] = {"render", "", "", "render"};
  QStringList running;
  double fraction = 0;
  for (int job = 0; job < int(progress_.size()); ++job) {
    const JobProgress& p = progress_[job];
    // A job shows from its first report: a load with a depth file reports nothing.
    if (!p.id || p.stage.isEmpty()) continue;
    const int percent = int(std::floor(p.fraction * 100));
    const QString verb = tr(verbs[job]);
    running << (p.stage == own_stage[job] ? tr("%1 %2 %").arg(verb).arg(percent)
                                          : tr("%1: %2 %3 %").arg(verb, p.stage).arg(percent));
    if (running.size() == 1) fraction = p.fraction;
  }
  const QString text = running.isEmpty() ? QString() : running.first();
  const int value = int(std::lround(fraction * kProgressSteps));
  if (text == progress_bar_->format() && value == progress_bar_->value() &&
      progress_bar_->isVisibleTo(statusBar()) == !text.isEmpty())
    return;
  progress_bar_->setFormat(text);
  progress_bar_->setValue(value);
  progress_bar_->setToolTip(running.join("\n"));
  progress_bar_->setVisible(!text.isEmpty());
  emit progressShown(text, fraction);
}

void MainWindow::setLayer(Layer layer) {
  layer_box_->setCurrentIndex(layer_box_->findData(int(layer)));
}

void MainWindow::showLayer() {
  if (!document_) return;
  const Layer layer = Layer(layer_box_->currentData().toInt());
  if (layer == Layer::estimate && !estimate_overlay_.isNull()) {
    view_->setAfter(estimate_overlay_);
    return;
  }
  if (layer == Layer::photo) {
    view_->setAfter(document_->photo_display);
    return;
  }
  if (!preview_) {
    view_->setAfter(QImage());
    return;
  }
  switch (layer) {
    case Layer::composite:
      view_->setAfter(preview_->composite);
      break;
    case Layer::transmittance:
    case Layer::inscatter:
      view_->setAfter(preview_->displayLayer(layer, color_));
      break;
    case Layer::depth:
      view_->setAfter(preview_->depth);
      break;
    case Layer::estimate:
      if (estimate_overlay_.isNull()) {
        view_->setAfter(document_->photo_display);
        if (!estimating_) reestimate(false);
      } else {
        view_->setAfter(estimate_overlay_);
      }
      break;
    case Layer::photo:
      break;
  }
}

void MainWindow::dragEnterEvent(QDragEnterEvent* event) {
  if (event->mimeData()->hasUrls() && !event->mimeData()->urls().isEmpty() &&
      event->mimeData()->urls().first().isLocalFile())
    event->acceptProposedAction();
}

void MainWindow::dropEvent(QDropEvent* event) {
  const QString path = event->mimeData()->urls().first().toLocalFile();
  event->acceptProposedAction();
  // A model dropped on the photo stands where it was dropped (issue 16); anything else opens.
  if (ObjectTool::isModelFile(path)) {
    const QPoint in_view = view_->mapFrom(this, event->pos());
    if (!document_ || !view_->rect().contains(in_view)) {
      statusBar()->showMessage(tr("Drop a model on the photo to insert it"), 10000);
      return;
    }
    object_tool_->dropModel(path, view_->imageFromView(in_view));
    return;
  }
  openAny(path);
}

void MainWindow::openAny(const QString& path) {
  if (!maybeSave()) return;
  if (path.endsWith(".mrstudio", Qt::CaseInsensitive))
    openProject(path);
  else
    openPhoto(path);
}

void MainWindow::onOpen() {
  if (!maybeSave()) return;
  const QString path = QFileDialog::getOpenFileName(
      this, tr("Open photo"), QString(),
      tr("Images (*.jpg *.jpeg *.png *.tif *.tiff *.exr *.hdr *.pfm);;All files (*)"));
  if (!path.isEmpty()) openPhoto(path);
}

// ---- annotations -------------------------------------------------------------------------

void MainWindow::buildAnnotationDock() {
  auto* panel = new QWidget;
  panel->setObjectName("annotationPanel");
  auto* layout = new QVBoxLayout(panel);

  auto* camera = new QGroupBox(tr("Scale"));
  auto* form = new QFormLayout(camera);
  height_check_ = new QCheckBox(tr("Camera height"));
  height_check_->setToolTip(
      tr("Height of the camera above the ground (else from the known length, else 1.6 m)"));
  height_spin_ = new QDoubleSpinBox;
  height_spin_->setRange(0.1, 1000);
  height_spin_->setDecimals(2);
  height_spin_->setValue(1.6);
  height_spin_->setSuffix(tr(" m"));
  height_spin_->setKeyboardTracking(false);
  height_spin_->setEnabled(false);
  form->addRow(height_check_, height_spin_);
  length_spin_ = new QDoubleSpinBox;
  length_spin_->setRange(0.01, 10000);
  length_spin_->setDecimals(2);
  length_spin_->setValue(editor_->knownLength());
  length_spin_->setSuffix(tr(" m"));
  length_spin_->setKeyboardTracking(false);
  length_spin_->setToolTip(tr(
      "Length of the known-length line (Length tool): new ones get it, the selected one changes"));
  form->addRow(tr("Known length"), length_spin_);
  ceiling_check_ = new QCheckBox(tr("Ceiling height"));
  ceiling_check_->setObjectName("ceilingCheck");
  ceiling_check_->setToolTip(
      tr("Height of the interior box's ceiling above the floor (Floor "
         "tool first); with a ceiling point it fixes the camera height"));
  ceiling_spin_ = new QDoubleSpinBox;
  ceiling_spin_->setObjectName("ceilingSpin");
  ceiling_spin_->setRange(0.5, 100);
  ceiling_spin_->setDecimals(2);
  ceiling_spin_->setValue(2.5);
  ceiling_spin_->setSuffix(tr(" m"));
  ceiling_spin_->setKeyboardTracking(false);
  ceiling_spin_->setEnabled(false);
  form->addRow(ceiling_check_, ceiling_spin_);
  layout->addWidget(camera);

  auto* items = new QGroupBox(tr("Annotations"));
  auto* items_layout = new QVBoxLayout(items);
  annotation_list_ = new QListWidget;
  annotation_list_->setObjectName("annotationList");
  annotation_list_->setMinimumHeight(120);
  items_layout->addWidget(annotation_list_);
  auto* buttons = new QHBoxLayout;
  auto* remove = new QPushButton(tr("Delete"));
  remove->setToolTip(tr("Delete the selected annotation (Delete key in the view)"));
  auto* estimate = new QPushButton(tr("Re-estimate"));
  estimate->setObjectName("estimateButton");
  estimate->setToolTip(
      tr("Estimate the camera pose, the sun and the geometry from the annotations (Ctrl+R)"));
  auto* snap = new QPushButton(tr("Snap"));
  snap->setObjectName("snapButton");
  snap->setToolTip(tr("Snap the selected polygon to the object it outlines (GrabCut, Ctrl+G)"));
  buttons->addWidget(remove);
  buttons->addWidget(snap);
  buttons->addStretch(1);
  buttons->addWidget(estimate);
  items_layout->addLayout(buttons);
  auto_estimate_ = new QCheckBox(tr("Re-estimate after every edit"));
  auto_estimate_->setChecked(true);
  items_layout->addWidget(auto_estimate_);
  layout->addWidget(items);

  estimate_label_ = new QLabel(tr("No estimate yet."));
  estimate_label_->setObjectName("estimateLabel");
  estimate_label_->setWordWrap(true);
  estimate_label_->setTextInteractionFlags(Qt::TextSelectableByMouse);
  estimate_label_->setAlignment(Qt::AlignTop | Qt::AlignLeft);
  auto* notes = new QGroupBox(tr("Estimate"));
  auto* notes_layout = new QVBoxLayout(notes);
  notes_layout->addWidget(estimate_label_);
  layout->addWidget(notes);
  layout->addStretch(1);

  auto* scroll = new QScrollArea;
  scroll->setWidget(panel);
  scroll->setWidgetResizable(true);
  scroll->setHorizontalScrollBarPolicy(Qt::ScrollBarAlwaysOff);
  annotation_dock_ = new QDockWidget(tr("Annotations"), this);
  annotation_dock_->setObjectName("annotationDock");
  annotation_dock_->setFeatures(QDockWidget::DockWidgetMovable | QDockWidget::DockWidgetFloatable);
  annotation_dock_->setWidget(scroll);
  addDockWidget(Qt::RightDockWidgetArea, annotation_dock_);

  connect(height_check_, &QCheckBox::toggled, this, [this](bool on) {
    height_spin_->setEnabled(on);
    editor_->setCameraHeight(on ? std::optional<double>(height_spin_->value()) : std::nullopt);
  });
  connect(height_spin_, qOverload<double>(&QDoubleSpinBox::valueChanged), this, [this](double v) {
    if (height_check_->isChecked()) editor_->setCameraHeight(v);
  });
  connect(length_spin_, qOverload<double>(&QDoubleSpinBox::valueChanged), editor_,
          &AnnotationEditor::setKnownLength);
  connect(ceiling_check_, &QCheckBox::toggled, this, [this](bool on) {
    editor_->setCeilingHeight(on ? std::optional<double>(ceiling_spin_->value()) : std::nullopt);
    refreshAnnotationList();  // rejected without a box: the check goes back
  });
  connect(ceiling_spin_, qOverload<double>(&QDoubleSpinBox::valueChanged), this, [this](double v) {
    if (ceiling_check_->isChecked()) editor_->setCeilingHeight(v);
  });
  connect(remove, &QPushButton::clicked, editor_, &AnnotationEditor::deleteSelected);
  connect(snap, &QPushButton::clicked, this, &MainWindow::snapSelectedPolygon);
  auto update_snap = [this, snap] {
    const auto kind = editor_->selection().kind;
    snap->setEnabled(kind == ItemRef::Kind::plane || kind == ItemRef::Kind::lamp_patch);
  };
  connect(editor_, &AnnotationEditor::selectionChanged, snap, update_snap);
  update_snap();
  connect(estimate, &QPushButton::clicked, this, [this] { reestimate(true); });
  connect(annotation_list_, &QListWidget::currentRowChanged, this, [this](int row) {
    const auto items = annotation_items(editor_->annotations());
    if (row >= 0 && row < int(items.size())) editor_->select(items[row]);
  });
}

void MainWindow::refreshAnnotationList() {
  const mr::Annotations& a = editor_->annotations();
  const QSignalBlocker block_list(annotation_list_), block_check(height_check_),
      block_spin(height_spin_), block_ceiling_check(ceiling_check_),
      block_ceiling_spin(ceiling_spin_);
  annotation_list_->clear();
  const auto items = annotation_items(a);
  for (const ItemRef& item : items) annotation_list_->addItem(item_label(a, item));
  const auto it = std::find(items.begin(), items.end(), editor_->selection());
  annotation_list_->setCurrentRow(it == items.end() ? -1 : int(it - items.begin()));
  height_check_->setChecked(bool(a.camera_height_m));
  height_spin_->setEnabled(bool(a.camera_height_m));
  if (a.camera_height_m) height_spin_->setValue(*a.camera_height_m);
  const std::optional<double> ceiling =
      a.interior_box ? a.interior_box->ceiling_height_m : std::nullopt;
  ceiling_check_->setChecked(bool(ceiling));
  ceiling_check_->setEnabled(bool(a.interior_box));
  ceiling_spin_->setEnabled(bool(ceiling));
  if (ceiling) ceiling_spin_->setValue(*ceiling);
  if (a.known_length && editor_->selection().kind == ItemRef::Kind::known_length) {
    const QSignalBlocker block_length(length_spin_);
    length_spin_->setValue(a.known_length->length_m);
  }
}

void MainWindow::setTool(Tool tool) {
  editor_->setTool(tool);
  if (tool != Tool::navigate) annotation_dock_->raise();
  static const char* hints[] = {"",
                                "Select: click an annotation, drag its points",
                                "Horizon: click two points on it",
                                "Known length: click its two ends on the ground",
                                "Shadow: click the caster's top, its foot, then the shadow's tip",
                                "Lamp: click the lamp",
                                "Plane: click its corners, double-click or Enter to close",
                                "Lamp patch: click its corners, double-click or Enter to close",
                                "Floor: click where walls meet the floor; Enter finishes",
                                "Ceiling: click where it meets a wall"};
  if (tool != Tool::navigate) statusBar()->showMessage(tr(hints[int(tool)]), 8000);
  view_->setFocus();
}

void MainWindow::snapSelectedPolygon() {
  const ItemRef item = editor_->selection();
  if (!document_ || (item.kind != ItemRef::Kind::plane && item.kind != ItemRef::Kind::lamp_patch)) {
    statusBar()->showMessage(tr("Select a plane or a lamp patch to snap"), 5000);
    return;
  }
  const mr::Annotations before = editor_->annotations();
  const std::vector<mr::PixelPoint> rough = item.kind == ItemRef::Kind::plane
                                                ? before.planes[item.index].polygon
                                                : before.lamp_patches[item.index].polygon;
  const QImage photo = document_->photo_display;
  statusBar()->showMessage(tr("Snapping to the object..."));
  QtConcurrent::run(&pool_, [this, photo, rough, item, before] {
    std::vector<mr::PixelPoint> snapped;
    QString error;
    try {
      snapped = snap_polygon_grabcut(photo, rough);
    } catch (const std::exception& e) {
      error = QString::fromStdString(e.what());
    }
    QMetaObject::invokeMethod(
        this,
        [this, snapped, error, item, before] {
          if (!error.isEmpty()) {
            statusBar()->showMessage(error, 8000);
            emit snapFinished(false, error);
            return;
          }
          // Another edit meanwhile: the snap is of a polygon that may not be there any more.
          if (annotation_items(editor_->annotations()) != annotation_items(before)) {
            emit snapFinished(false, tr("the annotations changed meanwhile"));
            return;
          }
          mr::Annotations after = editor_->annotations();
          (item.kind == ItemRef::Kind::plane ? after.planes[item.index].polygon
                                             : after.lamp_patches[item.index].polygon) = snapped;
          const bool ok =
              editor_->edit(after, tr("Snap %1 to the object").arg(item_label(after, item)));
          statusBar()->showMessage(
              ok ? tr("Snapped: %1 points").arg(snapped.size()) : tr("Snap rejected"), 5000);
          emit snapFinished(ok, QString());
        },
        Qt::QueuedConnection);
  });
}

void MainWindow::reestimate(bool apply_scene) {
  if (!document_) return;
  estimate_timer_.stop();
  ++estimate_generation_;
  if (estimating_) {
    estimate_pending_ = true;  // the running one is stale; start the newest when it ends
    estimate_pending_apply_ = estimate_pending_apply_ || apply_scene;
    return;
  }
  estimating_ = true;
  estimate_label_->setText(tr("Estimating..."));
  const std::shared_ptr<const Document> doc = document_;
  mr::Annotations unpaired;
  const mr::Annotations annotations = complete_part(editor_->annotations(), &unpaired);
  unpaired_note_ =
      !unpaired.lamps.empty()          ? tr("The lamps are not used until a lamp patch is marked.")
      : !unpaired.lamp_patches.empty() ? tr("The lamp patches are not used until a lamp is marked.")
                                       : QString();
  const mr::ColorConfig color = color_;
  const int generation = estimate_generation_;
  auto progress = std::make_shared<mr::CancelToken>();
  const quint64 progress_id = startProgress(Job::estimate, *progress);
  QtConcurrent::run(
      &pool_, [this, doc, annotations, color, generation, apply_scene, progress, progress_id] {
        std::shared_ptr<EstimateResult> result;
        QString error;
        try {
          result = run_estimate(doc, annotations, color, progress.get());
          result->generation = generation;
        } catch (const std::exception& e) {
          error = QString::fromStdString(e.what());
        }
        QMetaObject::invokeMethod(
            this,
            [this, result, error, generation, apply_scene, progress_id] {
              endProgress(Job::estimate, progress_id);
              onEstimateDone(result, error, generation, apply_scene);
            },
            Qt::QueuedConnection);
      });
}

void MainWindow::onEstimateDone(std::shared_ptr<EstimateResult> result, QString error,
                                int generation, bool apply) {
  estimating_ = false;
  if (estimate_pending_) {
    estimate_pending_ = false;
    const bool pending_apply = estimate_pending_apply_ || apply;
    estimate_pending_apply_ = false;
    reestimate(pending_apply);
    return;
  }
  if (generation != estimate_generation_) return;  // another photo
  if (!result) {
    estimate_label_->setText(
        tr("<span style='color:#c03030'>%1</span>").arg(error.toHtmlEscaped()));
    statusBar()->showMessage(tr("Estimation failed: %1").arg(error), 10000);
    emit estimateFinished(false, error);
    return;
  }
  const mr::SceneEstimate& est = result->estimate;
  QStringList notes;
  for (const std::string& n : est.notes) notes << QString::fromStdString(n).toHtmlEscaped();
  if (!unpaired_note_.isEmpty()) notes << "<b>" + unpaired_note_.toHtmlEscaped() + "</b>";
  estimate_label_->setText(notes.join("<br>") +
                           tr("<br><i>%1 ms</i>").arg(std::lround(result->seconds * 1000)));
  estimate_overlay_ = result->overlay;
  if (apply) {
    if (result->document) document_ = result->document;
    mr::FogScene scene = fog_panel_->scene();
    scene.pose = est.scene.pose;
    if (est.sun) scene.lighting.sun = est.scene.lighting.sun;
    if (est.scene.lighting.sky_radiance)
      scene.lighting.sky_radiance = est.scene.lighting.sky_radiance;
    if (!est.scene.lighting.lamps.empty()) scene.lighting.lamps = est.scene.lighting.lamps;
    fog_panel_->setScene(scene);
    syncBlockersContext();
    requestPreview();
  }
  showLayer();
  emit estimateFinished(true, notes.join("\n"));
}

// ---- unsaved changes, autosave, recent files -----------------------------------------------

QMessageBox::StandardButton MainWindow::ask(QMessageBox::Icon icon, const QString& title,
                                            const QString& text,
                                            QMessageBox::StandardButtons buttons) {
  if (prompt_answer_ != QMessageBox::NoButton) return prompt_answer_;
  QMessageBox box(icon, title, text, buttons, this);
  box.setObjectName("promptBox");
  return QMessageBox::StandardButton(box.exec());
}

bool MainWindow::maybeSave() {
  if (!isModified()) return true;
  const auto answer = ask(QMessageBox::Warning, tr("Unsaved changes"),
                          tr("%1 has unsaved changes. Save them to the project?")
                              .arg(QFileInfo(document_->photo_path).fileName()),
                          QMessageBox::Save | QMessageBox::Discard | QMessageBox::Cancel);
  if (answer == QMessageBox::Cancel) return false;
  if (answer == QMessageBox::Save) {
    QString path = project_path_;
    if (path.isEmpty()) {
      path = QFileDialog::getSaveFileName(this, tr("Save project"), QString(),
                                          tr("mr-studio projects (*.mrstudio)"));
      if (path.isEmpty()) return false;
      if (!path.endsWith(".mrstudio")) path += ".mrstudio";
    }
    if (!saveProject(path)) return false;
  }
  QFile::remove(recovery_path_);  // saved or discarded on purpose
  scene_modified_ = false;
  editor_->undoStack()->setClean();
  return true;
}

void MainWindow::closeEvent(QCloseEvent* event) {
  if (!maybeSave()) {
    event->ignore();
    return;
  }
  QFile::remove(recovery_path_);
  event->accept();
}

void MainWindow::setAutosave(const QString& recovery_path, int interval_ms) {
  recovery_path_ = recovery_path;
  autosave_timer_.setInterval(interval_ms);
  autosave_timer_.start();
}

bool MainWindow::autosaveNow() {
  if (!document_) return false;
  try {
    QDir().mkpath(QFileInfo(recovery_path_).absolutePath());
    writeFileAtomically(recovery_path_, projectJson(recovery_path_));
  } catch (const mr::Error& e) {
    statusBar()->showMessage(tr("Autosave failed: %1").arg(QString::fromStdString(e.what())), 8000);
    return false;
  }
  return true;
}

bool MainWindow::offerRecovery() {
  if (!QFileInfo::exists(recovery_path_)) return false;
  const auto answer = ask(
      QMessageBox::Question, tr("Recover unsaved work"),
      tr("mr-studio did not close properly. Reopen the work autosaved at %1?")
          .arg(QLocale().toString(QFileInfo(recovery_path_).lastModified(), QLocale::ShortFormat)),
      QMessageBox::Yes | QMessageBox::No);
  if (answer != QMessageBox::Yes) {
    QFile::remove(recovery_path_);
    return false;
  }
  openProject(recovery_path_);
  return true;
}

QStringList MainWindow::recentFiles() const {
  return QSettings().value("recentFiles").toStringList();
}

void MainWindow::addRecentFile(const QString& path) {
  if (path.isEmpty() || path == recovery_path_) return;
  QStringList files = recentFiles();
  const QString absolute = QFileInfo(path).absoluteFilePath();
  files.removeAll(absolute);
  files.prepend(absolute);
  while (files.size() > kRecentFiles) files.removeLast();
  QSettings().setValue("recentFiles", files);
}

void MainWindow::rebuildRecentMenu() {
  recent_menu_->clear();
  const QStringList files = recentFiles();
  for (const QString& f : files)
    recent_menu_->addAction(QFileInfo(f).fileName(), this, [this, f] { openAny(f); })
        ->setToolTip(f);
  if (files.isEmpty()) recent_menu_->addAction(tr("(none)"))->setEnabled(false);
}

// ---- project files ---------------------------------------------------------------------------

QByteArray MainWindow::projectJson(const QString& path) const {
  const std::string scene_text = mr::scene_to_json(fog_panel_->scene());
  QJsonObject project;
  project["format"] = kProjectFormat;
  project["version"] = 1;
  project["photo"] = QFileInfo(path).absoluteDir().relativeFilePath(document_->photo_path);
  project["scene"] = QJsonDocument::fromJson(QByteArray::fromStdString(scene_text)).object();
  // The annotations document as libmr writes it; lamps still waiting for their lamp patch (the
  // document wants both or neither) are kept beside it so that no click is lost.
  mr::Annotations unpaired;
  const mr::Annotations a = complete_part(editor_->annotations(), &unpaired);
  if (annotation_count(a) > 0) {
    const std::string annotations_text = mr::annotations_to_json(a);
    project["annotations"] =
        QJsonDocument::fromJson(QByteArray::fromStdString(annotations_text)).object();
  }
  if (!unpaired.lamps.empty() || !unpaired.lamp_patches.empty()) {
    // Written as a document of lamps with one stand-in patch, so libmr parses it on reading.
    mr::Annotations pending = unpaired;
    if (pending.lamps.empty())
      pending.lamps.push_back({pending.lamp_patches[0].polygon[0], 0, std::nullopt});
    if (pending.lamp_patches.empty())
      pending.lamp_patches.push_back({{pending.lamps[0].pixel,
                                       {pending.lamps[0].pixel[0] + 1, pending.lamps[0].pixel[1]},
                                       {pending.lamps[0].pixel[0], pending.lamps[0].pixel[1] + 1}},
                                      std::nullopt});
    QJsonObject o =
        QJsonDocument::fromJson(QByteArray::fromStdString(mr::annotations_to_json(pending)))
            .object();
    QJsonObject unfinished;
    if (!unpaired.lamps.empty()) unfinished["lamps"] = o["lamps"];
    if (!unpaired.lamp_patches.empty()) unfinished["lamp_patches"] = o["lamp_patches"];
    project["unfinished_annotations"] = unfinished;
  }
  return QJsonDocument(project).toJson();
}

void MainWindow::writeFileAtomically(const QString& path, const QByteArray& data) const {
  QFile file(path + ".tmp");
  if (!file.open(QIODevice::WriteOnly | QIODevice::Truncate) || file.write(data) < 0 ||
      !file.flush()) {
    file.remove();
    throw mr::Error(mr::ErrorCode::io,
                    path.toStdString() + ": cannot write: " + file.errorString().toStdString());
  }
  file.close();
  QFile::remove(path);
  if (!QFile::rename(path + ".tmp", path)) {
    QFile::remove(path + ".tmp");
    throw mr::Error(mr::ErrorCode::io, path.toStdString() + ": cannot write");
  }
}

bool MainWindow::saveProject(const QString& path) {
  if (!document_) {
    showError(tr("Cannot save the project"), tr("Open a photo first."));
    return false;
  }
  try {
    writeFileAtomically(path, projectJson(path));
  } catch (const mr::Error& e) {
    showError(tr("Cannot save the project"), QString::fromStdString(e.what()));
    return false;
  }
  project_path_ = path;
  scene_modified_ = false;
  editor_->undoStack()->setClean();
  QFile::remove(recovery_path_);
  addRecentFile(path);
  updateTitle();
  statusBar()->showMessage(tr("Saved %1").arg(path), 5000);
  return true;
}

void MainWindow::openProject(const QString& path) {
  try {
    QFile file(path);
    if (!file.open(QIODevice::ReadOnly))
      throw mr::Error(mr::ErrorCode::io,
                      path.toStdString() + ": cannot read: " + file.errorString().toStdString());
    QJsonParseError parse;
    const QJsonDocument json = QJsonDocument::fromJson(file.readAll(), &parse);
    if (json.isNull())
      throw mr::Error(mr::ErrorCode::invalid_argument,
                      path.toStdString() + ": " + parse.errorString().toStdString());
    const QJsonObject project = json.object();
    if (project["format"].toString() != kProjectFormat || project["version"].toInt() != 1)
      throw mr::Error(mr::ErrorCode::invalid_argument,
                      path.toStdString() + ": not an mr-studio project (format/version)");
    if (!project["photo"].isString() || !project["scene"].isObject())
      throw mr::Error(mr::ErrorCode::invalid_argument,
                      path.toStdString() + ": expected \"photo\" and \"scene\"");
    const mr::FogScene scene =
        mr::scene_from_json(QJsonDocument(project["scene"].toObject()).toJson().toStdString(),
                            path.toStdString() + " (scene)");
    mr::Annotations annotations;
    if (project.contains("annotations")) {
      if (!project["annotations"].isObject())
        throw mr::Error(mr::ErrorCode::invalid_argument,
                        path.toStdString() + ": \"annotations\" must be an object");
      annotations = mr::annotations_from_json(
          QJsonDocument(project["annotations"].toObject()).toJson().toStdString(),
          path.toStdString() + " (annotations)");
    }
    if (project.contains("unfinished_annotations")) {
      // Lamps (or lamp patches) without their counterpart: parsed through libmr with a stand-in.
      const QJsonObject u = project["unfinished_annotations"].toObject();
      QJsonObject doc{{"format", mr::kAnnotationsFormatName},
                      {"version", mr::kAnnotationsFormatVersion}};
      const bool has_lamps = u.contains("lamps"), has_patches = u.contains("lamp_patches");
      doc["lamps"] = has_lamps ? u["lamps"] : QJsonArray{QJsonObject{{"pixel", QJsonArray{0, 0}}}};
      doc["lamp_patches"] =
          has_patches
              ? u["lamp_patches"]
              : QJsonArray{QJsonObject{
                    {"polygon", QJsonArray{QJsonArray{0, 0}, QJsonArray{1, 0}, QJsonArray{0, 1}}}}};
      const mr::Annotations unfinished =
          mr::annotations_from_json(QJsonDocument(doc).toJson().toStdString(),
                                    path.toStdString() + " (unfinished_annotations)");
      if (has_lamps)
        annotations.lamps.insert(annotations.lamps.end(), unfinished.lamps.begin(),
                                 unfinished.lamps.end());
      if (has_patches)
        annotations.lamp_patches.insert(annotations.lamp_patches.end(),
                                        unfinished.lamp_patches.begin(),
                                        unfinished.lamp_patches.end());
    }
    pending_scene_ = std::make_unique<mr::FogScene>(scene);
    pending_annotations_ = std::make_unique<mr::Annotations>(annotations);
    // A recovered project keeps no path: saving asks where (it is not the user's file).
    project_path_ = path == recovery_path_ ? QString() : path;
    openPhoto(QFileInfo(path).absoluteDir().absoluteFilePath(project["photo"].toString()));
  } catch (const mr::Error& e) {
    showError(tr("Cannot open the project"), QString::fromStdString(e.what()));
  }
}

void MainWindow::onOpenProject() {
  if (!maybeSave()) return;
  const QString path = QFileDialog::getOpenFileName(this, tr("Open project"), QString(),
                                                    tr("mr-studio projects (*.mrstudio)"));
  if (!path.isEmpty()) openProject(path);
}

void MainWindow::onSaveProject() {
  QString path = QFileDialog::getSaveFileName(this, tr("Save project"), project_path_,
                                              tr("mr-studio projects (*.mrstudio)"));
  if (path.isEmpty()) return;
  if (!path.endsWith(".mrstudio")) path += ".mrstudio";
  saveProject(path);
}

// ---- export ------------------------------------------------------------------------------

void MainWindow::cancelExport() {
  if (export_cancel_) export_cancel_->request();
}

bool MainWindow::exportImage(const QString& path, const ExportSettings& settings,
                             bool show_progress) {
  if (!document_) {
    showError(tr("Cannot export"), tr("Open a photo first."));
    return false;
  }
  if (!mr::is_writable_image_extension(path.toStdString())) {
    showError(tr("Cannot export"),
              tr("%1: not a writable image format (use .jpg, .png, .tif or .exr)").arg(path));
    return false;
  }
  const bool exr = path.endsWith(".exr", Qt::CaseInsensitive);
  if (settings.aovs && !exr) {
    showError(tr("Cannot export"), tr("%1: AOV layers need an OpenEXR file (.exr)").arg(path));
    return false;
  }
  if (exporting_) {
    statusBar()->showMessage(tr("An export is running already"), 5000);
    return false;
  }
  exporting_ = true;
  statusBar()->showMessage(tr("Exporting %1...").arg(path));
  const std::shared_ptr<const Document> doc = document_;
  mr::FogScene scene = fog_panel_->scene();
  scene.render.quality = mr::Quality::normal;
  const mr::ColorConfig color = color_;
  // The render and the write run on the worker; the write goes through mr::write_image /
  // write_exr_layers, which write a temporary file and rename it (atomic). A cancel during the
  // render stops mr::fog (within a row); one before the write starts writes nothing.
  // The token also carries the export's progress: mr::fog's stages, then "writing" (reported
  // here: the writers have no progress of their own).
  std::shared_ptr<mr::CancelToken> cancelled = std::make_shared<mr::CancelToken>();
  export_cancel_ = cancelled;
  const quint64 progress_id = startProgress(Job::export_image, *cancelled);
  QFuture<QString> job =
      QtConcurrent::run(&pool_, [doc, scene, color, path, settings, cancelled]() -> QString {
        try {
          mr::ScatteringLayers aovs;
          const mr::FogLayers layers = mr::fog(doc->photo, doc->distance_m, doc->sky_alpha,
                                               doc->camera, scene, &aovs, cancelled.get());
          if (cancelled->requested()) return QStringLiteral("cancelled");
          mr::report_progress(cancelled.get(), kWritingStage, 0, 1);
          if (settings.aovs) {
            const mr::Image composite_rgb = layers.composite.select_channels(std::array{0, 1, 2});
            const mr::ExrLayer exr_layers[] = {{"", &composite_rgb},
                                               {"transmittance", &layers.transmittance},
                                               {"inscatter", &layers.inscatter},
                                               {"depth", &doc->distance_m, true}};
            mr::write_exr_layers(path.toStdString(), exr_layers, doc->photo.metadata(),
                                 settings.pixel_type == mr::PixelType::float32
                                     ? mr::PixelType::float32
                                     : mr::PixelType::half);
          } else {
            mr::Image out = layers.composite;
            out.metadata() = doc->photo.metadata();
            mr::WriteOptions write;
            write.color = &color;
            write.pixel_type = settings.pixel_type;
            write.colorspace = settings.colorspace;
            mr::write_image(path.toStdString(), out, write);
          }
          mr::report_progress(cancelled.get(), kWritingStage, 1, 1);
          return {};
        } catch (const mr::Error& e) {
          if (e.code() == mr::ErrorCode::cancelled) return QStringLiteral("cancelled");
          return QString::fromStdString(e.what());
        } catch (const std::exception& e) {
          return QString::fromStdString(e.what());
        }
      });
  QProgressDialog* progress = nullptr;
  if (show_progress) {
    progress = new QProgressDialog(tr("Rendering %1...").arg(QFileInfo(path).fileName()),
                                   tr("Cancel"), 0, kProgressSteps, this);
    progress->setObjectName("exportProgress");
    progress->setWindowModality(Qt::WindowModal);
    progress->setMinimumDuration(0);
    // Each stage runs from 0 to 100 %: the end of the render is not the end of the export.
    progress->setAutoReset(false);
    progress->setAutoClose(false);
    progress->setValue(0);
    connect(progress, &QProgressDialog::canceled, this, &MainWindow::cancelExport);
    // The export's own progress, as the status bar gets it (on the UI thread, queued).
    connect(
        this, &MainWindow::progressReported, progress,
        [progress, path, progress_id](int job, quint64 id, const QString& stage, double fraction) {
          if (job != int(Job::export_image) || id != progress_id) return;
          const QString file = QFileInfo(path).fileName();
          progress->setLabelText(stage == kWritingStage ? tr("Writing %1...").arg(file)
                                 : stage == "render"    ? tr("Rendering %1...").arg(file)
                                                     : tr("Rendering %1: %2...").arg(file, stage));
          progress->setValue(int(std::lround(fraction * kProgressSteps)));
        },
        Qt::QueuedConnection);
  }
  QFutureWatcher<QString> watcher;
  QEventLoop loop;
  connect(&watcher, &QFutureWatcher<QString>::finished, &loop, &QEventLoop::quit);
  watcher.setFuture(job);
  if (!job.isFinished()) loop.exec();
  export_cancel_.reset();
  endProgress(Job::export_image, progress_id);
  delete progress;
  const QString error = job.result();
  exporting_ = false;
  if (error == "cancelled") {
    statusBar()->showMessage(tr("Export cancelled: nothing written"), 8000);
    return false;
  }
  if (!error.isEmpty()) {
    showError(tr("Export failed"), error);
    return false;
  }
  statusBar()->showMessage(tr("Exported %1").arg(path), 8000);
  return true;
}

void MainWindow::onExport() {
  if (!document_) {
    showError(tr("Cannot export"), tr("Open a photo first."));
    return;
  }
  ExportDialog dialog(color_, QFileInfo(document_->photo_path).completeBaseName() + "_fog", this,
                      QFileInfo(document_->photo_path).absolutePath());
  if (dialog.exec() != QDialog::Accepted) return;
  exportImage(dialog.path(), dialog.settings(), true);
}

}  // namespace mrstudio
