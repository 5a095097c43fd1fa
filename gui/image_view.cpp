#include "image_view.h"

#include <QKeyEvent>
#include <QMouseEvent>
#include <QPainter>
#include <QWheelEvent>
#include <algorithm>
#include <cmath>

namespace mrstudio {

ImageView::ImageView(QWidget* parent) : QWidget(parent) {
  setFocusPolicy(Qt::StrongFocus);
  setMinimumSize(320, 240);
  setAutoFillBackground(true);
  QPalette p = palette();
  p.setColor(QPalette::Window, QColor(40, 40, 44));
  setPalette(p);
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
  offset_ = QPointF((width() - before_.width() * zoom_) / 2, (height() - before_.height() * zoom_) / 2);
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
    painter.drawText(rect(), Qt::AlignCenter,
                     tr("Open a photo (File > Open, or drop it here)"));
    return;
  }
  painter.setRenderHint(QPainter::SmoothPixmapTransform, zoom_ < 2.0);
  const QRectF target = imageRect();
  const QImage& after = after_.isNull() ? before_ : after_;
  painter.drawImage(target, after);
  const double split_x = target.left() + split_ * target.width();
  if (split_ > 0) {
    painter.save();
    painter.setClipRect(QRectF(target.left(), target.top(), split_x - target.left(), target.height()));
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
}

void ImageView::resizeEvent(QResizeEvent*) {
  if (fit_) fitToWindow();
  else clampOffset();
}

void ImageView::wheelEvent(QWheelEvent* event) {
  const double steps = event->angleDelta().y() / 120.0;
  setZoom(zoom_ * std::pow(1.25, steps), event->position());
  event->accept();
}

void ImageView::mousePressEvent(QMouseEvent* event) {
  if (event->button() == Qt::LeftButton) {
    panning_ = true;
    last_mouse_ = event->pos();
    setCursor(Qt::ClosedHandCursor);
  }
}

void ImageView::mouseMoveEvent(QMouseEvent* event) {
  if (!panning_) return;
  offset_ += event->pos() - last_mouse_;
  last_mouse_ = event->pos();
  fit_ = false;
  clampOffset();
  update();
}

void ImageView::mouseReleaseEvent(QMouseEvent*) {
  panning_ = false;
  unsetCursor();
}

void ImageView::keyPressEvent(QKeyEvent* event) {
  const double step = 40;
  switch (event->key()) {
    case Qt::Key_Plus: case Qt::Key_Equal: setZoom(zoom_ * 1.25, rect().center()); break;
    case Qt::Key_Minus: setZoom(zoom_ / 1.25, rect().center()); break;
    case Qt::Key_0: fitToWindow(); break;
    case Qt::Key_1: zoomActualSize(); break;
    case Qt::Key_Left: offset_.rx() += step; clampOffset(); update(); break;
    case Qt::Key_Right: offset_.rx() -= step; clampOffset(); update(); break;
    case Qt::Key_Up: offset_.ry() += step; clampOffset(); update(); break;
    case Qt::Key_Down: offset_.ry() -= step; clampOffset(); update(); break;
    default: QWidget::keyPressEvent(event);
  }
}

}  // namespace mrstudio
