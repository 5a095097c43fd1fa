#include "main_window.h"

#include <QAction>
#include <QApplication>
#include <QComboBox>
#include <QDir>
#include <QDockWidget>
#include <QDragEnterEvent>
#include <QDropEvent>
#include <QEventLoop>
#include <QFile>
#include <QFileDialog>
#include <QFileInfo>
#include <QJsonDocument>
#include <QJsonObject>
#include <QLabel>
#include <QMenuBar>
#include <QMessageBox>
#include <QMimeData>
#include <QScrollArea>
#include <QSlider>
#include <QStatusBar>
#include <QToolBar>
#include <QtConcurrent/QtConcurrentRun>
#include <cmath>

#include "fog_panel.h"
#include "image_view.h"

namespace mrstudio {

namespace {

// The draft pass: on the 2-core machine mr::fog at draft quality takes ~25 ms on 0.25 MP and the
// whole pass shows ~42 ms after an edit (bench/bench_studio.cpp; 0.5 MP took ~99 ms).
constexpr double kDraftPixels = 0.25e6;
constexpr const char* kProjectFormat = "mr-studio-project";

QString ms(double seconds) { return QString::number(seconds * 1000.0, 'f', 0) + " ms"; }

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

  fog_panel_ = new FogPanel;
  auto* scroll = new QScrollArea;
  scroll->setWidget(fog_panel_);
  scroll->setWidgetResizable(true);
  scroll->setHorizontalScrollBarPolicy(Qt::ScrollBarAlwaysOff);
  scroll->setMinimumWidth(fog_panel_->sizeHint().width() + 24);
  auto* dock = new QDockWidget(tr("Fog and light"), this);
  dock->setObjectName("fogDock");
  dock->setFeatures(QDockWidget::DockWidgetMovable | QDockWidget::DockWidgetFloatable);
  dock->setWidget(scroll);
  addDockWidget(Qt::RightDockWidgetArea, dock);

  layer_box_ = new QComboBox;
  layer_box_->setObjectName("layerBox");
  layer_box_->addItem(tr("Composite"), int(Layer::composite));
  layer_box_->addItem(tr("Photo"), int(Layer::photo));
  layer_box_->addItem(tr("Transmittance"), int(Layer::transmittance));
  layer_box_->addItem(tr("In-scatter"), int(Layer::inscatter));
  layer_box_->addItem(tr("Depth"), int(Layer::depth));
  split_slider_ = new QSlider(Qt::Horizontal);
  split_slider_->setObjectName("splitSlider");
  split_slider_->setRange(0, 100);
  split_slider_->setValue(50);
  split_slider_->setFixedWidth(160);
  split_slider_->setToolTip(tr("Before / after: left of the line the photo, right of it the layer"));

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

  backend_label_ = new QLabel(tr("backend: -"));
  timing_label_ = new QLabel;
  zoom_label_ = new QLabel;
  for (QLabel* label : {timing_label_, backend_label_, zoom_label_}) {
    label->setContentsMargins(10, 0, 10, 0);
    label->setFrameShape(QFrame::StyledPanel);
    label->setFrameShadow(QFrame::Sunken);
  }
  statusBar()->addPermanentWidget(timing_label_);
  statusBar()->addPermanentWidget(backend_label_);
  statusBar()->addPermanentWidget(zoom_label_);
  statusBar()->showMessage(tr("Open a photo to start"));

  monitor_ = new EventLoopMonitor(this);
  pool_.setMaxThreadCount(2);  // a load and a render (libmr parallelises each with TBB)

  connect(layer_box_, qOverload<int>(&QComboBox::currentIndexChanged), this, [this] { showLayer(); });
  connect(split_slider_, &QSlider::valueChanged, this, [this](int v) { view_->setSplit(v / 100.0); });
  connect(fog_panel_, &FogPanel::sceneChanged, this, &MainWindow::requestPreview);
  connect(view_, &ImageView::zoomChanged, this, [this](double z) {
    zoom_label_->setText(QString("%1%2 %").arg(view_->fitting() ? tr("fit ") : QString()).arg(std::lround(z * 100)));
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
}

void MainWindow::buildMenus() {
  QMenu* file = menuBar()->addMenu(tr("&File"));
  file->addAction(tr("&Open photo..."), this, &MainWindow::onOpen, QKeySequence::Open);
  file->addAction(tr("Open &project..."), this, &MainWindow::onOpenProject);
  file->addAction(tr("&Save project..."), this, &MainWindow::onSaveProject, QKeySequence::Save);
  file->addAction(tr("&Export image..."), this, &MainWindow::onExport, QKeySequence(tr("Ctrl+E")));
  file->addSeparator();
  file->addAction(tr("&Quit"), this, &QWidget::close, QKeySequence::Quit);
  QMenu* view = menuBar()->addMenu(tr("&View"));
  view->addAction(tr("&Fit to window"), view_, &ImageView::fitToWindow, QKeySequence(tr("Ctrl+0")));
  view->addAction(tr("&100 %"), view_, &ImageView::zoomActualSize, QKeySequence(tr("Ctrl+1")));
  view->addAction(tr("Zoom &in"), this, [this] { view_->setZoom(view_->zoom() * 1.25, view_->rect().center()); },
                  QKeySequence::ZoomIn);
  view->addAction(tr("Zoom &out"), this, [this] { view_->setZoom(view_->zoom() / 1.25, view_->rect().center()); },
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
  if (document_) title = QFileInfo(document_->photo_path).fileName() + " - " + title;
  setWindowTitle(title);
}

void MainWindow::openPhoto(const QString& path) {
  const int load = ++load_generation_;
  statusBar()->showMessage(tr("Loading %1...").arg(path));
  const mr::ColorConfig color = color_;
  QtConcurrent::run(&pool_, [this, path, color, load] {
    std::shared_ptr<const Document> doc;
    QString error;
    try {
      doc = load_document(path, color);
    } catch (const mr::Error& e) {
      error = QString::fromStdString(e.what());
    } catch (const std::exception& e) {
      error = path + ": " + QString::fromStdString(e.what());
    }
    QMetaObject::invokeMethod(this, [this, doc, error, load] {
      if (load != load_generation_) return;  // a newer open won
      if (!doc) {
        pending_scene_.reset();
        showError(tr("Cannot open photo"), error);
        return;
      }
      document_ = doc;
      preview_.reset();
      view_->setBefore(doc->photo_display);
      view_->setAfter(QImage());
      fog_panel_->setScene(pending_scene_ ? *pending_scene_ : doc->scene);
      pending_scene_.reset();
      updateTitle();
      QString message = tr("%1: %2 x %3, depth %4")
                            .arg(QFileInfo(doc->photo_path).fileName())
                            .arg(doc->photo.width())
                            .arg(doc->photo.height())
                            .arg(doc->depth_estimated ? doc->depth_source
                                                      : QFileInfo(doc->depth_source).fileName());
      if (!doc->notes.isEmpty()) message += " | " + doc->notes.join("; ");
      statusBar()->showMessage(message, 15000);
      emit photoLoaded();
      requestPreview();
    }, Qt::QueuedConnection);
  });
}

void MainWindow::requestPreview() {
  if (!document_) return;
  ++generation_;
  if (rendering_) {
    render_pending_ = true;  // the job running now is stale; start the newest when it ends
    return;
  }
  startRender(mr::Quality::draft);
}

void MainWindow::startRender(mr::Quality quality) {
  PreviewRequest request;
  request.document = document_;
  request.scene = fog_panel_->scene();
  request.quality = quality;
  request.generation = generation_;
  if (quality == mr::Quality::draft) {
    request.max_pixels = kDraftPixels;
  } else {
    const QSize display = view_->displayPixels();
    request.max_pixels = std::max(kDraftPixels, double(display.width()) * display.height());
  }
  rendering_ = true;
  const mr::ColorConfig color = color_;
  QtConcurrent::run(&pool_, [this, request, color] {
    std::shared_ptr<PreviewResult> result;
    QString error;
    try {
      result = render_preview(request, color);
    } catch (const mr::Error& e) {
      error = QString::fromStdString(e.what());
    } catch (const std::exception& e) {
      error = QString::fromStdString(e.what());
    }
    const int generation = request.generation;
    QMetaObject::invokeMethod(this, [this, result, error, generation] { onRenderDone(result, error, generation); },
                              Qt::QueuedConnection);
  });
}

void MainWindow::onRenderDone(std::shared_ptr<PreviewResult> result, QString error, int generation) {
  rendering_ = false;
  const bool current = generation == generation_;
  if (current && !error.isEmpty()) {
    // One box at a time: a slider drag over a bad value should not stack dialogs.
    if (!findChild<QMessageBox*>("errorBox")) showError(tr("Cannot render the preview"), error);
    else emit errorShown(error);
  }
  if (current && result) {
    preview_ = result;
    showLayer();
    // The fall-back notice is a long sentence: the label says it short, its tooltip in full.
    backend_label_->setText(tr("backend: %1%2")
                                .arg(QString::fromStdString(result->backend))
                                .arg(result->backend_notice.empty() ? QString() : tr(" (fall-back)")));
    backend_label_->setToolTip(QString::fromStdString(result->backend_notice));
    timing_label_->setText(tr("%1 %2 x %3: fog %4, total %5")
                               .arg(to_string(result->quality))
                               .arg(result->photo.width())
                               .arg(result->photo.height())
                               .arg(ms(result->render_s))
                               .arg(ms(result->total_s)));
    for (const std::string& w : mr::scene_warnings(result->scene))
      statusBar()->showMessage(tr("Warning: %1").arg(QString::fromStdString(w)), 8000);
    emit previewUpdated(generation, int(result->quality));
  }
  if (render_pending_) {
    render_pending_ = false;
    startRender(mr::Quality::draft);
  } else if (current && result && result->quality == mr::Quality::draft) {
    startRender(mr::Quality::normal);
  }
}

void MainWindow::setLayer(Layer layer) {
  layer_box_->setCurrentIndex(layer_box_->findData(int(layer)));
}

void MainWindow::showLayer() {
  if (!document_) return;
  const Layer layer = Layer(layer_box_->currentData().toInt());
  if (layer == Layer::photo) {
    view_->setAfter(document_->photo_display);
    return;
  }
  if (!preview_) {
    view_->setAfter(QImage());
    return;
  }
  switch (layer) {
    case Layer::composite: view_->setAfter(preview_->composite); break;
    case Layer::transmittance: view_->setAfter(preview_->transmittance); break;
    case Layer::inscatter: view_->setAfter(preview_->inscatter); break;
    case Layer::depth: view_->setAfter(preview_->depth); break;
    case Layer::photo: break;
  }
}

void MainWindow::dragEnterEvent(QDragEnterEvent* event) {
  if (event->mimeData()->hasUrls() && !event->mimeData()->urls().isEmpty() &&
      event->mimeData()->urls().first().isLocalFile())
    event->acceptProposedAction();
}

void MainWindow::dropEvent(QDropEvent* event) {
  const QString path = event->mimeData()->urls().first().toLocalFile();
  if (path.endsWith(".mrstudio", Qt::CaseInsensitive)) openProject(path);
  else openPhoto(path);
  event->acceptProposedAction();
}

void MainWindow::onOpen() {
  const QString path = QFileDialog::getOpenFileName(
      this, tr("Open photo"), QString(),
      tr("Images (*.jpg *.jpeg *.png *.tif *.tiff *.exr *.hdr *.pfm);;All files (*)"));
  if (!path.isEmpty()) openPhoto(path);
}

bool MainWindow::saveProject(const QString& path) {
  if (!document_) {
    showError(tr("Cannot save the project"), tr("Open a photo first."));
    return false;
  }
  try {
    const std::string scene_text = mr::scene_to_json(fog_panel_->scene());
    QJsonObject project;
    project["format"] = kProjectFormat;
    project["version"] = 1;
    project["photo"] = QFileInfo(path).absoluteDir().relativeFilePath(document_->photo_path);
    project["scene"] = QJsonDocument::fromJson(QByteArray::fromStdString(scene_text)).object();
    QFile file(path + ".tmp");
    if (!file.open(QIODevice::WriteOnly | QIODevice::Truncate) ||
        file.write(QJsonDocument(project).toJson()) < 0 || !file.flush()) {
      file.remove();
      throw mr::Error(mr::ErrorCode::io, path.toStdString() + ": cannot write: " + file.errorString().toStdString());
    }
    file.close();
    QFile::remove(path);
    if (!QFile::rename(path + ".tmp", path)) {
      QFile::remove(path + ".tmp");
      throw mr::Error(mr::ErrorCode::io, path.toStdString() + ": cannot write");
    }
  } catch (const mr::Error& e) {
    showError(tr("Cannot save the project"), QString::fromStdString(e.what()));
    return false;
  }
  project_path_ = path;
  statusBar()->showMessage(tr("Saved %1").arg(path), 5000);
  return true;
}

void MainWindow::openProject(const QString& path) {
  try {
    QFile file(path);
    if (!file.open(QIODevice::ReadOnly))
      throw mr::Error(mr::ErrorCode::io, path.toStdString() + ": cannot read: " + file.errorString().toStdString());
    QJsonParseError parse;
    const QJsonDocument json = QJsonDocument::fromJson(file.readAll(), &parse);
    if (json.isNull())
      throw mr::Error(mr::ErrorCode::invalid_argument, path.toStdString() + ": " + parse.errorString().toStdString());
    const QJsonObject project = json.object();
    if (project["format"].toString() != kProjectFormat || project["version"].toInt() != 1)
      throw mr::Error(mr::ErrorCode::invalid_argument,
                      path.toStdString() + ": not an mr-studio project (format/version)");
    if (!project["photo"].isString() || !project["scene"].isObject())
      throw mr::Error(mr::ErrorCode::invalid_argument, path.toStdString() + ": expected \"photo\" and \"scene\"");
    const mr::FogScene scene = mr::scene_from_json(
        QJsonDocument(project["scene"].toObject()).toJson().toStdString(), path.toStdString() + " (scene)");
    pending_scene_ = std::make_unique<mr::FogScene>(scene);
    project_path_ = path;
    openPhoto(QFileInfo(path).absoluteDir().absoluteFilePath(project["photo"].toString()));
  } catch (const mr::Error& e) {
    showError(tr("Cannot open the project"), QString::fromStdString(e.what()));
  }
}

void MainWindow::onOpenProject() {
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

bool MainWindow::exportImage(const QString& path) {
  if (!document_) {
    showError(tr("Cannot export"), tr("Open a photo first."));
    return false;
  }
  if (!mr::is_writable_image_extension(path.toStdString())) {
    showError(tr("Cannot export"), tr("%1: not a writable image format (use .jpg, .png, .tif or .exr)").arg(path));
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
  QFuture<QString> job = QtConcurrent::run(&pool_, [doc, scene, color, path]() -> QString {
    try {
      const mr::FogLayers layers = mr::fog(doc->photo, doc->distance_m, doc->camera, scene);
      mr::Image out = layers.composite;
      out.metadata() = doc->photo.metadata();
      mr::WriteOptions write;
      write.color = &color;
      mr::write_image(path.toStdString(), out, write);
      return {};
    } catch (const std::exception& e) {
      return QString::fromStdString(e.what());
    }
  });
  QFutureWatcher<QString> watcher;
  QEventLoop loop;
  connect(&watcher, &QFutureWatcher<QString>::finished, &loop, &QEventLoop::quit);
  watcher.setFuture(job);
  if (!job.isFinished()) loop.exec();
  const QString error = job.result();
  exporting_ = false;
  if (!error.isEmpty()) {
    showError(tr("Export failed"), error);
    return false;
  }
  statusBar()->showMessage(tr("Exported %1").arg(path), 8000);
  return true;
}

void MainWindow::onExport() {
  const QString path = QFileDialog::getSaveFileName(this, tr("Export image"), QString(),
                                                    tr("Images (*.jpg *.png *.tif *.exr)"));
  if (!path.isEmpty()) exportImage(path);
}

}  // namespace mrstudio
