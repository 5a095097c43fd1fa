#include "sun_dial.h"

#include <QMouseEvent>
#include <QPainter>
#include <QPainterPath>
#include <algorithm>
#include <cmath>

namespace mrstudio {

namespace {
constexpr double kDeg = M_PI / 180.0;
}

SunDial::SunDial(QWidget* parent) : QWidget(parent) {
  setMinimumSize(110, 110);
  setSizePolicy(QSizePolicy::Preferred, QSizePolicy::Fixed);
  setToolTip(tr(
      "The sky from above: centre = overhead, rim = horizon, up = straight ahead. Drag the sun."));
  setCursor(Qt::CrossCursor);
}

QPointF SunDial::centre() const {
  return QPointF(width() / 2.0, height() / 2.0);
}
double SunDial::radius() const {
  return std::min(width(), height()) / 2.0 - 8;
}

void SunDial::setSun(double azimuth_deg, double elevation_deg) {
  azimuth_deg_ = azimuth_deg;
  elevation_deg_ = elevation_deg;
  update();
}

QPointF SunDial::positionOf(double azimuth_deg, double elevation_deg) const {
  // Distance from the centre linear in zenith angle.
  const double r = radius() * (90.0 - std::clamp(elevation_deg, 0.0, 90.0)) / 90.0;
  return centre() + QPointF(r * std::sin(azimuth_deg * kDeg), -r * std::cos(azimuth_deg * kDeg));
}

void SunDial::directionAt(const QPointF& p, double* azimuth_deg, double* elevation_deg) const {
  const QPointF d = p - centre();
  const double r = std::hypot(d.x(), d.y());
  *elevation_deg = std::clamp(90.0 * (1.0 - r / radius()), 0.0, 90.0);
  *azimuth_deg = r > 0 ? std::atan2(d.x(), -d.y()) / kDeg : 0.0;
}

void SunDial::paintEvent(QPaintEvent*) {
  QPainter p(this);
  p.setRenderHint(QPainter::Antialiasing);
  const QPointF c = centre();
  const double r = radius();
  QRadialGradient sky(c, r);
  sky.setColorAt(0, QColor(120, 170, 230));
  sky.setColorAt(1, QColor(200, 220, 240));
  p.setBrush(sky);
  p.setPen(QPen(palette().color(QPalette::Mid), 1));
  p.drawEllipse(c, r, r);
  p.setBrush(Qt::NoBrush);
  p.setPen(QPen(QColor(255, 255, 255, 140), 1, Qt::DotLine));
  for (double e : {30.0, 60.0}) p.drawEllipse(c, r * (90 - e) / 90, r * (90 - e) / 90);
  // The camera's view: a wedge toward azimuth 0 (up).
  QPainterPath wedge;
  wedge.moveTo(c);
  wedge.arcTo(QRectF(c.x() - r, c.y() - r, 2 * r, 2 * r), 90 - 25, 50);
  wedge.closeSubpath();
  p.fillPath(wedge, QColor(255, 255, 255, 70));
  p.setPen(palette().color(QPalette::WindowText));
  p.drawText(QRectF(c.x() - 30, 0, 60, 10), Qt::AlignCenter, tr("view"));
  const bool above = elevation_deg_ >= 0;
  const QPointF s = positionOf(azimuth_deg_, elevation_deg_);
  p.setPen(QPen(QColor(120, 80, 0), 1));
  p.setBrush(above ? QColor(255, 210, 40) : QColor(150, 150, 150));
  p.drawEllipse(s, 6, 6);
}

void SunDial::mousePressEvent(QMouseEvent* event) {
  double az, el;
  directionAt(event->pos(), &az, &el);
  setSun(az, el);
  emit changed(az, el);
}

void SunDial::mouseMoveEvent(QMouseEvent* event) {
  if (!(event->buttons() & Qt::LeftButton)) return;
  mousePressEvent(event);
}

}  // namespace mrstudio
