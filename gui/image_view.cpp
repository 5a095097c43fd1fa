#include "image_view.h"

#include <QKeyEvent>
#include <QMouseEvent>
#include <QPainter>
#include <QWheelEvent>
#include <algorithm>
#include <cmath>

#include "annotation_editor.h"
#include "object_tool.h"

namespace mrstudio {

ImageView::ImageView(QWidget* parent) : QWidget(parent) {
  setFocusPolicy(Qt::StrongFocus);
  setMinimumSize(320, 240);
  setAutoFillBackground(true);
  QPalette p = palette();
  p.setColor(QPalette::Window, QColor(40, 40, 44));
  setPalette(p);
  setMouseTracking(true);
}

void ImageView::setEditor(AnnotationEditor* editor) {
  editor_ = editor;
  auto repaint = [this] { update(); };
  for (auto signal : {&AnnotationEditor::changed, &AnnotationEditor::pendingChanged,
                      &AnnotationEditor::selectionChanged})
    connect(editor_, signal, this, repaint);
  connect(editor_, &AnnotationEditor::toolChanged, this, [this] {
    setCursor(editor_->tool() == Tool::navigate ? Qt::OpenHandCursor
              : editor_->tool() == Tool::select ? Qt::ArrowCursor
                                                : Qt::CrossCursor);
  });
  update();
}

void ImageView::setShowAnnotations(bool show) {
  show_annotations_ = show;
  update();
}

QPointF ImageView::viewFromImage(const mr::PixelPoint& p) const {
  return offset_ + QPointF(p[0] + 0.5, p[1] + 0.5) * zoom_;
}

mr::PixelPoint ImageView::imageFromView(const QPointF& p) const {
  const QPointF q = (p - offset_) / zoom_;
  return {q.x() - 0.5, q.y() - 0.5};
}

void ImageView::setBefore(const QImage& image) {
  const bool new_size = image.size() != before_.size();
  before_ = image;
  if (new_size) fitToWindow();
  update();
}

void ImageView::setAfter(const QImage& image) {
  after_ = image;
  update();
}

void ImageView::clear() {
  before_ = after_ = QImage();
  update();
}

void ImageView::setSplit(double fraction) {
  split_ = std::clamp(fraction, 0.0, 1.0);
  update();
}

QRectF ImageView::imageRect() const {
  return QRectF(offset_, QSizeF(before_.width() * zoom_, before_.height() * zoom_));
}

void ImageView::fitToWindow() {
  fit_ = true;
  if (before_.isNull()) return;
  const double z = std::min(double(width()) / before_.width(), double(height()) / before_.height());
  zoom_ = std::max(1e-3, z);
  offset_ =
      QPointF((width() - before_.width() * zoom_) / 2, (height() - before_.height() * zoom_) / 2);
  update();
  emit zoomChanged(zoom_);
}

void ImageView::setZoom(double zoom, QPointF anchor) {
  if (before_.isNull()) return;
  zoom = std::clamp(zoom, 0.02, 32.0);
  const QPointF image_point = (anchor - offset_) / zoom_;
  zoom_ = zoom;
  fit_ = false;
  offset_ = anchor - image_point * zoom_;
  clampOffset();
  update();
  emit zoomChanged(zoom_);
}

void ImageView::clampOffset() {
  // Keep the photo (or its centre, when smaller than the view) in view.
  const QSizeF s(before_.width() * zoom_, before_.height() * zoom_);
  auto axis = [](double off, double size, double view) {
    if (size <= view) return (view - size) / 2;
    return std::clamp(off, view - size, 0.0);
  };
  offset_ = QPointF(axis(offset_.x(), s.width(), width()), axis(offset_.y(), s.height(), height()));
}

QSize ImageView::displayPixels() const {
  if (before_.isNull()) return {};
  const double z = std::min(1.0, zoom_ * devicePixelRatioF());
  return QSize(std::max(1, int(std::lround(before_.width() * z))),
               std::max(1, int(std::lround(before_.height() * z))));
}

void ImageView::paintEvent(QPaintEvent*) {
  QPainter painter(this);
  if (before_.isNull()) {
    painter.setPen(QColor(170, 170, 175));
    painter.drawText(rect(), Qt::AlignCenter, tr("Open a photo (File > Open, or drop it here)"));
    return;
  }
  painter.setRenderHint(QPainter::SmoothPixmapTransform, zoom_ < 2.0);
  const QRectF target = imageRect();
  const QImage& after = after_.isNull() ? before_ : after_;
  painter.drawImage(target, after);
  const double split_x = target.left() + split_ * target.width();
  if (split_ > 0) {
    painter.save();
    painter.setClipRect(
        QRectF(target.left(), target.top(), split_x - target.left(), target.height()));
    painter.drawImage(target, before_);
    painter.restore();
    if (split_ < 1) {
      painter.setPen(QPen(QColor(255, 255, 255, 200), 1.5));
      painter.drawLine(QPointF(split_x, target.top()), QPointF(split_x, target.bottom()));
      painter.setPen(Qt::white);
      const QRectF label_before(split_x - 70, target.top() + 6, 64, 18);
      const QRectF label_after(split_x + 6, target.top() + 6, 64, 18);
      painter.fillRect(label_before, QColor(0, 0, 0, 120));
      painter.fillRect(label_after, QColor(0, 0, 0, 120));
      painter.drawText(label_before, Qt::AlignCenter, tr("before"));
      painter.drawText(label_after, Qt::AlignCenter, tr("after"));
    }
  }
  if (editor_ && show_annotations_) {
    painter.setClipRect(target.adjusted(-8, -8, 8, 8));  // handles on the border stay whole
    QTransform to_view;
    to_view.translate(offset_.x(), offset_.y());
    to_view.scale(zoom_, zoom_);
    to_view.translate(0.5, 0.5);
    editor_->paint(painter, to_view);
  }
  if (object_tool_) {
    QTransform to_view;
    to_view.translate(offset_.x(), offset_.y());
    to_view.scale(zoom_, zoom_);
    to_view.translate(0.5, 0.5);
    object_tool_->paint(painter, to_view);
  }
}

void ImageView::resizeEvent(QResizeEvent*) {
  if (fit_)
    fitToWindow();
  else
    clampOffset();
}

void ImageView::setObjectTool(ObjectTool* tool) {
  object_tool_ = tool;
  connect(tool, &ObjectTool::changed, this, qOverload<>(&QWidget::update));
}

bool ImageView::objectToolActive() const {
  return object_tool_ && !before_.isNull() &&
         (!editor_ || editor_->tool() == Tool::navigate || editor_->tool() == Tool::select);
}

void ImageView::wheelEvent(QWheelEvent* event) {
  if (objectToolActive() &&
      object_tool_->wheel(imageFromView(event->position()), event->angleDelta().y() / 120.0,
                          event->modifiers())) {
    event->accept();
    return;
  }
  const double steps = event->angleDelta().y() / 120.0;
  setZoom(zoom_ * std::pow(1.25, steps), event->position());
  event->accept();
}

void ImageView::mousePressEvent(QMouseEvent* event) {
  setFocus(Qt::MouseFocusReason);
  if (event->button() == Qt::LeftButton && objectToolActive() &&
      object_tool_->press(imageFromView(event->pos()), event->modifiers()))
    return;
  if (event->button() == Qt::LeftButton && editor_ && !before_.isNull() &&
      editor_->press(imageFromView(event->pos()), zoom_))
    return;
  if (event->button() == Qt::LeftButton || event->button() == Qt::MiddleButton) {
    panning_ = true;
    last_mouse_ = event->pos();
    setCursor(Qt::ClosedHandCursor);
  }
}

void ImageView::mouseMoveEvent(QMouseEvent* event) {
  if (object_tool_ && object_tool_->dragging()) {
    object_tool_->move(imageFromView(event->pos()));
    return;
  }
  if (!panning_) {
    if (editor_ && !before_.isNull()) editor_->move(imageFromView(event->pos()), zoom_);
    return;
  }
  offset_ += event->pos() - last_mouse_;
  last_mouse_ = event->pos();
  fit_ = false;
  clampOffset();
  update();
}

void ImageView::mouseReleaseEvent(QMouseEvent* event) {
  if (object_tool_ && object_tool_->dragging() && event->button() == Qt::LeftButton) {
    object_tool_->release(imageFromView(event->pos()));
    return;
  }
  if (panning_) {
    panning_ = false;
    if (editor_ && editor_->tool() != Tool::navigate)
      setCursor(editor_->tool() == Tool::select ? Qt::ArrowCursor : Qt::CrossCursor);
    else
      setCursor(Qt::OpenHandCursor);
    return;
  }
  if (event->button() == Qt::LeftButton && editor_ && !before_.isNull())
    editor_->release(imageFromView(event->pos()), zoom_);
}

void ImageView::mouseDoubleClickEvent(QMouseEvent* event) {
  if (event->button() == Qt::LeftButton && editor_ && !before_.isNull() &&
      editor_->doubleClick(imageFromView(event->pos()), zoom_))
    return;
  QWidget::mouseDoubleClickEvent(event);
}

void ImageView::keyPressEvent(QKeyEvent* event) {
  if (editor_ && editor_->key(event->key())) return;
  const double step = 40;
  switch (event->key()) {
    case Qt::Key_Plus:
    case Qt::Key_Equal:
      setZoom(zoom_ * 1.25, rect().center());
      break;
    case Qt::Key_Minus:
      setZoom(zoom_ / 1.25, rect().center());
      break;
    case Qt::Key_0:
      fitToWindow();
      break;
    case Qt::Key_1:
      zoomActualSize();
      break;
    case Qt::Key_Left:
      offset_.rx() += step;
      clampOffset();
      update();
      break;
    case Qt::Key_Right:
      offset_.rx() -= step;
      clampOffset();
      update();
      break;
    case Qt::Key_Up:
      offset_.ry() += step;
      clampOffset();
      update();
      break;
    case Qt::Key_Down:
      offset_.ry() -= step;
      clampOffset();
      update();
      break;
    default:
      QWidget::keyPressEvent(event);
  }
}

}  // namespace mrstudio
