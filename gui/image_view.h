// The photo view: zoom (fit, 100 %, wheel, + / - keys) and pan (drag, arrow keys), with a
// before/after split: left of the split the photo, right of it the selected layer.
#pragma once
#include <QImage>
#include <QPointF>
#include <QWidget>

#include "mr/annotations.h"

namespace mrstudio {

class AnnotationEditor;
class ObjectTool;

class ImageView : public QWidget {
  Q_OBJECT
 public:
  explicit ImageView(QWidget* parent = nullptr);

  /// The "before" image; its size is the photo's and defines the view's coordinates.
  void setBefore(const QImage& image);
  /// The "after" image (any size: drawn stretched over the photo).
  void setAfter(const QImage& image);
  void clear();
  const QImage& afterImage() const { return after_; }
  /// Split position as a fraction of the photo's width: 0 shows only "after", 1 only "before".
  void setSplit(double fraction);
  double split() const { return split_; }

  double zoom() const { return zoom_; }  ///< screen pixels per photo pixel
  bool fitting() const { return fit_; }
  void fitToWindow();
  void setZoom(double zoom, QPointF anchor_widget);
  void zoomActualSize() { setZoom(1.0, rect().center()); }

  /// The rendered size that shows the photo at the current zoom in device pixels (for the
  /// preview's resolution), at most the photo's size.
  QSize displayPixels() const;

  /// Annotations drawn over the photo and edited with the left button (its tool decides; the
  /// navigate tool pans). The middle button always pans. Not owned.
  void setEditor(AnnotationEditor* editor);
  /// The insertion tool (object_tool.h): it gets left-button drags that start on an object and
  /// modifier+wheel over one, in the navigate and select tools, before panning and the editor.
  /// Not owned.
  void setObjectTool(ObjectTool* tool);
  /// Draw the annotations (editing works either way).
  void setShowAnnotations(bool show);
  bool showAnnotations() const { return show_annotations_; }
  /// View (widget) position of a photo pixel coordinate (annotations.h convention: (0, 0) is
  /// the centre of the top-left pixel) and back.
  QPointF viewFromImage(const mr::PixelPoint& p) const;
  mr::PixelPoint imageFromView(const QPointF& p) const;

 signals:
  void zoomChanged(double zoom);

 protected:
  void paintEvent(QPaintEvent*) override;
  void resizeEvent(QResizeEvent*) override;
  void wheelEvent(QWheelEvent*) override;
  void mousePressEvent(QMouseEvent*) override;
  void mouseMoveEvent(QMouseEvent*) override;
  void mouseReleaseEvent(QMouseEvent*) override;
  void mouseDoubleClickEvent(QMouseEvent*) override;
  void keyPressEvent(QKeyEvent*) override;

 private:
  QRectF imageRect() const;
  void clampOffset();

  QImage before_, after_;
  double split_ = 0.5;
  double zoom_ = 1.0;
  bool fit_ = true;
  QPointF offset_;  ///< widget position of the photo's top-left corner
  bool panning_ = false;
  QPointF last_mouse_;
  AnnotationEditor* editor_ = nullptr;
  ObjectTool* object_tool_ = nullptr;
  /// Whether the insertion tool may take the mouse (the annotation tool is navigate or select).
  bool objectToolActive() const;
  bool show_annotations_ = true;
};

}  // namespace mrstudio
