// A small sky dial for the sun: the disc is the sky seen from above (centre: the zenith, rim:
// the horizon; up: azimuth 0, straight ahead of the camera; right: azimuth 90). Click or drag
// to place the sun; the camera's view direction is drawn as a wedge.
#pragma once
#include <QWidget>

namespace mrstudio {

class SunDial : public QWidget {
  Q_OBJECT
 public:
  explicit SunDial(QWidget* parent = nullptr);
  double azimuth() const { return azimuth_deg_; }
  double elevation() const { return elevation_deg_; }
  /// Sets the sun without emitting changed.
  void setSun(double azimuth_deg, double elevation_deg);
  /// The widget position of a sun direction, and back (elevation clamped to [0, 90]).
  QPointF positionOf(double azimuth_deg, double elevation_deg) const;
  void directionAt(const QPointF& p, double* azimuth_deg, double* elevation_deg) const;
  QSize sizeHint() const override { return {120, 120}; }

 signals:
  void changed(double azimuth_deg, double elevation_deg);  ///< by the user (click, drag)

 protected:
  void paintEvent(QPaintEvent*) override;
  void mousePressEvent(QMouseEvent*) override;
  void mouseMoveEvent(QMouseEvent*) override;

 private:
  QPointF centre() const;
  double radius() const;
  double azimuth_deg_ = 0, elevation_deg_ = 30;
};

}  // namespace mrstudio
